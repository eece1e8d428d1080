"""The simulated Jaco2 (no ROS): joint-velocity control with Kinova's safety behaviour, the gripper, ground truth.

Control law: each arm joint has a MuJoCo velocity actuator tau_i = kv (qdot_cmd_i - qdot_i) on gravity-compensated
links (kv about 200 tracks: docs/install.md, "Platform notes"). The command qdot_cmd is what the motion planner
streams (the joint velocities of its STPIK solution, Eq. 16-17 of the paper) and is

- rejected whole if it has the wrong length or a NaN/Inf entry (BadCommandError; the previous state is kept),
- clamped to the velocity limits of Table 7 (`QDOT_MAX`),
- slowed towards a joint limit of Table 6 so that the joint stops on it (joint-limit stop),
- zeroed by the watchdog when no command came for `watchdog_timeout` of simulated time (Kinova: 50 ms);
and after every physics step the joint velocities are held within Table 7 and the angles within Table 6, as the
arm's firmware does (`_enforce_limits`): the servo alone let joint 3 reach 1.14x its limit under +-1e30 commands.

Grasp: a weld constraint (see `gripper_close`). Physics at 1 kHz (model timestep 0.001).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np
from numpy.typing import ArrayLike

from relocation_common.robot_description import (
    CONTINUOUS,
    FINGER_JOINT_NAMES,
    JOINT_NAMES,
    N_JOINTS,
    Q_HOME,
    Q_LOWER,
    Q_UPPER,
    QDOT_MAX,
)
from relocation_common.scenario import Scenario

from .params import CameraSpec, DriverParams
from .scene import DESCRIPTION_FINGER_GEOMS, FINGER_CLOSED, HAND_BODY, build_model

LIMIT_BRAKE_TIME = 0.02     # s: near a limit the allowed speed towards it is distance / LIMIT_BRAKE_TIME
GRASP_RADIAL_TOL = 0.025    # m: bottle axis to grasp centre, across the hand (fingers open to about +-36 mm)
RELEASE_DELAY = 0.15        # s from opening the fingers to letting the bottle go (they are clear of it by then)
GRASP_TILT_COS = math.cos(math.radians(30))  # hand y axis (finger spread) vs bottle axis
GRASP_CLOSURE = 0.5         # finger targets past this fraction of closed grasp, below it release
GRASP_END = 0.2             # of a cylinder's length: an end grasp's centre at most this far inside an end cap


class BadCommandError(ValueError):
    """A joint-velocity command that cannot be executed (wrong length, NaN, Inf)."""


@dataclass(frozen=True)
class ObjectPose:
    """Ground truth of one object: the centre of its base as built (scene._object: a cylinder's lower end face, a
    box's bottom face) and its body's orientation (w, x, y, z) in the base frame; the primitive's centre is half its
    size z along the body's z axis (messages.ground_truth)."""

    id: str
    position: tuple[float, float, float]
    quat_wxyz: tuple[float, float, float, float]


def check_velocity_command(qdot: ArrayLike, n: int = N_JOINTS) -> np.ndarray:
    """Validate a joint-velocity command (rad/s); BadCommandError with the reason otherwise."""
    try:
        v = np.asarray(qdot, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise BadCommandError(f"joint velocity command is not a list of numbers: {qdot!r}") from None
    if v.size != n:
        raise BadCommandError(f"joint velocity command has {v.size} values, expected {n}")
    if not np.all(np.isfinite(v)):
        raise BadCommandError(f"joint velocity command has NaN or Inf: {v.tolist()}")
    return v


class Jaco2Sim:
    """Scenario scene + arm; not thread-safe (the node serialises access with a lock). `camera` and
    `watchdog_timeout` None: the driver's parameters (config/jaco2_sim_driver.yaml, params.DriverParams)."""

    def __init__(self, scenario: Scenario, *, camera: CameraSpec | None = None,
                 watchdog_timeout: float | None = None, q_home: ArrayLike = Q_HOME) -> None:
        if camera is None or watchdog_timeout is None:
            configured = DriverParams.load()
            camera = camera if camera is not None else configured.camera()
            watchdog_timeout = watchdog_timeout if watchdog_timeout is not None else configured.watchdog_timeout
        self.scenario = scenario
        self.camera = camera
        self.model = build_model(scenario, camera)
        self.data = mujoco.MjData(self.model)
        self.qdot_max = QDOT_MAX.copy()  # Table 7, from the robot description (its one place)
        if watchdog_timeout <= 0:
            raise ValueError(f"watchdog_timeout must be positive, got {watchdog_timeout}")
        self.watchdog_timeout = float(watchdog_timeout)
        self.q_home = np.asarray(q_home, float)
        m = self.model
        self._qadr = np.array([m.joint(j).qposadr[0] for j in JOINT_NAMES])
        self._vadr = np.array([m.joint(j).dofadr[0] for j in JOINT_NAMES])
        self._fqadr = np.array([m.joint(j).qposadr[0] for j in FINGER_JOINT_NAMES])
        self._fvadr = np.array([m.joint(j).dofadr[0] for j in FINGER_JOINT_NAMES])
        self._act = np.array([m.actuator(f"v_{j}").id for j in JOINT_NAMES])
        self._fact = np.array([m.actuator(f"p_{j}").id for j in FINGER_JOINT_NAMES])
        self._limited = ~np.asarray(CONTINUOUS)
        self._hand = m.body(HAND_BODY).id
        self._site = m.site("end_effector").id
        self._bodies = {b.id: m.body(b.id).id for b in scenario.world}  # listed and unlisted
        self._welds = {b.id: m.equality(f"grasp_{b.id}").id for b in scenario.world}
        self._release: tuple[str, float] | None = None  # (bottle, sim time) of a pending release
        for g in DESCRIPTION_FINGER_GEOMS:  # the moving finger bodies replace the description's static capsules
            gid = m.geom(g).id
            m.geom_contype[gid] = m.geom_conaffinity[gid] = 0
            m.geom_rgba[gid, 3] = 0.0
        self.grasped: str | None = None
        self.watchdog_stops = 0  # a moving arm stopped by the watchdog, over resets too (the driver's health)
        self._tripped = True  # the watchdog's state at the last step (a stop is counted when it trips)
        self.reset()

    # ---------------------------------------------------------------- state
    @property
    def time(self) -> float:
        """Simulated time (s)."""
        return float(self.data.time)

    @property
    def q(self) -> np.ndarray:
        """Joint angles in Kinova's physical convention Q (rad)."""
        return self.data.qpos[self._qadr].copy()

    @property
    def qdot(self) -> np.ndarray:
        """Joint velocities (rad/s)."""
        return self.data.qvel[self._vadr].copy()

    @property
    def effort(self) -> np.ndarray:
        """Actuator torques of the arm joints (N m)."""
        return self.data.actuator_force[self._act].copy()

    @property
    def finger_q(self) -> np.ndarray:
        """Finger hinge angles (rad): 0 open, FINGER_CLOSED when the tips meet."""
        return self.data.qpos[self._fqadr].copy()

    @property
    def finger_qdot(self) -> np.ndarray:
        """Finger hinge velocities (rad/s)."""
        return self.data.qvel[self._fvadr].copy()

    @property
    def command(self) -> np.ndarray:
        """The velocity command currently applied (after clamping, limit stop and watchdog)."""
        return self.data.ctrl[self._act].copy()

    @property
    def watchdog_tripped(self) -> bool:
        """True when no command came for `watchdog_timeout` of simulated time (the command is then zero)."""
        return self.command_age > self.watchdog_timeout

    @property
    def command_age(self) -> float:
        """Simulated seconds since the last velocity command (inf: none since the reset)."""
        return self.time - self._cmd_time

    def ee_pose(self) -> np.ndarray:
        """4x4 pose of the tool frame (site end_effector: z approach, x closing, origin grasp centre)."""
        t = np.eye(4)
        t[:3, :3] = self.data.site_xmat[self._site].reshape(3, 3)
        t[:3, 3] = self.data.site_xpos[self._site]
        return t

    def object_poses(self) -> list[ObjectPose]:
        """Ground-truth poses of every object, listed then unlisted, in file order."""
        return [ObjectPose(oid, tuple(self.data.xpos[b]), tuple(self.data.xquat[b]))
                for oid, b in self._bodies.items()]

    # ---------------------------------------------------------------- commands
    def set_velocity(self, qdot: ArrayLike) -> np.ndarray:
        """Command joint velocities (rad/s, order JOINT_NAMES); returns the clamped command. Feeds the watchdog.
        A bad command raises BadCommandError and changes nothing."""
        v = np.clip(check_velocity_command(qdot), -self.qdot_max, self.qdot_max)
        self._cmd = v
        self._cmd_time = self.time
        self._apply()
        return v.copy()

    def stop(self) -> None:
        """Command zero joint velocity (the watchdog is not fed)."""
        self._cmd = np.zeros(N_JOINTS)
        self._apply()

    def _apply(self) -> None:
        tripped = self.watchdog_tripped
        if tripped and not self._tripped and np.any(self._cmd != 0):
            self.watchdog_stops += 1  # a moving arm stopped by the watchdog (the command stream stopped or stalled)
        self._tripped = tripped
        v = self._cmd if not tripped else np.zeros(N_JOINTS)
        q = self.data.qpos[self._qadr]
        lim = self._limited
        # joint-limit stop: the speed towards a limit shrinks with the distance to it
        up = np.maximum(Q_UPPER - q, 0.0) / LIMIT_BRAKE_TIME
        lo = np.maximum(q - Q_LOWER, 0.0) / LIMIT_BRAKE_TIME
        v = np.where(lim & (v > 0), np.minimum(v, up), v)
        v = np.where(lim & (v < 0), np.maximum(v, -lo), v)
        self.data.ctrl[self._act] = v

    def _enforce_limits(self) -> None:
        """Joint velocities within +-qdot_max (Table 7); a limited joint past Table 6 is put back on its limit and
        stopped there."""
        d = self.data
        d.qvel[self._vadr] = np.clip(d.qvel[self._vadr], -self.qdot_max, self.qdot_max)
        q = d.qpos[self._qadr]
        out = self._limited & ((q > Q_UPPER) | (q < Q_LOWER))
        if out.any():
            d.qpos[self._qadr[out]] = np.clip(q[out], Q_LOWER[out], Q_UPPER[out])
            d.qvel[self._vadr[out]] = 0.0

    def step(self, n: int = 1) -> None:
        """Advance n physics steps of 1 ms, re-applying watchdog and limit stop before each."""
        for _ in range(n):
            self._apply()
            mujoco.mj_step(self.model, self.data)
            self._enforce_limits()
            if self._release is not None and self.data.time >= self._release[1]:
                self._let_go(self._release[0])

    # ---------------------------------------------------------------- scene
    def reset(self) -> None:
        """Scenario state: objects where the scenario puts them, arm at home, gripper open, no grasp."""
        mujoco.mj_resetData(self.model, self.data)
        self.data.eq_active[:] = 0
        for b in self._bodies.values():
            self.model.body_gravcomp[b] = 0.0
        self.grasped = None
        self._release = None
        self.data.ctrl[self._fact] = 0.0
        self.home()

    def home(self) -> None:
        """Put the arm at q_home at rest (a teleport, not a motion) and stop it."""
        self.data.qpos[self._qadr] = self.q_home
        self.data.qvel[self._vadr] = 0.0
        self._cmd = np.zeros(N_JOINTS)
        self._cmd_time = -math.inf
        self._tripped = True
        self.data.ctrl[self._act] = 0.0
        if self.grasped is not None:  # a carried bottle comes along, at its grasp offset
            mujoco.mj_kinematics(self.model, self.data)
            self._place_grasped(self.grasped)
        mujoco.mj_forward(self.model, self.data)

    def bottle_between_fingers(self) -> str | None:
        """Id of the object between the fingers, or None: a bottle (cylinder) whose axis passes through the grasp
        centre (within GRASP_RADIAL_TOL across it), or a box whose footprint holds the grasp centre (the side grasp
        takes it by a face the hand fits: its centre may be farther than a bottle's axis); either with the grasp
        centre within its height and the hand's finger-spread axis along its own z (a cylinder's axis, a box's
        vertical). Or an end grasp (a lying cylinder grasped along its axis): a cylinder whose axis is along the
        approach (tool z), the grasp centre within GRASP_RADIAL_TOL of that axis and inside its length, at most
        GRASP_END of it from an end cap (the fingers reaching 42 mm beyond the grasp centre close across that end)."""
        c, r = self.data.site_xpos[self._site], self.data.site_xmat[self._site].reshape(3, 3)
        best, best_d = None, GRASP_RADIAL_TOL
        for oid, b in self._bodies.items():
            obj = self.scenario.world_object(oid)
            frame = self.data.xmat[b].reshape(3, 3)
            axis = frame[:, 2]
            d = c - self.data.xpos[b]
            s = float(d @ axis)
            if abs(float(axis @ r[:, 1])) < GRASP_TILT_COS:
                end = obj.shape != "box" and abs(float(axis @ r[:, 2])) >= GRASP_TILT_COS and \
                    0.0 <= min(s, obj.height - s) <= GRASP_END * obj.height
                if not end:
                    continue
            elif not 0.2 * obj.height <= s <= 0.9 * obj.height:
                continue
            radial = float(np.linalg.norm(d - s * axis))
            if obj.shape == "box":
                u, v, _ = frame.T @ d
                radial = 0.0 if abs(u) <= obj.size[0] / 2 and abs(v) <= obj.size[1] / 2 else math.inf
            if radial < best_d:
                best, best_d = oid, radial
        return best

    def gripper_close(self) -> str | None:
        """Close the three fingers. If a bottle is between them it is grasped: a weld constraint fixes it to the
        hand at its current relative pose and its weight is compensated while carried. Returns its id or None."""
        self.data.ctrl[self._fact] = FINGER_CLOSED
        if self.grasped is not None:
            return self.grasped
        if self._release is not None:  # closing again right after opening: finish that release first
            self._let_go(self._release[0])
        oid = self.bottle_between_fingers()
        if oid is None:
            return None
        b, eq = self._bodies[oid], self._welds[oid]
        # relpose of the weld = pose of the bottle in the hand frame now (so that nothing jumps)
        hp, hq = self.data.xpos[self._hand], self.data.xquat[self._hand]
        hq_inv, rel_p, rel_q = np.zeros(4), np.zeros(3), np.zeros(4)
        mujoco.mju_negQuat(hq_inv, hq)
        mujoco.mju_rotVecQuat(rel_p, self.data.xpos[b] - hp, hq_inv)
        mujoco.mju_mulQuat(rel_q, hq_inv, self.data.xquat[b])
        self.model.eq_data[eq, 0:3] = 0.0
        self.model.eq_data[eq, 3:6] = rel_p
        self.model.eq_data[eq, 6:10] = rel_q
        self.model.eq_data[eq, 10] = 1.0
        self.model.body_gravcomp[b] = 1.0
        self.data.eq_active[eq] = 1
        self.grasped = oid
        return oid

    def gripper_open(self) -> str | None:
        """Open the fingers and release the grasped bottle (weld off, weight back) RELEASE_DELAY later, once the
        fingers have left it: released at once, the fingers' unequal closing forces (one finger against two)
        pushed the bottle sideways by about 1 cm and tipped it against a finger. Returns its id or None."""
        self.data.ctrl[self._fact] = 0.0
        oid, self.grasped = self.grasped, None
        if oid is not None:
            self._release = (oid, self.data.time + RELEASE_DELAY)
        return oid

    def set_fingers(self, targets: ArrayLike) -> str | None:
        """Drive the three fingers to hinge angles `targets` (rad, 0 open .. FINGER_CLOSED, clamped). A target past
        half-closed (mean over the fingers) closes the hand as `gripper_close` does (a bottle between the fingers
        is grasped), one below it opens it as `gripper_open` does (a held bottle is released). Returns the bottle
        grasped or released, or None. BadCommandError for anything but three finite numbers."""
        try:
            t = np.asarray(targets, dtype=float).reshape(-1)
        except (TypeError, ValueError):
            raise BadCommandError(f"finger command is not a list of numbers: {targets!r}") from None
        if t.size != len(self._fact) or not np.all(np.isfinite(t)):
            raise BadCommandError(f"finger command must be {len(self._fact)} finite numbers, got {t.tolist()}")
        t = np.clip(t, 0.0, FINGER_CLOSED)
        oid = self.gripper_close() if t.mean() >= GRASP_CLOSURE * FINGER_CLOSED else self.gripper_open()
        self.data.ctrl[self._fact] = t
        return oid

    def _let_go(self, oid: str) -> None:
        b = self._bodies[oid]
        self.data.eq_active[self._welds[oid]] = 0
        self.model.body_gravcomp[b] = 0.0
        # a bottle held still sleeps with the hand (MuJoCo sleeping) and would hang in the air where it was let
        # go: a downward velocity above the sleep tolerance (2 cm/s, against 0.5 m/s after its 12 mm fall) wakes it
        self.data.qvel[self.model.jnt_dofadr[self.model.body_jntadr[b]] + 2] = -0.02
        self._release = None

    def _place_grasped(self, oid: str) -> None:
        eq, b = self._welds[oid], self._bodies[oid]
        hp, hq = self.data.xpos[self._hand], self.data.xquat[self._hand]
        p, q = np.zeros(3), np.zeros(4)
        mujoco.mju_rotVecQuat(p, self.model.eq_data[eq, 3:6], hq)
        mujoco.mju_mulQuat(q, hq, self.model.eq_data[eq, 6:10])
        adr = self.model.jnt_qposadr[self.model.body_jntadr[b]]
        vadr = self.model.jnt_dofadr[self.model.body_jntadr[b]]
        self.data.qpos[adr:adr + 3] = hp + p
        self.data.qpos[adr + 3:adr + 7] = q
        self.data.qvel[vadr:vadr + 6] = 0.0
