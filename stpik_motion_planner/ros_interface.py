"""The motion_planner node's ROS side beyond the node itself: the driver's interface as a `streaming.ArmLink`, the
trajectory and tool-path messages.

`RosArmLink`: the driver's surface as the arm interface says (`relocation_common.arm_interface`,
config/arm_interface.yaml, shared with the driver; docs/kinova.md): `kinova` = kinova-ros's j2s7s300 driver
(kinova_msgs/JointVelocity in deg/s on `<driver_prefix>/in/joint_velocity`, `<driver_prefix>/out/joint_state`, the
SetFingersPosition action `<driver_prefix>/fingers_action/finger_positions`); `ros2_control` =
`/velocity_controller/commands` (rad/s), `/gripper_controller/commands`, `/joint_states`. The joint states are read
by a SideNode on its own executor (100 Hz, never late: docs/architecture.md). A driver on another surface is found in
the ROS graph (`arm_interface.MismatchWatch`): logged, and a relocation that gets no joint state aborts with it.
"""
from __future__ import annotations

import threading
import time
from array import array
from typing import Any, Callable, Sequence

import numpy as np
import rclpy
from action_msgs.msg import GoalStatus
from builtin_interfaces.msg import Duration
from geometry_msgs.msg import Point
from kinova_msgs.action import SetFingersPosition
from kinova_msgs.msg import FingerPosition, JointVelocity
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.node import Node
from rclpy.publisher import Publisher
from rclpy.task import Future
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint
from visualization_msgs.msg import Marker

from relocation_common import robot_description as rd
from relocation_common.arm_interface import GRIPPER_TOPIC, ArmInterface, MismatchWatch
from relocation_common.node import ActionClient, SideNode
from relocation_common.ros_conversions import BASE_FRAME
from stpik_motion_planner.execution.streaming import Aborted, Cancelled
from stpik_motion_planner.planning.trajectory import Trajectory


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


def _positions(names: Sequence[str], msg: JointState) -> tuple[np.ndarray, float] | None:
    """(positions of `names`, now) from a joint state, None if one is NaN; ValueError or IndexError if one lacks."""
    q = np.array([msg.position[msg.name.index(n)] for n in names], float)
    return (q, time.monotonic()) if np.all(np.isfinite(q)) else None


class RosArmLink:
    """streaming.ArmLink over the driver's topics and fingers action as `arm` says, created on `node` (see the module
    docstring); `path` is the publisher of the `~/path` marker. Call close()."""

    def __init__(self, node: Node, arm: ArmInterface, path: Publisher) -> None:
        self.kinova, self._node, self._path = arm.kinova, node, path
        self._q: tuple[np.ndarray, float] | None = None
        self._fingers_q: tuple[np.ndarray, float] | None = None  # finger joint angles (rad), time received
        if self.kinova:  # kinova-ros's j2s7s300 driver surface: kinova_msgs, deg/s, fingers action
            self._cmd = node.create_publisher(JointVelocity, arm.velocity_topic, 10)
            self._fingers = ActionClient(node, SetFingersPosition, arm.fingers_action,
                                         callback_group=ReentrantCallbackGroup())
        else:  # ros2_control: JointGroupVelocityController, the fingers as a JointGroupPositionController
            self._cmd = node.create_publisher(Float64MultiArray, arm.velocity_topic, 10)
            self._gripper_cmd = node.create_publisher(Float64MultiArray, GRIPPER_TOPIC, 10)
        self._state = SideNode("motion_planner_joint_state", context=node.context)  # 100 Hz, never late
        self._state.node.create_subscription(JointState, arm.state_topic, self._on_joint_state, 10)
        self.state_topic = node.resolve_topic_name(arm.state_topic)
        self.watch = MismatchWatch(self._state.node, arm, "planner", node.resolve_topic_name(arm.state_topic),
                                   period=1.0, log=node.get_logger().error)

    def _on_joint_state(self, msg: JointState) -> None:
        try:
            self._q = _positions(rd.JOINT_NAMES, msg) or self._q
        except (ValueError, IndexError):
            self._node.get_logger().error("joint state without the 7 Kinova arm joints", throttle_duration_sec=5.0)
        try:
            self._fingers_q = _positions(rd.FINGER_JOINT_NAMES, msg) or self._fingers_q
        except (ValueError, IndexError):
            pass

    def close(self) -> None:
        """Stop the joint states' executor."""
        self._state.close()

    # -- streaming.ArmLink ------------------------------------------------------------------------------------
    def joint_state(self) -> tuple[np.ndarray, float] | None:
        """(arm joint angles, time received) of the latest joint state. Aborted when none ever came and the driver
        is on another surface (MismatchWatch)."""
        if self._q is None and self.watch.found is not None:
            raise Aborted(self.watch.found)
        return self._q

    def joint_state_age(self) -> float | None:
        """Seconds since the latest joint state came (None: none yet), for the node's health."""
        return None if self._q is None else time.monotonic() - self._q[1]

    def finger_state(self) -> tuple[np.ndarray, float] | None:
        """(finger joint angles, time received) of the latest joint state."""
        return self._fingers_q

    def send(self, qdot: np.ndarray) -> None:
        """One velocity command (rad/s): kinova_msgs/JointVelocity in deg/s, or ros2_control's rad/s."""
        if self.kinova:
            d = np.degrees(qdot)
            self._cmd.publish(JointVelocity(**{f"joint{i + 1}": float(d[i]) for i in range(rd.N_JOINTS)}))
        else:
            self._cmd.publish(Float64MultiArray(data=[float(x) for x in qdot]))

    def send_fingers(self, angle: float) -> None:
        """ros2_control: the three finger joints' position command (rad)."""
        self._gripper_cmd.publish(Float64MultiArray(data=[float(angle)] * len(rd.FINGER_JOINT_NAMES)))

    def show_path(self, trajectory: Trajectory, phase: str) -> None:
        """The tool path on `~/path`."""
        self._path.publish(path_marker(trajectory, phase))

    def ok(self) -> bool:
        """rclpy is not shutting down."""
        return rclpy.ok()

    def driver_present(self) -> bool:
        """A publisher of the joint states is in the graph (a SIGKILLed driver's stays until its DDS lease ends)."""
        return self._state.node.count_publishers(self.state_topic) > 0

    def finger_goal(self, turns: float, deadline: float, cancelled: Callable[[], bool]) -> np.ndarray:
        """kinova surface: a SetFingersPosition goal (Kinova turns) -> the finger positions of its result (kinova-ros
        ends a goal whose fingers stall on an object as aborted, with the positions reached)."""
        timeout = deadline - time.monotonic()
        if not self._fingers.wait_for_server(timeout_sec=timeout):
            raise Aborted(f"gripper: no fingers action server after {timeout:.0f} s (is the driver running?)")
        msg = SetFingersPosition.Goal(fingers=FingerPosition(finger1=turns, finger2=turns, finger3=turns))
        handle = _wait(self._fingers.send_goal_async(msg), deadline, cancelled, "answer to the fingers goal")
        if not handle.accepted:
            raise Aborted("gripper: the driver rejected the fingers goal")
        try:
            res = _wait(handle.get_result_async(), deadline, cancelled, "fingers result")
        except (Aborted, Cancelled):
            handle.cancel_goal_async()
            raise
        if res.status not in (GoalStatus.STATUS_SUCCEEDED, GoalStatus.STATUS_ABORTED):
            raise Aborted(f"gripper: fingers goal ended with status {res.status}")
        f = res.result.fingers
        return np.array([f.finger1, f.finger2, f.finger3], float)


def _wait(future: Future, deadline: float, cancelled: Callable[[], bool], what: str) -> Any:
    done = threading.Event()
    future.add_done_callback(lambda _: done.set())
    while not done.wait(0.02):
        if cancelled():
            raise Cancelled()
        if time.monotonic() > deadline:
            raise Aborted(f"gripper: no {what} within gripper_timeout")
    return future.result()
