"""The arm of one relocation over a driver's command stream (ROS-free; the motion_planner node supplies the link).

`StreamedArm` is relocation.Arm over an `ArmLink` (the driver's interface: velocity commands, joint states, the
fingers): a planned motion is streamed at `stream_rate` (100 Hz, kinova-ros's "Note on publish frequency") with
`execution.TrajectoryFollower`'s commands from the latest joint state; joint states older than `state_hold` hold
the arm (zero velocity, as a Kinova driver that gets no commands does) until they return, older than
`state_timeout` abort the relocation. The gripper: on the kinova surface a SetFingersPosition goal and its result
(the link), on ros2_control the finger joints' position command, watched in the joint states until the fingers
reach the goal or stall (`relocation_common.kinova.FingerMonitor`, as Kinova's action decides); closing must stop
short of `finger_empty_closure` (a bottle is between the fingers). Progress per phase: relocation.PHASES.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, fields
from typing import Any, Callable, Mapping, Protocol

import numpy as np

from relocation_common import kinova
from relocation_common import robot_description as rd
from relocation_common.arm_interface import ArmInterface
from stpik_motion_planner.execution.follower import FollowerParams, TrajectoryFollower
from stpik_motion_planner.execution.relocation import PHASES, PUSH_PHASES
from stpik_motion_planner.planning.params import node_parameters
from stpik_motion_planner.planning.trajectory import Trajectory

STATE_POLL = 0.005  # s between looks at the joint states while the arm is held
GRIPPER_POLL = 0.02  # s between the ros2_control gripper's (repeated) commands


class Aborted(Exception):
    """A relocation that cannot go on (the message is the reason sent back in the result)."""


class Cancelled(Exception):
    """The goal was cancelled: the arm is stopped."""


@dataclass(frozen=True)
class StreamParams:
    """The node's streaming and gripper parameters (config/motion_planner.yaml, their one place: `load`;
    docs/motion_planner.md)."""

    stream_rate: float  # Hz
    state_hold: float  # s: older joint states hold the arm
    state_timeout: float  # s: older joint states abort
    finger_closed: float  # turns of a closing goal
    finger_empty_closure: float  # fraction of finger_closed: closed past it = closed on nothing
    gripper_timeout: float  # s
    gripper_settle: float  # s after the fingers stopped
    finger_tolerance: float  # turns (FingerMonitor, ros2_control surface): config/arm_interface.yaml
    finger_stall_threshold: float  # turns: config/arm_interface.yaml
    finger_stall_interval: float  # s: config/arm_interface.yaml
    follower: FollowerParams  # config/motion_planner.yaml follower.*

    def __post_init__(self) -> None:
        if not 0.0 < self.state_hold < self.state_timeout:
            raise ValueError(f"parameters state_hold and state_timeout must satisfy 0 < state_hold < state_timeout, "
                             f"got {self.state_hold} and {self.state_timeout}")
        if not self.stream_rate > 0:
            raise ValueError(f"parameter stream_rate must be > 0, got {self.stream_rate!r}")

    @classmethod
    def from_mapping(cls, params: Mapping[str, Any]) -> StreamParams:
        """From the node's parameters (the keys of this class, the arm interface's finger settings among them,
        `follower.*` for FollowerParams); ValueError."""
        keys = {f.name for f in fields(cls)} - {"follower"}
        own = {k: float(v) for k, v in params.items() if k in keys}
        return cls(**own, follower=FollowerParams.from_mapping(params))

    @classmethod
    def load(cls) -> StreamParams:
        """config/motion_planner.yaml's and config/arm_interface.yaml's values (a core without a node)."""
        return cls.from_mapping({**ArmInterface.load().to_dict(), **node_parameters()})


class ArmLink(Protocol):
    """The driver's interface, as the arm needs it (the node implements it over ROS, a test over a fake arm)."""

    kinova: bool  # the kinova surface (a fingers action) or ros2_control (a finger position command)

    def send(self, qdot: np.ndarray) -> None:
        """One joint-velocity command (rad/s)."""

    def joint_state(self) -> tuple[np.ndarray, float] | None:
        """(arm joint angles, time.monotonic() when received) of the latest joint state."""

    def finger_state(self) -> tuple[np.ndarray, float] | None:
        """(finger joint angles in rad as Kinova reports them, time received) of the latest joint state."""

    def send_fingers(self, angle: float) -> None:
        """ros2_control: every finger joint's position command (rad)."""

    def finger_goal(self, turns: float, deadline: float, cancelled: Callable[[], bool]) -> np.ndarray:
        """kinova: a SetFingersPosition goal of `turns` for every finger; the turns of its result. Aborted (no server,
        rejected, timeout at `deadline`, an unexpected status) or Cancelled."""

    def show_path(self, trajectory: Trajectory, phase: str) -> None:
        """The motion about to be executed (the tool path marker)."""

    def ok(self) -> bool:
        """False once the node is shutting down."""

    def driver_present(self) -> bool:
        """False once no publisher of the joint states is left in the graph (the driver has gone)."""


def progress(phase: str, within: float = 0.0) -> float:
    """The whole relocation's progress (0..1) at `within` (0..1) of `phase` (relocation.PHASES, or a push's:
    relocation.PUSH_PHASES)."""
    table = PUSH_PHASES if phase in PUSH_PHASES else PHASES
    names = list(table)
    k = names.index(phase)
    lo, hi = table[phase], table[names[min(k + 1, len(names) - 1)]]
    return float(lo + (hi - lo) * within)


class StreamedArm:
    """relocation.Arm over an ArmLink for one goal. `cancelled()`: the goal's cancel request (always False for the
    recovery after a cancel, which runs to its end); `feedback(phase, progress)`; `log(level, text)`."""

    def __init__(self, link: ArmLink, params: StreamParams, cancelled: Callable[[], bool] = lambda: False,
                 feedback: Callable[[str, float], None] = lambda *_: None,
                 log: Callable[[str, str], None] = lambda *_: None) -> None:
        self.link, self.p, self.cancelled, self.feedback, self.log = link, params, cancelled, feedback, log

    def uncancellable(self) -> StreamedArm:
        """The same arm, deaf to the cancel request (feedback still goes to the goal)."""
        return StreamedArm(self.link, self.p, lambda: False, self.feedback, self.log)

    # -- relocation.Arm ---------------------------------------------------------------------------------------
    def measured(self) -> np.ndarray:
        """The latest joint angles; the arm held while they are late (see the module docstring)."""
        return self._fresh_state()[0]

    def phase(self, phase: str) -> None:
        """Feedback: `phase` starts."""
        self.feedback(phase, progress(phase))

    def follow(self, traj: Trajectory, phase: str) -> None:
        """Stream the trajectory at stream_rate with position feedback until it settles (execution/follower.py)."""
        follower = TrajectoryFollower(traj, rd.QDOT_MAX, self.p.follower)
        self.link.show_path(traj, phase)
        period = 1.0 / self.p.stream_rate
        last = next_tick = time.monotonic()
        tick = 0
        while True:
            self._check()
            q, held = self._fresh_state()
            now = time.monotonic()
            status = follower.update(q, period if held else now - last)  # the reference waits while held
            last = now
            if status == follower.SETTLED:
                self.stop()
                return
            if status == follower.FAILED:
                raise Aborted(f"{phase}: {follower.reason}")
            self.link.send(follower.command(q))
            if tick % 10 == 0:
                self.feedback(phase, progress(phase, follower.progress))
            tick += 1
            next_tick = max(next_tick + period, now)
            time.sleep(max(0.0, next_tick - time.monotonic()))

    def gripper(self, action: str, phase: str) -> None:
        """Close or open the fingers and wait until they stop (the module docstring); closing has to stop short of
        finger_empty_closure, opening has to open, or the relocation aborts; 'shut' (a push's hand) has to close
        further than finger_empty_closure (on nothing)."""
        self.phase(phase)
        closing = action in ("close", "shut")
        closed = self.p.finger_closed
        goal = closed if closing else 0.0
        deadline = time.monotonic() + self.p.gripper_timeout
        turns = (self.link.finger_goal(goal, deadline, self.cancelled) if self.link.kinova
                 else self._fingers_command(goal, deadline))
        closure = float(np.mean(turns)) / closed
        if action == "shut":  # closed on nothing, for a push (execution/push.py)
            if closure <= self.p.finger_empty_closure:
                raise Aborted(f"gripper shut for a push: the fingers stopped {closure:.0%} closed (something between "
                              "them)")
            self.log("info", f"gripper shut: fingers {closure:.0%} closed")
            time.sleep(self.p.gripper_settle)
            return
        if closing and closure > self.p.finger_empty_closure:
            raise Aborted(f"gripper close: the fingers closed on nothing ({closure:.0%} closed)")
        if closing and closure < 0.02:
            raise Aborted("gripper close: the fingers did not move")
        if not closing and closure > 0.1:
            raise Aborted(f"gripper open: the fingers stopped {closure:.0%} closed")
        self.log("info", f"gripper {action}: fingers stopped {closure:.0%} closed")
        time.sleep(self.p.gripper_settle)

    # -- the rest ---------------------------------------------------------------------------------------------
    def stop(self) -> None:
        """Zero velocity (three times: a lost message does not leave the arm moving until the watchdog)."""
        if self.link.ok():
            for _ in range(3):
                self.link.send(np.zeros(rd.N_JOINTS))

    def wait_for_state(self, timeout: float) -> None:
        """Wait up to `timeout` s (less if the node shuts down) for a joint state no older than `state_hold`: right
        after start-up, discovery of the driver can take a moment; a driver starved under load can fall silent for
        longer than `state_timeout` (the closed-loop grid at a load average of 25: 2.5 s). A driver that has gone
        (states came before, no publisher of them is left) is not waited for: its relocation aborts at once."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline and self.link.ok():
            st = self.link.joint_state()
            if st is not None and (time.monotonic() - st[1] <= self.p.state_hold or not self.link.driver_present()):
                return
            time.sleep(0.05)

    def _check(self) -> None:
        if self.cancelled():
            raise Cancelled()
        if not self.link.ok():
            raise Aborted("node shutting down")

    def _fresh_state(self) -> tuple[np.ndarray, float]:
        """(joint angles, seconds the arm was held waiting for them)."""
        t0 = time.monotonic()
        held, age_max = False, 0.0
        while True:
            st = self.link.joint_state()
            now = time.monotonic()
            age = math.inf if st is None else now - st[1]
            if st is not None and age <= self.p.state_hold:
                if held:
                    self.log("warning", f"joint states back after {age_max:.2f} s: the arm was held {now - t0:.2f} s")
                return st[0].copy(), (now - t0) if held else 0.0
            if age > self.p.state_timeout:
                raise Aborted(f"no joint state from the driver for {age:.1f} s (> state_timeout): "
                              f"is jaco2_sim_driver (or the Kinova driver) running?")
            self._check()
            if not held:
                self.stop()
                held = True
            age_max = age
            time.sleep(STATE_POLL)

    def _fingers_command(self, goal: float, deadline: float) -> np.ndarray:
        """ros2_control: the finger joints' position (Kinova's joint angle of `goal` turns) on the gripper
        controller, then the joint states until the fingers reach it or stall, as Kinova's action decides."""
        angle = float(kinova.turns_to_joint(goal))
        monitor = None
        while True:
            self.link.send_fingers(angle)  # a forward command: repeating it is harmless and survives a lost message
            time.sleep(GRIPPER_POLL)
            if self.cancelled():
                raise Cancelled()
            now, st = time.monotonic(), self.link.finger_state()
            if now > deadline:
                raise Aborted("gripper: the fingers did not stop within gripper_timeout")
            if st is None or now - st[1] > self.p.state_timeout:
                continue
            turns = kinova.joint_to_turns(st[0])
            if monitor is None:
                monitor = kinova.FingerMonitor([goal] * len(turns), now, turns, self.p.finger_tolerance,
                                               self.p.finger_stall_threshold, self.p.finger_stall_interval)
            elif monitor.update(now, turns) != monitor.MOVING:
                return turns
