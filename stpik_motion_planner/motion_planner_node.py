"""motion_planner node: a thin ROS 2 shell over stpik_motion_planner.feasibility.MotionPlanner (paper Sect. 4.1).

- service `~/plan_feasibility` (PlanFeasibility): Eq. 11's answer g_U / g_O / g_T for (object, removed set),
  with the home -> grasp trajectory unless the request asks for the label only; a bad request answers ok=false
  with the reason, the node keeps serving. Served by its own executor thread (SideNode), not the main executor.
- action `~/relocate` (RelocateObject): plan the pick, stream joint velocities at 100 Hz with feedback from the
  joint states, close the gripper, plan and stream the carry to the next slot of the bottom shelf, release,
  retreat, plan and stream the way home. Feedback by phase; cancel stops the arm; a silent driver aborts the goal
  with the reason. The driver's surface is `command_interface` (docs/kinova.md): `kinova` = kinova-ros's
  j2s7s300 driver (kinova_msgs/JointVelocity deg/s on `<driver_prefix>/in/joint_velocity`,
  `<driver_prefix>/out/joint_state`, the SetFingersPosition action `<driver_prefix>/fingers_action/finger_positions`);
  `ros2_control` = `/velocity_controller/commands` (rad/s), `/gripper_controller/commands`, `/joint_states`.
- `~/path` (visualization_msgs/Marker, latched): the tool path of the motion being executed, as a line strip.
- the scene: the scenario file (shelf, slots, initial bottles), updated from `scene_topic` (ObjectArray,
  transient local). Bottles no longer on the top shelf are ignored; bottles not seen keep their last pose.
"""
from __future__ import annotations

import math
import threading
import time
from array import array

import numpy as np
import rclpy
from action_msgs.msg import GoalStatus
from builtin_interfaces.msg import Duration
from geometry_msgs.msg import Point
from kinova_msgs.action import SetFingersPosition
from kinova_msgs.msg import FingerPosition, JointVelocity
from qtree_relocation_msgs.action import RelocateObject
from qtree_relocation_msgs.msg import ObjectArray
from qtree_relocation_msgs.srv import PlanFeasibility
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.node import Node
from rclpy.qos import QoSDurabilityPolicy, QoSProfile
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint
from visualization_msgs.msg import Marker

from relocation_common import kinova
from relocation_common.node import ActionClient, SideNode, abort_with_reason, declare_parameters, end_goal, node_main
from relocation_common.ros_conversions import BASE_FRAME, NO_ANSWER, blockers_to_msgs, lanes_to_msgs, msg_to_bottles
from relocation_common.scenario import ScenarioError, UnknownObjectError, load_scenario
from relocation_common.scene_check import check_scene

from . import goal_check
from . import robot_description as rd
from .blockers import lane_blockers
from .execution import FollowerParams, TrajectoryFollower
from .feasibility import MotionPlanner, PlannerParams, PlanningError, SafetyNetTimeout
from .relocation import PHASES, Progress, recover, relocate
from .scene_update import merge_perceived
from .trajectory import Trajectory

SCENE_QOS = QoSProfile(depth=1, durability=QoSDurabilityPolicy.TRANSIENT_LOCAL)
# Requests queue here while one is planned: the default depth 10 dropped all but 11 of 50 concurrent requests
# silently (their clients waited forever); 1000 answers a burst of a whole tree level.
SERVICE_QOS = QoSProfile(depth=1000)
INTERFACES = ("kinova", "ros2_control")  # command_interface: the driver's surface (docs/kinova.md)
VELOCITY_TOPIC = "/velocity_controller/commands"  # ros2_control JointGroupVelocityController (rad/s)
GRIPPER_TOPIC = "/gripper_controller/commands"    # ros2_control JointGroupPositionController, finger joints (rad)


def trajectory_to_msg(traj: Trajectory | None) -> JointTrajectory:
    """The 100 Hz trajectory as a message. Positions and velocities as array('d'): the message takes them without
    checking each float (half the time of lists here, and a third of the serialisation)."""
    msg = JointTrajectory()
    if traj is None:
        return msg
    msg.joint_names = list(traj.joint_names)
    points = []
    pos, vel = (np.ascontiguousarray(x, dtype=np.float64) for x in (traj.positions, traj.velocities))
    for t, q, v in zip(np.asarray(traj.times, float).tolist(), pos, vel):
        sec = int(t)
        point = JointTrajectoryPoint()
        point.positions = array("d", q.tobytes())
        point.velocities = array("d", v.tobytes())
        point.time_from_start = Duration(sec=sec, nanosec=int(round((t - sec) * 1e9)))
        points.append(point)
    msg.points = points
    return msg


def path_marker(traj: Trajectory, phase: str, every: int = 5) -> Marker:
    """The tool path of a joint trajectory (forward kinematics of the DH table) as a LINE_STRIP."""
    m = Marker(ns="tool_path", id=0, type=Marker.LINE_STRIP, action=Marker.ADD, text=phase)
    m.header.frame_id = BASE_FRAME
    m.pose.orientation.w = 1.0
    m.scale.x = 0.006
    m.color.r, m.color.g, m.color.b, m.color.a = 1.0, 0.55, 0.0, 1.0
    idx = list(range(0, len(traj), every)) + [len(traj) - 1]
    for k in idx:
        x, y, z = rd.dh_fk(traj.positions[k])[-1][:3, 3]
        m.points.append(Point(x=float(x), y=float(y), z=float(z)))
    return m


class _Aborted(Exception):
    """A relocation that cannot go on (the message is the reason sent back in the result)."""


class _Cancelled(Exception):
    pass


class MotionPlannerNode(Node):
    def __init__(self) -> None:
        super().__init__("motion_planner")
        params = declare_parameters(self)  # config/motion_planner.yaml: planner, follower.* and node keys
        planner_params = PlannerParams.from_mapping({k: v for k, v in params.items() if k in PlannerParams.keys()})
        self.follower_params = FollowerParams(**{k.split(".", 1)[1]: float(v) for k, v in params.items()
                                                 if k.startswith("follower.")})
        self.base = load_scenario(self.p("scenario") or None)
        self.planner = MotionPlanner(self.base, planner_params)
        self.qdot_max = planner_params.stpik.qdot_max
        self._plan_lock = threading.Lock()  # MotionPlanner is not thread-safe
        self._bottles = {b.id: b for b in self.base.objects}
        self._q: tuple[np.ndarray, float] | None = None
        self._relocating = threading.Lock()
        self._slot = 0  # the running relocation's slot
        self._held: str | None = None  # the object of the running relocation: its perceived pose is ignored
        self._relocated: dict[str, int] = {}  # object -> slot, relocated by this node (until seen on the top shelf)
        self._scene = goal_check.SceneWatch()  # the last scene as received

        self._state = None
        self._arm_interface()  # nothing in a feasibility-only replica (serve_relocation false)
        self.create_subscription(ObjectArray, self.p("scene_topic"), self._on_scene, SCENE_QOS,
                                 callback_group=MutuallyExclusiveCallbackGroup())
        # the feasibility service on a node of its own, spun by its own single-threaded executor (a thread): an
        # answer waits for no thread of the main executor (held by relocations) and scans a wait set of one service
        self._feas = SideNode("motion_planner_feasibility", context=self.context)
        self._feas.node.create_service(PlanFeasibility, self.resolve_service_name("~/plan_feasibility"),
                                       self._on_feasibility, qos_profile=SERVICE_QOS)
        if self.p("serve_relocation"):
            self._server = ActionServer(self, RelocateObject, "~/relocate", execute_callback=self._execute,
                                        goal_callback=self._on_goal, cancel_callback=lambda _: CancelResponse.ACCEPT,
                                        callback_group=ReentrantCallbackGroup())
        driver = str(self.p("driver_prefix")) if self._kinova else "ros2_control"
        self.get_logger().info(f"ready: scenario {self.base.name} ({len(self.base.objects)} bottles), service "
                               f"{self.resolve_service_name('~/plan_feasibility')}, scene from "
                               f"{self.p('scene_topic')}, " + (f"driver {driver}" if self._state else
                                                               "feasibility only (serve_relocation false)"))

    def p(self, name: str):
        return self.get_parameter(name).value

    def _arm_interface(self) -> None:
        """The driver's command and state topics, as command_interface says (docs/kinova.md)."""
        pre = str(self.p("driver_prefix")).rstrip("/")
        interface = str(self.p("command_interface"))
        if interface not in INTERFACES:
            raise ValueError(f"parameter command_interface must be one of {', '.join(INTERFACES)}, got {interface!r}")
        self._kinova = interface == "kinova"
        if not self.p("serve_relocation"):
            return
        goal_check.check_parameters({k: self.p(k) for k in goal_check.PARAMETERS})
        if not 0.0 < float(self.p("state_hold")) < float(self.p("state_timeout")):
            raise ValueError(f"parameters state_hold and state_timeout must satisfy 0 < state_hold < state_timeout, "
                             f"got {self.p('state_hold')} and {self.p('state_timeout')}")
        self._fingers_q: tuple[np.ndarray, float] | None = None  # finger joint angles (rad), time received
        if self._kinova:  # kinova-ros's j2s7s300 driver surface: kinova_msgs, deg/s, fingers action
            self._cmd = self.create_publisher(JointVelocity, f"{pre}/in/joint_velocity", 10)
            self._fingers = ActionClient(self, SetFingersPosition, f"{pre}/fingers_action/finger_positions",
                                         callback_group=ReentrantCallbackGroup())
            state_topic = f"{pre}/out/joint_state"
        else:  # ros2_control: JointGroupVelocityController, the fingers as a JointGroupPositionController
            self._cmd = self.create_publisher(Float64MultiArray, VELOCITY_TOPIC, 10)
            self._gripper_cmd = self.create_publisher(Float64MultiArray, GRIPPER_TOPIC, 10)
            state_topic = "/joint_states"
        self._path = self.create_publisher(Marker, "~/path", SCENE_QOS)
        self._state = SideNode("motion_planner_joint_state", context=self.context)  # 100 Hz, never late
        self._state.node.create_subscription(JointState, state_topic, self._on_joint_state, 10)
        self._state.node.create_subscription(JointState, state_topic, self._on_finger_state, 10)

    def close(self) -> None:
        self._feas.close()
        if self._state is not None:
            self._state.close()

    # -- inputs ---------------------------------------------------------------------------------------------
    def _on_joint_state(self, msg: JointState) -> None:
        try:
            idx = [msg.name.index(n) for n in rd.JOINT_NAMES]
            q = np.array([msg.position[i] for i in idx], float)
        except (ValueError, IndexError):
            self.get_logger().error("joint state without the 7 Kinova arm joints", throttle_duration_sec=5.0)
            return
        if np.all(np.isfinite(q)):
            self._q = (q, time.monotonic())

    def _on_scene(self, msg: ObjectArray) -> None:
        """Bottles standing on the top shelf replace the planner's; the rest of the scene stays."""
        try:
            bottles = msg_to_bottles(msg)
        except ScenarioError as e:
            self.get_logger().error(f"scene ignored: {e}", throttle_duration_sec=5.0)
            return
        perceived = [(b, o.pose.position.z) for b, o in zip(bottles, msg.objects)]
        try:
            check_scene(self.base, [(b.id, b.x, b.y, z) for b, z in perceived], f"scene on {self.p('scene_topic')}")
        except ScenarioError as e:
            self.get_logger().warning(f"scene ignored: {e}", throttle_duration_sec=5.0)
            return
        self._scene.update((b.id, b.x, b.y, z) for b, z in perceived)
        merged, changed, seen = merge_perceived(self.base.shelf, self._bottles, perceived, self._held)
        for i in seen:  # seen back on the top shelf (a reset scene): it can be relocated again
            self._relocated.pop(i, None)
        if not changed:
            return
        try:
            scenario = self.base.with_objects(merged.values())
        except ScenarioError as e:
            self.get_logger().error(f"scene ignored: {e}", throttle_duration_sec=5.0)
            return
        with self._plan_lock:
            self.planner.set_scenario(scenario)
            self._bottles = merged
        self.get_logger().info(f"scene updated from {self.p('scene_topic')}: {sorted(changed)}")

    # -- feasibility (Eq. 11) -------------------------------------------------------------------------------
    def _on_feasibility(self, req, res):
        res.ok = False
        try:
            if not math.isfinite(req.timeout):
                raise ValueError(f"timeout must be a finite number of seconds (<= 0: the default), got {req.timeout}")
            timeout = float(req.timeout) if req.timeout > 0 else None
            lanes_only = req.all_lanes and not req.object_id  # every object's lane blockers, no question asked
            with self._plan_lock:
                lanes = lane_blockers(self.planner, list(req.removed_ids)) if req.all_lanes else {}
                ans = None if lanes_only else self.planner.feasibility(req.object_id, list(req.removed_ids),
                                                                       timeout)
        except (UnknownObjectError, ScenarioError, ValueError, TypeError) as e:
            res.message = str(e)
            self.get_logger().warning(f"feasibility request refused: {e}")
            return res
        except SafetyNetTimeout as e:
            res.message = f"{NO_ANSWER}{e}"
            self.get_logger().warning(res.message)
            return res
        except Exception as e:  # a planner bug must not take the node down
            res.message = f"internal planner error: {type(e).__name__}: {e}"
            self.get_logger().error(res.message)
            return res
        res.ok, res.lanes = True, lanes_to_msgs(lanes)
        if ans is None:
            res.message = "lanes only"
            return res
        res.label, res.planning_time = int(ans.label), float(ans.planning_time)
        res.attempts, res.message = int(ans.attempts), ans.message
        if not req.label_only:  # training asks for the label only; execution for the trajectory too
            res.trajectory = trajectory_to_msg(ans.trajectory)
        res.blockers = blockers_to_msgs(ans.blockers)
        return res

    # -- relocation -----------------------------------------------------------------------------------------
    def _on_goal(self, goal) -> GoalResponse:
        if self._relocating.locked():
            self.get_logger().error("relocation goal rejected: a relocation is already running")
            return GoalResponse.REJECT
        return GoalResponse.ACCEPT

    def _execute(self, goal_handle):
        result = RelocateObject.Result()
        progress = Progress()
        why = goal_check.goal_refusal(self.base, goal_handle.request.object_id, list(goal_handle.request.removed_ids),
                                      self._scene.seen, self._relocated)
        if why is not None:  # accepted, then aborted with the reason: the client learns why (as nav2 does)
            return abort_with_reason(goal_handle, result, f"relocation goal refused: {why}", self.get_logger())
        with self._relocating:
            self._held = oid = goal_handle.request.object_id
            try:
                before, slot = dict(self._scene.seen), self._relocate(goal_handle, progress)
                self._relocated[oid] = slot
                result.success, result.message = goal_check.outcome(
                    self._scene, before, self.base, oid, slot, {k: self.p(k) for k in goal_check.PARAMETERS},
                    self.p("scene_topic"), rclpy.ok)
                end_goal(goal_handle, "succeed" if result.success else "abort")
            except _Cancelled:
                self._stop()
                result.message = "cancelled: arm stopped" + self._recover(goal_handle, progress)
                goal_handle.canceled()
            except Exception as e:  # planning, the arm, bad input; a bug ends the goal with its reason, not the node
                self._stop()
                known = isinstance(e, (_Aborted, PlanningError, UnknownObjectError, ValueError))
                result.message = str(e) if known else f"internal error: {type(e).__name__}: {e}"
                self.get_logger().error(f"relocation of {goal_handle.request.object_id} aborted: {result.message}")
                result.message += self._recover(goal_handle, progress)
                goal_handle.abort()
            finally:
                self._held = None
        return result

    def _recover(self, gh, progress: Progress) -> str:
        """After a failed or cancelled goal: relocation.recover (the bottle set down where it was picked, the arm
        home), not cancellable itself; unless the node is shutting down. The text added to the result message."""
        if not rclpy.ok() or not progress.moves:
            return ""
        try:
            self._measured()  # a driver that is gone: fail now, not after the gripper's timeout
            what = recover(self.planner, _GoalArm(self, _Uncancellable(gh)), progress, self._plan_lock)
        except Exception as e:
            self.get_logger().error(f"recovery after the failed relocation failed: {e}")
            return f"; recovery failed: {e}"
        self.get_logger().info(f"recovered: {what}")
        if progress.released:
            self._relocated[progress.object_id] = self._slot
        return f"; recovered: {what}"

    def _relocate(self, gh, progress: Progress) -> int:
        """Carry the goal's object to a free slot (goal_check); returns the slot."""
        deadline = time.monotonic() + 5.0  # right after start-up, discovery of the driver can take a moment
        while self._q is None and time.monotonic() < deadline:
            time.sleep(0.05)
        self._slot, placed = goal_check.destination(self.base, self._scene.seen, self._relocated)
        relocate(self.planner, _GoalArm(self, gh), gh.request.object_id, list(gh.request.removed_ids),
                 home_tol=self.p("home_tol"), lock=self._plan_lock, progress=progress, slot=self._slot,
                 placed=placed)
        return self._slot

    def _measured(self, gh=None) -> np.ndarray:
        """The latest joint angles. Older than state_hold: the arm is held (zero velocity, as a Kinova driver that
        gets no commands does) until a fresh state arrives; older than state_timeout: the relocation aborts."""
        return self._fresh_state(gh)[0]

    def _fresh_state(self, gh=None) -> tuple[np.ndarray, float]:
        """(joint angles, seconds the arm was held waiting for them)."""
        t0 = time.monotonic()
        held = False
        while True:
            st = self._q
            now = time.monotonic()
            age = math.inf if st is None else now - st[1]
            if age <= self.p("state_hold"):
                if held:
                    self.get_logger().warning(f"joint states back after {age_max:.2f} s: the arm was held "
                                              f"{now - t0:.2f} s", throttle_duration_sec=1.0)
                return st[0].copy(), (now - t0) if held else 0.0
            if age > self.p("state_timeout"):
                raise _Aborted(f"no joint state from the driver for {age:.1f} s (> state_timeout): "
                               f"is jaco2_sim_driver (or the Kinova driver) running?")
            if gh is not None and gh.is_cancel_requested:
                raise _Cancelled()
            if not rclpy.ok():
                raise _Aborted("node shutting down")
            if not held:
                self._stop()
                held = True
            age_max = age
            time.sleep(0.005)

    def _feedback(self, gh, phase: str, within: float = 0.0) -> None:
        names = list(PHASES)
        k = names.index(phase)
        lo, hi = PHASES[phase], PHASES[names[min(k + 1, len(names) - 1)]]
        gh.publish_feedback(RelocateObject.Feedback(phase=phase, progress=float(lo + (hi - lo) * within)))

    def _follow(self, gh, traj: Trajectory, phase: str) -> None:
        """Stream the trajectory at stream_rate with position feedback until it settles (execution.py)."""
        follower = TrajectoryFollower(traj, self.qdot_max, self.follower_params)
        self._path.publish(path_marker(traj, phase))
        period = 1.0 / float(self.p("stream_rate"))
        last = next_tick = time.monotonic()
        tick = 0
        while True:
            if gh.is_cancel_requested:
                raise _Cancelled()
            if not rclpy.ok():
                raise _Aborted("node shutting down")
            q, held = self._fresh_state(gh)
            now = time.monotonic()
            status = follower.update(q, period if held else now - last)  # the reference waits while held
            last = now
            if status == follower.SETTLED:
                self._stop()
                return
            if status == follower.FAILED:
                raise _Aborted(f"{phase}: {follower.reason}")
            self._send(follower.command(q))
            if tick % 10 == 0:
                self._feedback(gh, phase, follower.progress)
            tick += 1
            next_tick = max(next_tick + period, now)
            time.sleep(max(0.0, next_tick - time.monotonic()))

    def _send(self, v: np.ndarray) -> None:
        """One velocity command (rad/s): kinova_msgs/JointVelocity in deg/s, or ros2_control's rad/s."""
        if self._kinova:
            d = np.degrees(v)
            self._cmd.publish(JointVelocity(**{f"joint{i + 1}": float(d[i]) for i in range(rd.N_JOINTS)}))
        else:
            self._cmd.publish(Float64MultiArray(data=[float(x) for x in v]))

    def _stop(self) -> None:
        if rclpy.ok():
            for _ in range(3):
                self._send(np.zeros(rd.N_JOINTS))

    def _gripper_call(self, gh, action: str, phase: str) -> None:
        """Close or open the fingers and wait until they stop: a kinova_msgs SetFingersPosition goal and its result
        (kinova-ros ends a goal whose fingers stall on an object as aborted, with the positions reached), or on
        ros2_control the finger joints' position command, watched in the joint states. Closing has to stop short
        of `finger_empty_closure` (a bottle is between the fingers), opening has to open, or the relocation aborts."""
        self._feedback(gh, phase)
        closing = action == "close"
        closed = float(self.p("finger_closed"))
        goal = closed if closing else 0.0
        timeout = float(self.p("gripper_timeout"))
        turns = self._fingers_action(gh, goal, timeout) if self._kinova else self._fingers_command(gh, goal, timeout)
        closure = float(np.mean(turns)) / closed
        if closing and closure > float(self.p("finger_empty_closure")):
            raise _Aborted(f"gripper close: the fingers closed on nothing ({closure:.0%} closed)")
        if closing and closure < 0.02:
            raise _Aborted("gripper close: the fingers did not move")
        if not closing and closure > 0.1:
            raise _Aborted(f"gripper open: the fingers stopped {closure:.0%} closed")
        self.get_logger().info(f"gripper {action}: fingers stopped {closure:.0%} closed")
        time.sleep(float(self.p("gripper_settle")))

    def _wait_future(self, gh, future, deadline: float, what: str):
        done = threading.Event()
        future.add_done_callback(lambda _: done.set())
        while not done.wait(0.02):
            if gh.is_cancel_requested:
                raise _Cancelled()
            if time.monotonic() > deadline:
                raise _Aborted(f"gripper: no {what} within gripper_timeout")
        return future.result()

    def _fingers_action(self, gh, goal: float, timeout: float) -> np.ndarray:
        """kinova surface: SetFingersPosition goal (Kinova turns) -> the finger positions of its result."""
        deadline = time.monotonic() + timeout
        if not self._fingers.wait_for_server(timeout_sec=timeout):
            raise _Aborted(f"gripper: no fingers action server after {timeout:.0f} s (is the driver running?)")
        msg = SetFingersPosition.Goal(fingers=FingerPosition(finger1=goal, finger2=goal, finger3=goal))
        handle = self._wait_future(gh, self._fingers.send_goal_async(msg), deadline, "answer to the fingers goal")
        if not handle.accepted:
            raise _Aborted("gripper: the driver rejected the fingers goal")
        try:
            res = self._wait_future(gh, handle.get_result_async(), deadline, "fingers result")
        except (_Aborted, _Cancelled):
            handle.cancel_goal_async()
            raise
        if res.status not in (GoalStatus.STATUS_SUCCEEDED, GoalStatus.STATUS_ABORTED):
            raise _Aborted(f"gripper: fingers goal ended with status {res.status}")
        f = res.result.fingers
        return np.array([f.finger1, f.finger2, f.finger3], float)

    def _on_finger_state(self, msg: JointState) -> None:
        try:
            q = np.array([msg.position[msg.name.index(n)] for n in rd.FINGER_JOINT_NAMES], float)
        except (ValueError, IndexError):
            return
        if np.all(np.isfinite(q)):
            self._fingers_q = (q, time.monotonic())

    def _fingers_command(self, gh, goal: float, timeout: float) -> np.ndarray:
        """ros2_control surface: the finger joints' position (Kinova's joint angle of `goal` turns) on the gripper
        controller, then the joint states until the fingers reach it or stall, as Kinova's action decides."""
        deadline = time.monotonic() + timeout
        cmd = Float64MultiArray(data=[float(kinova.turns_to_joint(goal))] * len(rd.FINGER_JOINT_NAMES))
        monitor = None
        while True:
            self._gripper_cmd.publish(cmd)  # forward command: repeating it is harmless and survives a lost message
            time.sleep(0.02)
            if gh.is_cancel_requested:
                raise _Cancelled()
            now, st = time.monotonic(), self._fingers_q
            if now > deadline:
                raise _Aborted("gripper: the fingers did not stop within gripper_timeout")
            if st is None or now - st[1] > self.p("state_timeout"):
                continue
            turns = kinova.joint_to_turns(st[0])
            if monitor is None:
                monitor = kinova.FingerMonitor([goal] * len(turns), now, turns, self.p("finger_tolerance"),
                                               self.p("finger_stall_threshold"), self.p("finger_stall_interval"))
            elif monitor.update(now, turns) != monitor.MOVING:
                return turns


class _Uncancellable:
    """A goal handle whose cancel request is not seen (the recovery after a cancel runs to its end); feedback goes
    to the real goal."""

    is_cancel_requested = False

    def __init__(self, gh) -> None:
        self.publish_feedback = gh.publish_feedback


class _GoalArm:
    """relocation.Arm over ROS for one RelocateObject goal: streaming, gripper, feedback."""

    def __init__(self, node: MotionPlannerNode, goal_handle):
        self.node, self.gh = node, goal_handle

    def measured(self) -> np.ndarray:
        return self.node._measured(self.gh)

    def follow(self, trajectory: Trajectory, phase: str) -> None:
        self.node._follow(self.gh, trajectory, phase)

    def gripper(self, action: str, phase: str) -> None:
        self.node._gripper_call(self.gh, action, phase)

    def phase(self, phase: str) -> None:
        self.node._feedback(self.gh, phase)


def main(args=None) -> None:
    node_main("motion_planner", MotionPlannerNode, args, threads=6)


if __name__ == "__main__":
    main()
