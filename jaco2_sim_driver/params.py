"""The jaco2_sim_driver node's parameters (scenario, pacing, rates, camera, watchdog, stamps, disturbances), and the
simulated camera they describe (`CameraSpec`). Their values live in ONE place, config/jaco2_sim_driver.yaml (ROS
params-file form); this module validates and loads them.
The settings shared with the motion planner are `relocation_common.arm_interface.ArmInterface`'s
(config/arm_interface.yaml); the joint speed limits are the robot description's (Table 7).
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from relocation_common.config import ParameterError, node_section
from relocation_common.paths import config_file
from relocation_common.scenario import Shelf

from .disturbance import DisturbancePlan
from .sensor_model import SensorModel

# Default camera: fixed in the base frame, front right of the shelf (as the robot sees it), above the top shelf.
# With the arm at Q_HOME every bottle of paper_experiment_10 shows (>= 250 px each at 640x480; test_sim_core checks
# it); perception's tests are tuned on this view.
CAMERA_POSITION = (0.0, -0.35, 0.55)
CAMERA_TARGET = (0.62, 0.0, 0.26)
# Alternative placement relative to the shelf (CameraSpec.for_shelf): chosen with segmentation renders; shows more
# of every bottle of config/scenarios/*.yaml (paper_experiment_10: >= 1100 px each).
CAMERA_OFFSET = (-0.30, -0.30, 0.38)       # from (x_front, y_center, top_z)
CAMERA_LOOK_AT = (0.45, 0.0, 0.06)         # (fraction of the depth, y from y_center, z above top_z)


@dataclass(frozen=True)
class CameraSpec:
    """Pinhole camera of the scene (RealSense-like). position / look_at in the base frame; None = placed from the
    scenario's shelf (CAMERA_OFFSET, CAMERA_LOOK_AT), see `for_shelf`. Size and field of view are the driver's
    parameters (config/jaco2_sim_driver.yaml): `configured()` is the camera they describe."""

    fovy_deg: float
    width: int
    height: int
    position: tuple[float, float, float] | None = CAMERA_POSITION
    look_at: tuple[float, float, float] | None = CAMERA_TARGET

    @classmethod
    def for_shelf(cls, **kw: Any) -> "CameraSpec":
        """The shelf-relative placement (position and look_at from the scenario's shelf)."""
        return cls(position=None, look_at=None, **kw)

    @staticmethod
    def configured() -> "CameraSpec":
        """The driver's camera as config/jaco2_sim_driver.yaml describes it (DriverParams.camera)."""
        return DriverParams.load().camera()

    def placed(self, shelf: Shelf) -> tuple[np.ndarray, np.ndarray]:
        """(position, look_at) for this shelf."""
        p = self.position or (shelf.x_front + CAMERA_OFFSET[0], shelf.y_center + CAMERA_OFFSET[1],
                              shelf.top_z + CAMERA_OFFSET[2])
        t = self.look_at or (shelf.x_front + CAMERA_LOOK_AT[0] * shelf.depth, shelf.y_center + CAMERA_LOOK_AT[1],
                             shelf.top_z + CAMERA_LOOK_AT[2])
        return np.asarray(p, float), np.asarray(t, float)


NODE_NAME = "jaco2_sim_driver"
_BOOLS = ("state_on_command", "camera_relative_to_shelf", "sim_time_stamps")
_INTS = ("camera_width", "camera_height", "drop_seed")
_STRS = ("scenario", "camera_model", "disturbance_plan")
_POSITIVE = ("joint_state_rate", "objects_rate", "watchdog_timeout", "camera_width", "camera_height")
_NON_NEGATIVE = ("tf_rate", "camera_rate")


@dataclass(frozen=True)
class DriverParams:
    """The node's parameters (docs/sim_driver.md), validated; values in config/jaco2_sim_driver.yaml."""

    scenario: str  # scenario file ("" = the default scene)
    real_time_factor: float  # 1 = real time; <= 0 = as fast as possible
    joint_state_rate: float  # Hz of simulated time
    tf_rate: float  # Hz of simulated time; 0 = once
    state_on_command: bool  # a joint state right after every step that applied a new command
    objects_rate: float  # Hz, ground truth on /sim/objects
    camera_rate: float  # Hz; 0 = no camera
    camera_width: int  # px
    camera_height: int  # px
    camera_fovy: float  # degrees, vertical field of view
    camera_relative_to_shelf: bool  # placed from the shelf (CameraSpec.for_shelf) instead of the fixed pose
    camera_model: str  # a SensorModel name: ideal | realsense_d435
    watchdog_timeout: float  # s without commands -> zero velocity
    sim_time_stamps: bool  # stamp everything with the simulated time
    drop_probability: float  # per carry, the grasped bottle slips (seeded by drop_seed)
    drop_seed: int
    disturbance_plan: str  # "" or a DisturbancePlan's JSON

    def __post_init__(self) -> None:
        """Every parameter checked once, with its name in the error (ParameterError, a ValueError)."""
        for f in dataclasses.fields(self):
            object.__setattr__(self, f.name, _typed(f.name, getattr(self, f.name)))
        for k in _POSITIVE + _NON_NEGATIVE:
            v = getattr(self, k)
            if v < 0 or (v == 0 and k in _POSITIVE):
                raise ParameterError(f"parameter {k} must be {'> 0' if k in _POSITIVE else '>= 0'}, got {v!r}")
        if not 0.0 < self.camera_fovy < 180.0:
            raise ParameterError(f"parameter camera_fovy must be in (0, 180) degrees, got {self.camera_fovy!r}")
        if not 0.0 <= self.drop_probability <= 1.0:
            raise ParameterError(f"parameter drop_probability must be in [0, 1], got {self.drop_probability!r}")
        SensorModel.named(self.camera_model)  # ValueError naming camera_model and the known ones
        try:
            self.plan()
        except ValueError as e:
            raise ParameterError(f"parameter disturbance_plan: {e}") from None

    @classmethod
    def keys(cls) -> tuple[str, ...]:
        """The parameter names."""
        return tuple(f.name for f in dataclasses.fields(cls))

    @classmethod
    def from_mapping(cls, params: Mapping[str, Any]) -> DriverParams:
        """From the node's parameters (keys of other settings, the arm interface's, are left to them);
        ParameterError naming a missing one."""
        missing = [k for k in cls.keys() if k not in params]
        if missing:
            raise ParameterError(f"missing parameter(s): {', '.join(missing)}")
        return cls(**{k: params[k] for k in cls.keys()})

    @classmethod
    def load(cls, path: str | Path | None = None) -> DriverParams:
        """The `jaco2_sim_driver: ros__parameters:` section of a params file (default config/jaco2_sim_driver.yaml);
        ParameterError naming the file for a missing, unknown or bad key."""
        path = path if path is not None else config_file(f"{NODE_NAME}.yaml")
        section = node_section(path, NODE_NAME)
        try:
            unknown = sorted(set(section) - set(cls.keys()))
            if unknown:
                raise ParameterError(f"unknown parameter(s) {', '.join(unknown)}; known: {', '.join(cls.keys())}")
            return cls.from_mapping(section)
        except ParameterError as e:
            raise ParameterError(f"{path}: {e}") from None

    def replace(self, **changes: Any) -> DriverParams:
        """A copy with some parameters changed (validated)."""
        return dataclasses.replace(self, **changes)

    def camera(self) -> CameraSpec:
        """The simulated camera: size and field of view, fixed or placed from the shelf."""
        kw: dict[str, Any] = dict(fovy_deg=self.camera_fovy, width=self.camera_width, height=self.camera_height)
        return CameraSpec.for_shelf(**kw) if self.camera_relative_to_shelf else CameraSpec(**kw)

    def plan(self) -> DisturbancePlan | None:
        """The disturbance plan, or None."""
        return DisturbancePlan.from_json(self.disturbance_plan) if self.disturbance_plan else None


def _typed(name: str, v: Any) -> Any:
    """`v` as the parameter's type (bool, int, str or a finite float); ParameterError naming it otherwise."""
    if name in _BOOLS:
        if not isinstance(v, bool):
            raise ParameterError(f"parameter {name} must be true or false, got {v!r}")
        return v
    if name in _STRS:
        if not isinstance(v, str):
            raise ParameterError(f"parameter {name} must be a string, got {v!r}")
        return v
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise ParameterError(f"parameter {name} must be a finite number, got {v!r}")
    if name in _INTS:
        if not float(v).is_integer():
            raise ParameterError(f"parameter {name} must be an integer, got {v!r}")
        return int(v)
    return float(v)
