"""What the jaco2_sim_driver node does, without ROS (the node only translates messages to and from these calls).

- The simulation loop (`SimDriver.tick`): velocity commands from a queue, paced stepping at 1 kHz of simulated
  time (`real_time_factor`; 0: as fast as it goes), and when joint states, TF and the ground truth are due.
- Kinova's arm services: in/stop and in/start (commands ignored while stopped), in/home_arm (`home`), and the
  fingers action as kinova_fingers_action.cpp serves it (`fingers`); the ros2_control gripper command (`gripper`).
- The surfaces' joint states (`joint_state`): kinova-ros's (fingers as Kinova's joint angle, finger tips at 0) or
  joint_state_broadcaster's.
- Disturbances (docs/closed_loop.md): seeded drops during carries (`drop_probability`, `drop_seed`), a planned
  DisturbancePlan (`disturbance_plan`) applied at its moments, and commands (`disturb`) applied at the next step;
  each record (JSON-ready) comes out in the loop's Tick.
- The camera's render loop (`camera_loop`, on a snapshot of the simulation, in its own thread and GL context).

Thread-safe: one lock serialises access to `Jaco2Sim`; a velocity command goes through a queue that the loop
applies at its next step (a command never waits for the lock). Units and sources: docs/kinova.md.
"""
from __future__ import annotations

import queue
import threading
import time
from dataclasses import dataclass, field, replace
from typing import Any, Callable, Iterable

import mujoco
import numpy as np
from numpy.typing import ArrayLike

from relocation_common import kinova as units
from relocation_common.arm_interface import ArmInterface
from relocation_common.config import node_section
from relocation_common.paths import config_file
from relocation_common.robot_description import BASE_LINK, FINGER_JOINT_NAMES, JOINT_NAMES, PREFIX
from relocation_common.scenario import load_scenario

from . import disturbance, kinova
from .camera import MJ_TO_OPTICAL, CameraRenderer, Frame
from .params import DriverParams
from .scene import CAMERA_NAME
from .sensor_model import SensorModel
from .sim import BadCommandError, Jaco2Sim, ObjectPose, check_velocity_command

FINGER_TIP_NAMES = tuple(f"{PREFIX}_joint_finger_tip_{i}" for i in range(1, 4))  # kinova-ros publishes them at 0
HOMED = "KINOVA ARM HAS BEEN RETURNED HOME"  # kinova-ros's HomeArm answer
HOME_SPEED = 0.5  # HomeArm: fraction of Table 7's joint speeds
HOME_GAIN = 3.0  # 1/s, HomeArm's joint-space proportional gain
HOME_TOL = 5e-4  # rad, every joint, to count as home
HOME_TIMEOUT = 30.0  # s (wall) for the arm, then for the fingers
FINGERS_OPEN = 0.02  # rad of finger hinge: open
POLL = 0.01  # s (wall) between looks at the arm or the fingers while a service or the fingers action waits
MAX_LAG = 0.5  # s of simulated time the loop may fall behind before it stops trying to catch up
MAX_BATCH = 20  # steps (ms) per tick at most: a late thread gets the GIL back late
IDLE_BATCH = 2  # steps (ms) an idle loop sleeps until they are due: a wake-up per step or more cost a fifth of a core
IDLE_MIN = 0.0002  # s, the shortest sleep of an idle loop


@dataclass(frozen=True)
class Snapshot:
    """The arm at one instant: joints (rad, rad/s, N m) and fingers in Kinova's turns (and turns/s)."""

    time: float
    q: np.ndarray
    qdot: np.ndarray
    effort: np.ndarray
    turns: np.ndarray
    turns_dot: np.ndarray


@dataclass(frozen=True)
class Tick:
    """What one step of the loop produced: `steps` physics steps, then what is due for publishing (or None)."""

    steps: int
    time: float
    state: Snapshot | None
    tf: tuple[float, np.ndarray, np.ndarray, list[ObjectPose]] | None  # (time, q, finger hinge angles, bottles)
    objects: tuple[float, list[ObjectPose]] | None
    disturbances: list[dict[str, Any]] = field(default_factory=list)  # records of disturbances applied this tick


def joint_names(surface: str) -> list[str]:
    """The joint names of the surface's joint states (kinova-ros also lists the finger tips)."""
    extra = FINGER_TIP_NAMES if surface == "kinova" else ()
    return list(JOINT_NAMES) + list(FINGER_JOINT_NAMES) + list(extra)


def joint_state(surface: str, s: Snapshot) -> tuple[list[float], list[float], list[float]]:
    """(position, velocity, effort) of the surface's joint states. Fingers as Kinova reports them: joint angle =
    turns * 80/6800 deg (kinova_arm.cpp); no finger velocity or effort on the kinova surface, whose finger tip
    joints are always 0."""
    fingers = units.turns_to_joint(s.turns)
    zeros = np.zeros(len(joint_names(surface)) - len(JOINT_NAMES))
    if surface == "kinova":
        position = np.concatenate([s.q, fingers, np.zeros(len(FINGER_TIP_NAMES))])
        velocity = np.concatenate([s.qdot, zeros])
    else:
        position = np.concatenate([s.q, fingers])
        velocity = np.concatenate([s.qdot, units.turns_to_joint(s.turns_dot)])
    return position.tolist(), velocity.tolist(), np.concatenate([s.effort, zeros]).tolist()


def _check_goal(goal: ArrayLike) -> np.ndarray:
    g = np.asarray(goal, float)
    if g.shape != (len(FINGER_JOINT_NAMES),) or not np.all(np.isfinite(g)):
        raise ValueError(f"not finite {g.tolist()}")
    return g


class SimDriver:
    """The driver's behaviour over one `Jaco2Sim` (see the module docstring) with the node's parameters: `params`
    the loop's rates and pacing, the camera's sensor model and the disturbances; `arm` the fingers' end rule
    (FingerMonitor); `log`: where grasps and refusals are told (the node's logger)."""

    def __init__(self, sim: Jaco2Sim, params: DriverParams, arm: ArmInterface,
                 log: Callable[[str], None] = lambda _: None) -> None:
        self.sim, self.params, self.log = sim, params, log
        self.sensor = SensorModel.named(params.camera_model)  # the camera's sensor model (sensor_model)
        self.finger_params = arm.finger_rule()
        self.lock = threading.Lock()
        self.stopped = False  # kinova in/stop: commands are ignored until in/start
        self._commands: queue.SimpleQueue = queue.SimpleQueue()
        self._commanded = False
        self._pace_reset = True
        self._finger_goal = 0  # sequence number of the newest fingers goal (a newer goal preempts an older one)
        self._js_period = 1.0 / params.joint_state_rate
        self._tf_period = 1.0 / params.tf_rate if params.tf_rate > 0 else float("inf")
        self._obj_period = 1.0 / params.objects_rate
        self._next_js = self._next_obj = self._next_tf = self._wall0 = self._sim0 = 0.0
        self._states = 0  # joint states made since the start (each published by the node)
        self._rate_mark = (0, 0.0)  # (states, simulated time) at the last health report
        self.camera: CameraRenderer | None = None  # the camera loop's renderer (its frames rendered and reused)
        self._disturb: queue.SimpleQueue = queue.SimpleQueue()  # commands (disturbance.command's arguments)
        self.disturbances(params.drop_probability, params.drop_seed, params.plan())

    @classmethod
    def from_params(cls, params: DriverParams, arm: ArmInterface,
                    log: Callable[[str], None] = lambda _: None) -> SimDriver:
        """The driver of the node's parameters (config/jaco2_sim_driver.yaml, config/arm_interface.yaml): the
        scenario's simulation with its camera and watchdog, then the loop as `params` and `arm` say."""
        sim = Jaco2Sim(load_scenario(params.scenario or None), camera=params.camera(),
                       watchdog_timeout=params.watchdog_timeout)
        return cls(sim, params, arm, log)

    def disturbances(self, drop_probability: float, drop_seed: int, plan: disturbance.DisturbancePlan | None) -> None:
        """Drop the carried bottle with `drop_probability` per carry (seeded) and apply `plan` at its moments
        (counted from now: the next grasp is carry 1; a relocation has ended with the arm within the motion
        planner's home_tol of home, read from config/motion_planner.yaml)."""
        self._drop = (drop_probability, drop_seed, plan)
        self.dropper = disturbance.CarryDropper(drop_probability, drop_seed)
        home_tol = float(node_section(config_file("motion_planner.yaml"), "motion_planner")["home_tol"])
        self.schedule = disturbance.DisturbanceSchedule(plan, home_tol) if plan is not None else None

    def disturb(self, parent: str, child: str, translation: Iterable[float], rotation_xyzw: Iterable[float]) -> None:
        """A disturbance command as a transform (the node's /sim/disturb): child `bottle_<id>` or `grasped`;
        parent the base frame = move the bottle there, `bottle_<id>` = relative (nudge, or tip by the rotation).
        Applied at the loop's next step; its record (or why it was skipped) comes out in a Tick."""
        self._disturb.put((parent, child, tuple(translation), tuple(rotation_xyzw)))

    def _apply_disturbances(self) -> list[dict[str, Any]]:
        """Under the lock after a step: the dropper, the schedule and the queued commands; their records."""
        s, out = self.sim, []
        dropped = self.dropper.update(s)
        if dropped is not None:
            out.append({"kind": "drop", "when": f"during carry {dropped.detail['carry'] + 1}", **dropped.to_dict()})
        if self.schedule is not None:
            out += self.schedule.update(s)
        while not self._disturb.empty():
            parent, child, t, r = self._disturb.get_nowait()
            oid = child.removeprefix("bottle_")
            relative = parent != BASE_LINK
            if relative and parent != child and oid != disturbance.GRASPED:
                out.append({"command": {"object": oid, "parent": parent}, "skipped": f"frame {parent!r}: use "
                            f"{BASE_LINK} (move) or the bottle's own frame {child} (nudge or tip)"})
                continue
            out.append(disturbance.command(s, oid, relative, t, r))
        for record in out:
            record.setdefault("sim_time", round(s.time, 3))
        return out

    # ------------------------------------------------------------------ commands
    def command(self, v: ArrayLike) -> None:
        """A joint-velocity command (rad/s), applied at the loop's next step. BadCommandError for a bad one: the arm
        holds still."""
        try:
            v = check_velocity_command(v)
        except BadCommandError:
            self.hold()
            raise
        self._commands.put(v)

    def hold(self) -> None:
        """Zero velocity at the loop's next step."""
        self._commands.put(None)

    def gripper(self, joint_angles: ArrayLike) -> str | None:
        """ros2_control's gripper command: the finger joints' angles as Kinova reports them (rad, 0 open .. 1.396
        closed); the bottle grasped or released, or None. BadCommandError, ValueError or TypeError for bad input."""
        target = kinova.turns_to_sim(units.joint_to_turns(np.asarray(joint_angles, float)))
        with self.lock:
            oid = self.sim.set_fingers(target)
        self._log_grasp(oid, float(np.mean(target)))
        return oid

    def _log_grasp(self, oid: str | None, target: float) -> None:
        if oid is not None:
            self.log(f"{'grasped' if target >= 0.5 * kinova.FINGER_CLOSED else 'released'} {oid}")

    def stop(self) -> None:
        """kinova in/stop: the arm stops at once; commands (velocities, finger goals) are ignored until start()."""
        self.stopped = True
        self.hold()

    def start(self) -> None:
        """kinova in/start."""
        self.stopped = False

    def health(self) -> tuple[int, str, dict[str, str]]:
        """The driver's status for /diagnostics (relocation_common.node.Health): the command age (simulated s
        since the last velocity command), the watchdog's stops of a moving arm, stopped (kinova in/stop: WARN), the
        joint states made and their rate per simulated second since the last report (joint_state_rate when the loop
        keeps up; fewer when its ticks come late, each then one state for up to MAX_BATCH steps), as
        diagnostic_updater's frequency status gives a topic's rate; the camera's frames rendered and reused (the
        scene unchanged since the last render: CameraRenderer)."""
        with self.lock:
            age, stops, t, states = self.sim.command_age, self.sim.watchdog_stops, self.sim.time, self._states
            (states0, t0), self._rate_mark = self._rate_mark, (states, t)
        rate = (states - states0) / (t - t0) if t > t0 else float("nan")
        state = "stopped (in/stop): commands ignored until in/start" if self.stopped else \
            "moving on commands" if age <= self.sim.watchdog_timeout else "holding still (no command)"
        values = {"command age (s)": f"{age:.3f}" if age < 1e9 else "no command yet",
                  "watchdog stops": str(stops), "stopped": str(self.stopped), "sim time (s)": f"{t:.3f}",
                  "joint states": str(states), "joint state rate (per simulated s)": f"{rate:.1f}"}
        if self.camera is not None:
            values.update({"camera frames rendered": str(self.camera.renders),
                           "camera frames reused (scene unchanged)": str(self.camera.reused)})
        return (1 if self.stopped else 0), f"arm {state}; watchdog stops: {stops}", values

    def reset(self) -> str:
        """The scenario's state, arm home, fingers open, sim time 0, started; the scenario's name."""
        with self.lock:
            self.sim.reset()
            disturbance.restore_all_contacts(self.sim)
            self.disturbances(*self._drop)
            self._pace_reset = True
            self.stopped = False
        return self.sim.scenario.name

    # ------------------------------------------------------------------ home (kinova in/home_arm)
    def home(self, ok: Callable[[], bool] = lambda: True) -> str:
        """kinova-ros's homeArm + initFingers, both waited for: the arm moves home, then the fingers open; kinova-ros's
        answer. Home is the project's Q_HOME; the motion is straight in joint space at up to HOME_SPEED of Table 7
        with no collision avoidance, as the firmware's; stop() meanwhile ends it. `ok` false: give up (shutdown)."""
        if self.stopped:
            return "Arm is stopped, cannot home"
        answer = self._move_home(ok)
        if answer == HOMED:
            with self.lock:
                self.sim.set_fingers(np.zeros(len(FINGER_JOINT_NAMES)))
            deadline = time.monotonic() + HOME_TIMEOUT
            while ok() and time.monotonic() < deadline:
                with self.lock:
                    if np.max(np.abs(self.sim.finger_q)) < FINGERS_OPEN:
                        break
                time.sleep(POLL)
        return answer

    def _move_home(self, ok: Callable[[], bool]) -> str:
        """Joint velocities toward Q_HOME (gain HOME_GAIN, at most HOME_SPEED x Table 7) through the command queue,
        every POLL s, until every joint is within HOME_TOL."""
        limit = HOME_SPEED * self.sim.qdot_max
        deadline = time.monotonic() + HOME_TIMEOUT
        while ok() and not self.stopped:
            with self.lock:
                err = self.sim.q_home - self.sim.q
            if np.max(np.abs(err)) < HOME_TOL or time.monotonic() > deadline:
                self.hold()
                return HOMED if np.max(np.abs(err)) < HOME_TOL else f"Homing did not end within {HOME_TIMEOUT:g} s"
            self._commands.put(np.clip(HOME_GAIN * err, -limit, limit))
            time.sleep(POLL)
        return "Arm is stopped, cannot home"

    # ------------------------------------------------------------------ fingers (kinova fingers action)
    def finger_turns(self) -> tuple[float, np.ndarray]:
        """(sim time, the fingers in Kinova's turns)."""
        with self.lock:
            return self.sim.time, kinova.sim_to_turns(self.sim.finger_q)

    def fingers(self, goal: ArrayLike, cancelled: Callable[[], bool] = lambda: False,
                ok: Callable[[], bool] = lambda: True,
                feedback: Callable[[np.ndarray], None] = lambda _: None) -> tuple[str, np.ndarray]:
        """SetFingersPosition as kinova_fingers_action.cpp serves it, for `goal` (turns of the three fingers):
        ("succeed", turns) when the fingers are within the tolerance of the goal; ("abort", turns) when they stall
        (closed on an object), when the arm is stopped, when a newer goal comes, for a goal that is not three finite
        numbers, or when `ok()` turns false; ("canceled", turns) on `cancelled()`, the fingers stopped where they
        are. `feedback(turns)` every 10 polls, from the first."""
        with self.lock:
            self._finger_goal += 1
            seq = self._finger_goal
        t, p = self.finger_turns()
        if self.stopped:
            self.log("Could not complete finger action because the arm is stopped")
            return "abort", p
        try:
            goal = _check_goal(goal)
        except ValueError as e:
            self.log(f"finger goal rejected: {e}")
            return "abort", p
        with self.lock:
            oid = self.sim.set_fingers(kinova.turns_to_sim(goal))
        self._log_grasp(oid, float(np.mean(kinova.turns_to_sim(goal))))
        monitor = units.FingerMonitor(goal, t, p, **self.finger_params)
        k = 0
        while True:
            time.sleep(POLL)
            t, p = self.finger_turns()
            if not ok():
                return "abort", p
            if cancelled():
                with self.lock:
                    self.sim.set_fingers(self.sim.finger_q)
                return "canceled", p
            if self.stopped or seq != self._finger_goal:
                return "abort", p
            if k % 10 == 0:  # before the verdict: a goal over at its first look (its thread starved on a loaded
                feedback(p)  # machine while the fingers moved) still reports them once
            k += 1
            status = monitor.update(t, p)
            if status != monitor.MOVING:  # a stall ends the goal as aborted, with the positions reached (kinova-ros)
                return ("succeed" if status == monitor.REACHED else "abort"), p

    # ------------------------------------------------------------------ the simulation loop
    def tick(self) -> Tick:
        """One step of the loop: apply the queued commands, step the physics as far as the pacing says (at most
        MAX_BATCH steps; one when real_time_factor is 0), and say what is due for publishing."""
        r, s = self.params, self.sim
        with self.lock:
            if self._pace_reset:
                self._wall0, self._sim0 = time.monotonic(), s.time
                self._next_js = self._next_obj = self._next_tf = s.time
                self._pace_reset = False
            while not self._commands.empty():
                v = self._commands.get_nowait()
                if v is None:
                    s.stop()
                else:
                    s.set_velocity(v)
                    self._commanded = True
            n = self._steps_due(s.time)
            if n > 0:
                s.step(n)
            records = self._apply_disturbances() if n > 0 or not self._disturb.empty() else []
            t = s.time
            state = tf = objects = None
            if t >= self._next_js or (self._commanded and r.state_on_command and n > 0):
                self._commanded = False
                if t >= self._next_js:
                    self._next_js += self._js_period * max(1, int((t - self._next_js) / self._js_period) + 1)
                state = self.snapshot()
                self._states += 1
            if t >= self._next_tf:
                self._next_tf += self._tf_period * max(1, int((t - self._next_tf) / self._tf_period) + 1)
                tf = (t, s.q, s.finger_q, s.object_poses())
            if t >= self._next_obj:
                self._next_obj = t + self._obj_period
                objects = (t, s.object_poses())
        return Tick(n, t, state, tf, objects, records)

    def _steps_due(self, t: float) -> int:
        if self.params.real_time_factor <= 0:
            return 1
        target = self._sim0 + (time.monotonic() - self._wall0) * self.params.real_time_factor
        if target - t > MAX_LAG:  # too slow: drop the backlog instead of racing
            self._sim0, self._wall0 = t, time.monotonic()
            target = t
        return min(int((target - t) / float(self.sim.model.opt.timestep)), MAX_BATCH)

    def idle_time(self) -> float:
        """Wall seconds an idle loop (its tick stepped nothing) sleeps: until IDLE_BATCH steps are due, at least
        IDLE_MIN; IDLE_MIN when running as fast as possible. A command that comes meanwhile waits at most that long
        (the Kinova driver's own control loop runs at 100 Hz)."""
        r = self.params.real_time_factor
        if r <= 0:
            return IDLE_MIN
        with self.lock:
            due = self._sim0 + (time.monotonic() - self._wall0) * r
            lag = self.sim.time + IDLE_BATCH * float(self.sim.model.opt.timestep) - due
        return max(IDLE_MIN, lag / r)

    def snapshot(self) -> Snapshot:
        """The arm now (call with the lock held, or from the loop's thread)."""
        s = self.sim
        return Snapshot(s.time, s.q, s.qdot, s.effort, kinova.sim_to_turns(s.finger_q),
                        kinova.sim_to_turns(s.finger_qdot))

    # ------------------------------------------------------------------ camera
    def camera_transform(self) -> tuple[float, np.ndarray]:
        """(sim time, 4x4 pose of the camera's optical frame in the base frame): for /tf_static."""
        with self.lock:
            cam = self.sim.model.camera(CAMERA_NAME).id
            t_cam = np.eye(4)
            t_cam[:3, :3] = self.sim.data.cam_xmat[cam].reshape(3, 3) @ MJ_TO_OPTICAL
            t_cam[:3, 3] = self.sim.data.cam_xpos[cam]
            return self.sim.time, t_cam

    def camera_loop(self, period: float, publish: Callable[[Frame], bool], stop: threading.Event) -> None:
        """Render a frame of the current scene every `period` s (wall) and hand it to `publish` until `stop` is set
        or `publish` returns False. Renders on a copy of the joint positions (the lock is held only to copy), with
        its own renderer: call it in the thread that owns the GL context. Each frame's `wall` is the wall-clock time
        of that copy, not of the publishing: at a load average of 25 a render took far longer than its 75 ms, and a
        frame stamped when published showed the arm where it had been before its stamp (perception's self-filter
        then took the joint states of the wrong instant and left pieces of the arm as unlisted objects). A frame of
        an unchanged scene is not rendered again (CameraRenderer): its images are the last render's."""
        model, spec = self.sim.model, self.sim.camera
        renderer = self.camera = CameraRenderer(model, spec.width, spec.height, sensor=self.sensor)
        data = mujoco.MjData(model)
        next_t = time.monotonic()
        try:
            while not stop.is_set():
                with self.lock:
                    data.qpos[:] = self.sim.data.qpos
                    data.time = self.sim.data.time
                    wall = time.time()
                mujoco.mj_kinematics(model, data)
                mujoco.mj_camlight(model, data)
                if not publish(replace(renderer.render(data), wall=wall)):
                    return
                next_t += period
                delay = next_t - time.monotonic()
                if delay > 0:
                    if stop.wait(delay):
                        return
                else:
                    next_t = time.monotonic()
        finally:
            renderer.close()
