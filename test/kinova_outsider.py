"""Test helpers written as an outsider to this project would write them: they know Kinova's kinova-ros driver and
ROS 2 (ros2_control's forward command controllers, tf2, robot_state_publisher), never the project's code.

Imports: rclpy and the message packages kinova_msgs, sensor_msgs, std_msgs, tf2_msgs (and rosgraph_msgs for
/clock), nothing of the project (checked by test_kinova_surface.py::test_outsider_helpers_import_no_project_code).

- `Client`: a node in its own rclpy Context, spun by a background thread; `collect`, `call`, `goal`.
- `FakeArm`: a stand-in for a Jaco2 driver, on either surface: `kinova` (kinova-ros's j2s7s300 driver:
  in/joint_velocity deg/s, out/joint_state, the fingers action) or `ros2_control` (/velocity_controller/commands
  rad/s, /gripper_controller/commands, /joint_states). It integrates the velocity commands into its joint state at
  100 Hz (zero velocity 50 ms after the last command) and moves its fingers at a finite speed; closing fingers stop
  on an imaginary object at `object_turns`, as real fingers stop on a bottle. Run it as a process of its own, as a
  driver is: `python kinova_outsider.py kinova|ros2_control q1 .. q7 [N S]` (ROS_DOMAIN_ID from the environment;
  SIGINT or SIGTERM ends it; N S: no joint states for S seconds after the N-th velocity command).
"""
from __future__ import annotations

import math
import os
import signal
import sys
import threading
import time
from typing import Any, Callable

import numpy as np
import rclpy
from kinova_msgs.action import SetFingersPosition
from kinova_msgs.msg import FingerPosition, JointVelocity
from rclpy.action import ActionClient as RclpyActionClient
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.executors import MultiThreadedExecutor, SingleThreadedExecutor
from rclpy.signals import SignalHandlerOptions
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

# Kinova's conventions (kinova-ros, noetic-devel): fingers in "turns", 0 open .. 6800 closed (README "Finger position
# control"); a finger's joint angle in out/joint_state is turns * 80/6800 degrees (kinova_arm.cpp finger_conv_ratio_);
# the fingers action succeeds within 64 turns of the goal and aborts when they stall (kinova_fingers_action.cpp).
FINGER_CLOSED = 6800.0
DEG_PER_TURN = 80.0 / 6800.0
FINGER_TOLERANCE = 64.0
# action_msgs/msg/GoalStatus values
SUCCEEDED, CANCELED, ABORTED = 4, 5, 6

ARM_JOINTS = [f"j2s7s300_joint_{i}" for i in range(1, 8)]
FINGER_JOINTS = [f"j2s7s300_joint_finger_{i}" for i in range(1, 4)]
TIP_JOINTS = [f"j2s7s300_joint_finger_tip_{i}" for i in range(1, 4)]


def turns_to_rad(turns) -> np.ndarray:
    return np.radians(np.asarray(turns, float) * DEG_PER_TURN)


def rad_to_turns(rad) -> np.ndarray:
    return np.degrees(np.asarray(rad, float)) / DEG_PER_TURN


class ActionClient(RclpyActionClient):
    """An outsider's workaround of rclpy#1123 (Jazzy wheels; the project has its own in relocation_common.node): a
    response taken before the request's sequence number was registered is dropped, its future never completes."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._registering = threading.RLock()

    def send_goal_async(self, *args, **kwargs):
        with self._registering:
            return super().send_goal_async(*args, **kwargs)

    def _get_result_async(self, goal_handle):
        with self._registering:
            return super()._get_result_async(goal_handle)

    def _cancel_goal_async(self, goal_handle):
        with self._registering:
            return super()._cancel_goal_async(goal_handle)

    async def execute(self, taken_data):
        with self._registering:
            return await super().execute(taken_data)


class Topic:
    """Messages received on one topic, with their receive times (time.monotonic())."""

    def __init__(self):
        self.msgs: list[Any] = []
        self.times: list[float] = []
        self._cond = threading.Condition()

    def _on(self, msg) -> None:
        with self._cond:
            self.msgs.append(msg)
            self.times.append(time.monotonic())
            self._cond.notify_all()

    def wait(self, predicate: Callable[[list], bool] = lambda m: len(m) > 0, timeout: float = 10.0) -> list:
        deadline = time.monotonic() + timeout
        with self._cond:
            while not predicate(self.msgs):
                left = deadline - time.monotonic()
                if left <= 0:
                    raise TimeoutError(f"condition not met within {timeout} s ({len(self.msgs)} messages)")
                self._cond.wait(left)
            return list(self.msgs)

    def next(self, timeout: float = 5.0):
        """The first message received after this call."""
        n = len(self.msgs)
        return self.wait(lambda m: len(m) > n, timeout)[n]

    def latest(self):
        with self._cond:
            return self.msgs[-1] if self.msgs else None

    def snapshot(self) -> tuple[list, list]:
        """(messages, receive times), consistent with each other."""
        with self._cond:
            return list(self.msgs), list(self.times)


def _wait_future(future, timeout: float, what: str):
    done = threading.Event()
    future.add_done_callback(lambda _: done.set())
    if not done.wait(timeout):
        raise TimeoutError(f"{what}: nothing within {timeout} s")
    return future.result()


class Client:
    """A node of the test in its own Context and domain, spun in a background thread."""

    def __init__(self, domain_id: int, name: str, threads: int = 1):
        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=domain_id, signal_handler_options=SignalHandlerOptions.NO)
        self.node = rclpy.create_node(name, context=self.context)
        self.executor = (SingleThreadedExecutor(context=self.context) if threads <= 1
                         else MultiThreadedExecutor(num_threads=threads, context=self.context))
        self.executor.add_node(self.node)
        self._thread = threading.Thread(target=self._spin, daemon=True)
        self._thread.start()

    def _spin(self) -> None:
        try:
            self.executor.spin()
        except Exception:
            if self.context.ok():
                raise

    def collect(self, msg_type, topic: str, qos: Any = 10) -> Topic:
        t = Topic()
        self.node.create_subscription(msg_type, topic, t._on, qos)
        return t

    def publisher(self, msg_type, topic: str, qos: Any = 10, timeout: float = 15.0):
        """A publisher, once the topic has a subscriber."""
        pub = self.node.create_publisher(msg_type, topic, qos)
        deadline = time.monotonic() + timeout
        while pub.get_subscription_count() < 1:
            if time.monotonic() > deadline:
                raise TimeoutError(f"no subscriber on {topic} within {timeout} s")
            time.sleep(0.02)
        return pub

    def call(self, srv_type, name: str, timeout: float = 10.0):
        cli = self.node.create_client(srv_type, name)
        try:
            if not cli.wait_for_service(timeout_sec=timeout):
                raise TimeoutError(f"service {name} not available within {timeout} s")
            return _wait_future(cli.call_async(srv_type.Request()), timeout, name)
        finally:
            self.node.destroy_client(cli)

    def action(self, action_type, name: str, timeout: float = 15.0) -> ActionClient:
        ac = ActionClient(self.node, action_type, name)
        if not ac.wait_for_server(timeout_sec=timeout):
            raise TimeoutError(f"action {name} not available within {timeout} s")
        return ac

    @staticmethod
    def goal(ac: ActionClient, goal, timeout: float = 30.0, feedback=None):
        """Send a goal, wait for its result: (status, result)."""
        handle = _wait_future(ac.send_goal_async(goal, feedback_callback=feedback), timeout, "goal response")
        if not handle.accepted:
            return None, None
        res = _wait_future(handle.get_result_async(), timeout, "goal result")
        return res.status, res.result

    def stream(self, pub, msg, duration: float, rate: float = 100.0) -> tuple[float, float]:
        """Publish msg at `rate` for `duration` s; the wall times of the first and last publish."""
        t0 = time.monotonic()
        k, last = 0, t0
        while True:
            now = time.monotonic()
            if now - t0 > duration:
                return t0, last
            pub.publish(msg)
            last = now
            k += 1
            time.sleep(max(0.0, t0 + k / rate - time.monotonic()))

    def close(self) -> None:
        self.executor.shutdown(timeout_sec=5.0)
        self._thread.join(timeout=5.0)  # before the node goes: an executor still waiting on it raises
        try:
            self.node.destroy_node()
        finally:
            if self.context.ok():
                rclpy.shutdown(context=self.context)


class FakeArm(Client):
    """A minimal Jaco2 driver: joint velocity integration at 100 Hz, fingers with an object between them."""

    RATE = 100.0
    WATCHDOG = 0.05           # s: zero velocity after the last command
    FINGER_SPEED = 10000.0    # turns/s (a real Jaco2 closes in about 1 s)
    STALL_TIME = 0.5          # s without finger motion: the fingers action aborts (kinova-ros)

    def __init__(self, domain_id: int, surface: str, q0, prefix: str = "/j2s7s300_driver",
                 object_turns: float = 1500.0, stall: tuple[int, float] | None = None):
        """stall = (n, s): after the n-th velocity command no joint state is published for s seconds (the arm
        still follows the commands), as a driver whose process was not scheduled for that long."""
        # the fingers action's execute callback blocks, so kinova needs threads; but rclpy's MultiThreadedExecutor
        # delivered 100 Hz commands with gaps up to 0.6 s (watchdog stops; a CI run's relocation failed on it), so
        # the velocity commands always come through a node of their own on a single-threaded executor
        super().__init__(domain_id, f"fake_{surface}_arm", threads=4 if surface == "kinova" else 1)
        self._io = Client(domain_id, f"fake_{surface}_arm_commands") if surface == "kinova" else self
        self.surface, self.object_turns = surface, object_turns
        self.lock = threading.Lock()
        self.q = np.asarray(q0, float).copy()
        self.v = np.zeros(7)
        self.fingers = np.zeros(3)       # turns
        self.finger_goal = np.zeros(3)
        self._cmd_time = -math.inf
        self.commands = 0                # velocity commands received
        self.max_speed = np.zeros(7)     # rad/s, largest commanded per joint
        self.finger_goals: list[float] = []  # every finger target received (turns)
        self.js_published = 0
        self.stall = stall
        self.stalled: tuple[float, float] | None = None  # wall time (time.time()) of the stall's start and end
        group = ReentrantCallbackGroup()
        if surface == "kinova":
            self._io.node.create_subscription(JointVelocity, f"{prefix}/in/joint_velocity", self._on_kinova, 10)
            self.pub = self.node.create_publisher(JointState, f"{prefix}/out/joint_state", 10)
            self.names = ARM_JOINTS + FINGER_JOINTS + TIP_JOINTS
            self._server = ActionServer(self.node, SetFingersPosition, f"{prefix}/fingers_action/finger_positions",
                                        execute_callback=self._execute_fingers,
                                        goal_callback=lambda _: GoalResponse.ACCEPT,
                                        cancel_callback=lambda _: CancelResponse.ACCEPT, callback_group=group)
        else:
            self.node.create_subscription(Float64MultiArray, "/velocity_controller/commands", self._on_velocity, 10,
                                          callback_group=group)
            self.node.create_subscription(Float64MultiArray, "/gripper_controller/commands", self._on_gripper, 10,
                                          callback_group=group)
            self.pub = self.node.create_publisher(JointState, "/joint_states", 10)
            self.names = ARM_JOINTS + FINGER_JOINTS
        self._running = True
        self._loop = threading.Thread(target=self._run, daemon=True)
        self._loop.start()

    # commands
    def _velocity(self, v_rad) -> None:
        v = np.asarray(v_rad, float)
        if v.shape != (7,) or not np.all(np.isfinite(v)):
            return
        with self.lock:
            self.v, self._cmd_time = v, time.monotonic()
            self.commands += 1
            self.max_speed = np.maximum(self.max_speed, np.abs(v))

    def _on_kinova(self, msg: JointVelocity) -> None:
        self._velocity(np.radians([msg.joint1, msg.joint2, msg.joint3, msg.joint4, msg.joint5, msg.joint6,
                                   msg.joint7]))

    def _on_velocity(self, msg: Float64MultiArray) -> None:
        self._velocity(msg.data)

    def _set_fingers(self, turns) -> None:
        g = np.clip(np.asarray(turns, float), 0.0, FINGER_CLOSED)
        with self.lock:
            self.finger_goal = g
            self.finger_goals.append(float(g.mean()))

    def _on_gripper(self, msg: Float64MultiArray) -> None:
        if len(msg.data) == 3 and all(math.isfinite(x) for x in msg.data):
            self._set_fingers(rad_to_turns(msg.data))

    def _execute_fingers(self, gh):
        f = gh.request.fingers
        goal = np.array([f.finger1, f.finger2, f.finger3], float)
        self._set_fingers(goal)
        ref, ref_t = self.fingers.copy(), time.monotonic()
        while True:
            time.sleep(0.1)  # kinova-ros checks at 10 Hz
            with self.lock:
                p = self.fingers.copy()
            result = SetFingersPosition.Result(fingers=FingerPosition(finger1=p[0], finger2=p[1], finger3=p[2]))
            if gh.is_cancel_requested:
                gh.canceled()
                return result
            if np.all(np.abs(p - goal) <= FINGER_TOLERANCE):
                gh.succeed()
                return result
            if np.any(np.abs(p - ref) > 1.0):
                ref, ref_t = p, time.monotonic()
            elif time.monotonic() - ref_t > self.STALL_TIME:
                gh.abort()  # stalled on the object, as kinova-ros ends it
                return result

    # the arm
    def _run(self) -> None:
        period = 1.0 / self.RATE
        last = next_t = time.monotonic()
        while self._running:
            now = time.monotonic()
            dt, last = now - last, now
            with self.lock:
                v = self.v if now - self._cmd_time <= self.WATCHDOG else np.zeros(7)
                self.q += v * dt
                step = self.FINGER_SPEED * dt
                target = self.finger_goal.copy()
                closing = target > self.fingers
                target[closing] = np.minimum(target[closing], self.object_turns)  # the object stops them
                self.fingers += np.clip(target - self.fingers, -step, step)
                msg = JointState(name=self.names)
                msg.header.stamp = self.node.get_clock().now().to_msg()
                extra = [0.0] * (len(self.names) - 10)
                msg.position = list(self.q) + list(turns_to_rad(self.fingers)) + extra
                msg.velocity = list(v) + [0.0] * (len(self.names) - 7)
                msg.effort = [0.0] * len(self.names)
            if self._silent(now):
                msg = None
            try:
                if msg is not None:
                    self.pub.publish(msg)
                    self.js_published += 1
            except Exception:
                if self.context.ok():
                    raise
                return
            next_t = max(next_t + period, time.monotonic())
            time.sleep(max(0.0, next_t - time.monotonic()))

    def _silent(self, now: float) -> bool:
        """In the stall: no joint states (its wall times are printed when it ends)."""
        if self.stall is None or self.commands < self.stall[0]:
            return False
        if self.stalled is None:
            self.stalled = (time.time(), time.time() + self.stall[1])
            self._stall_end = now + self.stall[1]
        if now < self._stall_end:
            return True
        print(f"stalled {self.stalled[0]:.3f} {self.stalled[1]:.3f}", flush=True)
        self.stall = None
        return False

    def close(self) -> None:
        self._running = False
        self._loop.join(timeout=2)
        if self._io is not self:
            self._io.close()
        super().close()


def main(argv: list[str]) -> int:
    surface, q0 = argv[1], [float(x) for x in argv[2:9]]
    stall = (int(argv[9]), float(argv[10])) if len(argv) > 10 else None  # optional: N SECONDS
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    arm = FakeArm(int(os.environ.get("ROS_DOMAIN_ID", "0")), surface, q0, stall=stall)
    print(f"fake {surface} arm ready", flush=True)
    while not stop.wait(0.2):
        pass
    arm.close()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
