"""The arm's interface: what the motion planner and the driver (the simulator, or Kinova's own) must agree on.

One place, config/arm_interface.yaml (a ROS params file whose `/**` section applies to any node it is given to):
the surface (`command_interface`: `kinova`, kinova-ros's j2s7s300 driver under `driver_prefix`, or `ros2_control`),
and the fingers' end rule of Kinova's action (`FingerMonitor`: the driver applies it to the fingers action, the
planner to the ros2_control gripper). Both nodes declare these parameters with that file's values as defaults
(`relocation_common.node.declare_parameters`), so a `-p` on a node still overrides them (then give both the same).

A mismatch is never silent: `mismatch` reads the ROS graph as each side sees it (the planner: its joint-state topic
has no publisher while another surface's has one; the driver: the same for the velocity commands) and says which
surface the other side runs; the nodes log it, and the planner aborts a relocation with it. Units and sources:
docs/kinova.md.
"""
from __future__ import annotations

import math
import re
from dataclasses import asdict, dataclass, fields
from pathlib import Path
from typing import Any, Callable, Mapping

from .config import ParameterError, node_section
from .paths import config_file

FILE = "arm_interface.yaml"
SECTION = "/**"  # the params file's section: every node it is given to
SURFACES = ("kinova", "ros2_control")
VELOCITY_TOPIC = "/velocity_controller/commands"  # ros2_control JointGroupVelocityController, rad/s
GRIPPER_TOPIC = "/gripper_controller/commands"    # ros2_control JointGroupPositionController, finger joints (rad)
JOINT_STATES_TOPIC = "/joint_states"              # ros2_control joint_state_broadcaster
KINOVA_VELOCITY = "/in/joint_velocity"            # under driver_prefix: kinova_msgs/JointVelocity, deg/s
KINOVA_STATE = "/out/joint_state"                 # under driver_prefix: sensor_msgs/JointState, rad
KINOVA_FINGERS = "/fingers_action/finger_positions"  # under driver_prefix: kinova_msgs/action/SetFingersPosition
_NAMESPACE = re.compile(r"/?([A-Za-z_][A-Za-z0-9_]*(/[A-Za-z_][A-Za-z0-9_]*)*)?")


@dataclass(frozen=True)
class ArmInterface:
    """The shared settings of the arm's interface (the module docstring), validated; values in
    config/arm_interface.yaml."""

    command_interface: str  # kinova | ros2_control
    driver_prefix: str  # kinova: the driver's namespace (kinova-ros: /<robot type>_driver)
    finger_tolerance: float  # turns: the fingers are at their goal this close to it
    finger_stall_threshold: float  # turns: fingers that moved less for finger_stall_interval have stopped
    finger_stall_interval: float  # s

    def __post_init__(self) -> None:
        if self.command_interface not in SURFACES:
            raise ParameterError(f"parameter command_interface must be one of {', '.join(SURFACES)}, "
                                 f"got {self.command_interface!r}")
        if not isinstance(self.driver_prefix, str) or not _NAMESPACE.fullmatch(self.driver_prefix.rstrip("/")):
            raise ParameterError(f"parameter driver_prefix must be a ROS namespace such as /j2s7s300_driver, "
                                 f"got {self.driver_prefix!r}")
        object.__setattr__(self, "driver_prefix", self.driver_prefix.rstrip("/"))
        for k in ("finger_tolerance", "finger_stall_threshold", "finger_stall_interval"):
            v = getattr(self, k)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
                raise ParameterError(f"parameter {k} must be a finite number > 0, got {v!r}")
            object.__setattr__(self, k, float(v))

    @classmethod
    def keys(cls) -> tuple[str, ...]:
        """The parameter names."""
        return tuple(f.name for f in fields(cls))

    @classmethod
    def from_mapping(cls, params: Mapping[str, Any]) -> ArmInterface:
        """From a node's parameters (other keys are the node's own); ParameterError naming a missing one."""
        missing = [k for k in cls.keys() if k not in params]
        if missing:
            raise ParameterError(f"missing arm interface parameter(s): {', '.join(missing)}")
        return cls(**{k: params[k] for k in cls.keys()})

    @classmethod
    def load(cls, path: str | Path | None = None) -> ArmInterface:
        """config/arm_interface.yaml (or `path`); ParameterError naming the file for a missing, unknown or bad key."""
        path = path if path is not None else config_file(FILE)
        section = node_section(path, SECTION)
        unknown = sorted(set(section) - set(cls.keys()))
        try:
            if unknown:
                raise ParameterError(f"unknown parameter(s) {', '.join(unknown)}; known: {', '.join(cls.keys())}")
            return cls.from_mapping(section)
        except ParameterError as e:
            raise ParameterError(f"{path}: {e}") from None

    def to_dict(self) -> dict[str, Any]:
        """The parameters by name."""
        return asdict(self)

    @property
    def kinova(self) -> bool:
        """kinova-ros's surface (else ros2_control)."""
        return self.command_interface == "kinova"

    @property
    def velocity_topic(self) -> str:
        """Where the planner sends joint velocities and the driver reads them."""
        return self.driver_prefix + KINOVA_VELOCITY if self.kinova else VELOCITY_TOPIC

    @property
    def state_topic(self) -> str:
        """Where the driver publishes joint states and the planner reads them."""
        return self.driver_prefix + KINOVA_STATE if self.kinova else JOINT_STATES_TOPIC

    @property
    def fingers_action(self) -> str:
        """kinova: the SetFingersPosition action the driver serves and the planner calls."""
        return self.driver_prefix + KINOVA_FINGERS

    def finger_rule(self) -> dict[str, float]:
        """FingerMonitor's keyword arguments: tolerance, stall_threshold, stall_interval."""
        return dict(tolerance=self.finger_tolerance, stall_threshold=self.finger_stall_threshold,
                    stall_interval=self.finger_stall_interval)

    def describe(self) -> str:
        """E.g. 'command_interface kinova, driver_prefix /j2s7s300_driver'."""
        return f"command_interface {self.command_interface}" + (
            f", driver_prefix {self.driver_prefix or '/'}" if self.kinova else "")


def _surface_of(topic: str, suffix: str, ros2_control: str) -> str | None:
    """The surface a state or command topic belongs to, as text; None for any other topic."""
    if topic == ros2_control:
        return "command_interface ros2_control"
    if topic.endswith(suffix):
        return f"command_interface kinova, driver_prefix {topic[:-len(suffix)] or '/'}"
    return None


def _topic_kind(role: str) -> tuple[str, str]:
    """(kinova suffix, ros2_control topic) of what `role` reads: the planner joint states, the driver commands."""
    if role == "planner":
        return KINOVA_STATE, JOINT_STATES_TOPIC
    if role == "driver":
        return KINOVA_VELOCITY, VELOCITY_TOPIC
    raise ValueError(f"role must be planner or driver, got {role!r}")


def mismatch(arm: ArmInterface, role: str, expected: str, publishers: Mapping[str, int]) -> str | None:
    """Why the other side cannot be heard, or None. `role` 'planner' reads joint states on `expected`, 'driver' reads
    velocity commands on it (the resolved topic names); `publishers`: topic -> publishers in the graph. A mismatch:
    nobody publishes on `expected` while another surface's topic of that kind has a publisher."""
    if publishers.get(expected, 0) > 0:
        return None
    suffix, ros2_control = _topic_kind(role)
    other = sorted(t for t, n in publishers.items() if n > 0 and t != expected and _surface_of(t, suffix, ros2_control))
    if not other:
        return None
    what, who = ("joint states", "the driver") if role == "planner" else ("velocity commands", "the motion planner")
    return (f"arm interface mismatch: this node ({arm.describe()}) reads {what} on {expected}, which nobody "
            f"publishes, but {other[0]} is published: {who} runs {_surface_of(other[0], suffix, ros2_control)}. "
            f"Give both nodes the same settings (config/arm_interface.yaml, or the same -p on both)")


def graph_publishers(node: Any, role: str) -> dict[str, int]:
    """The graph as `node` (an rclpy Node) sees it: publishers of every topic that is some surface's joint states
    (role 'planner') or velocity commands ('driver')."""
    suffix, ros2_control = _topic_kind(role)
    return {t: node.count_publishers(t) for t, _ in node.get_topic_names_and_types()
            if _surface_of(t, suffix, ros2_control) is not None}


class MismatchWatch:
    """`mismatch` on `node`'s graph every `period` s (a timer of `node`); a new finding goes to `log` (default: the
    node's logger, as an error), and `found` holds the latest (None: none). `check()` looks now."""

    def __init__(self, node: Any, arm: ArmInterface, role: str, expected: str, period: float = 2.0,
                 log: Callable[[str], Any] | None = None) -> None:
        self.node, self.arm, self.role, self.expected = node, arm, role, expected
        self.log = log if log is not None else node.get_logger().error
        self.found: str | None = None
        self._timer = node.create_timer(period, self.check)

    def check(self) -> str | None:
        """Look at the graph now; log a finding that differs from the last one."""
        found = mismatch(self.arm, self.role, self.expected, graph_publishers(self.node, self.role))
        if found is not None and found != self.found:
            self.log(found)
        self.found = found
        return found
