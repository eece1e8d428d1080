"""jaco2_sim_driver node: the MuJoCo Jaco2 behind the interface of a real arm, selected by `command_interface`:
- `kinova`: kinova-ros's j2s7s300 driver surface (kinova_msgs; units and sources in docs/kinova.md) under
  `driver_prefix`: in/joint_velocity, out/joint_state, out/joint_angles, out/finger_position, the action
  fingers_action/finger_positions, the services in/home_arm, in/start, in/stop.
- `ros2_control`: a JointGroupVelocityController (/velocity_controller/commands), the fingers as a
  JointGroupPositionController (/gripper_controller/commands) and a joint_state_broadcaster (/joint_states).
Both: what robot_state_publisher publishes (/robot_description, /tf_static, /tf, plus the bottles' ground truth on
/tf), the camera, /sim/objects, /clock, the simulator's own `<driver_prefix>/in/reset_scene`, and disturbances:
/sim/disturb (TransformStamped) in, /sim/disturbances (String, one JSON record each, transient local) out.
A shell: parameters, topics, services and the fingers action translated to and from `driver.SimDriver`, where the
behaviour is (the loop's pacing, the arm services, the fingers protocol, the surfaces' joint states). Threads: the
executor (commands, services), the simulation loop (`SimDriver.tick`, then publishing), the camera
(`SimDriver.camera_loop`, publishing in `publish_camera_frame`) and, on the kinova surface, the fingers action's own
executor (a goal waits until the fingers stop). Interface: docs/sim_driver.md; the settings shared with the motion
planner: config/arm_interface.yaml (relocation_common.arm_interface; a planner on another surface is logged).
"""
from __future__ import annotations

import json
import threading
import time
from typing import Callable, Iterable, Sequence

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import PoseStamped, TransformStamped
from kinova_msgs.action import SetFingersPosition
from kinova_msgs.msg import FingerPosition, JointAngles, JointVelocity
from kinova_msgs.srv import HomeArm, Start, Stop
from qtree_relocation_msgs.msg import ObjectArray
from rclpy._rclpy_pybind11 import RCLError
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.action.server import ServerGoalHandle
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.node import Node
from rclpy.qos import QoSDurabilityPolicy, QoSProfile
from rclpy.serialization import deserialize_message
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import CameraInfo, Image, JointState
from std_msgs.msg import Float64MultiArray, String
from std_srvs.srv import Trigger
from tf2_msgs.msg import TFMessage

import jaco2_sim_driver  # noqa: F401  (MUJOCO_GL=egl before mujoco is imported)
from relocation_common.arm_interface import FILE, GRIPPER_TOPIC, VELOCITY_TOPIC, ArmInterface, MismatchWatch
from relocation_common.node import Health, SideNode, declare_parameters, node_main
from relocation_common.robot_description import BASE_LINK, urdf
from relocation_common.ros_conversions import transform_msgs

from . import frames
from .camera import Frame
from .driver import SimDriver, Snapshot, Tick, joint_names, joint_state
from .messages import OPTICAL_FRAME, camera_msgs, finger_msg, joint_angles_msg, objects_msg, time_msg
from .params import DriverParams
from .sim import BadCommandError

# a Float64MultiArray command of 7 values serializes to ~100 bytes; bigger ones are refused before deserialization
# (8 MB arrays deserialized on every message took the driver from 245 to 351 MiB and halved its joint-state rate)
MAX_COMMAND_BYTES = 4096
COMMAND_QOS = 1  # only the newest command matters: no queue of stale (or huge) ones
LATCHED = QoSProfile(depth=1, durability=QoSDurabilityPolicy.TRANSIENT_LOCAL)
DISTURBANCES_QOS = QoSProfile(depth=100, durability=QoSDurabilityPolicy.TRANSIENT_LOCAL)
TF_QOS = QoSProfile(depth=100)  # tf2_ros TransformBroadcaster's


class Jaco2SimDriver(Node):
    """The driver node (the module docstring)."""

    def __init__(self) -> None:
        super().__init__("jaco2_sim_driver")
        params = declare_parameters(self, shared=(FILE,))  # config/jaco2_sim_driver.yaml, arm_interface
        p, self.arm = DriverParams.from_mapping(params), ArmInterface.from_mapping(params)  # checked: ValueError
        self.core = SimDriver.from_params(p, self.arm, log=self.get_logger().info)
        self.sim, camera, scenario = self.core.sim, self.core.sim.camera, self.core.sim.scenario
        self.interface, cam_rate = self.arm.command_interface, p.camera_rate
        # use_sim_time (rclpy's own parameter): stamp everything with the simulated time, as Gazebo and ros2_control
        # in simulation do; otherwise with the system clock, as kinova-ros does (ros::Time::now())
        self.sim_stamps = p.sim_time_stamps or bool(self.get_parameter("use_sim_time").value)
        self._running = True
        self._stopping = threading.Event()  # wakes the camera thread at once on shutdown (exit within 2 s)
        self._fingers: SideNode | None = None  # serves the fingers action and in/home_arm (kinova surface)
        pre, self.kinova = self.arm.driver_prefix, self.arm.kinova
        self.names = joint_names(self.interface)
        self.pub_clock = self.create_publisher(Clock, "/clock", 10)  # simulated time, as simulators publish it
        if self.kinova:
            self._kinova_surface(pre)
        else:
            self._ros2_control_surface()
        self.create_service(Trigger, f"{pre}/in/reset_scene", self.srv_reset)  # the simulator's own
        self._sensor_publishers()
        self._watch = MismatchWatch(self, self.arm, "driver", self.resolve_topic_name(self.arm.velocity_topic))
        self.health = Health(self, "jaco2_sim_driver: arm", "jaco2 (simulated)", self.core.health)  # /diagnostics
        self._sim_thread = threading.Thread(target=self._sim_loop, name="sim", daemon=True)
        self._sim_thread.start()
        self._cam_thread = None
        self._camera_up = False
        if cam_rate > 0:
            self._cam_thread = threading.Thread(target=self.core.camera_loop, name="camera", daemon=True,
                                                args=(1.0 / cam_rate, self.publish_camera_frame, self._stopping))
            self._cam_thread.start()
        self.get_logger().info(
            f"{self.interface} surface, scenario {scenario.name} ({len(scenario.objects)} objects, "
            f"{len(scenario.unlisted)} unlisted), real_time_factor "
            f"{p.real_time_factor:g}, joint states {p.joint_state_rate:g} Hz, camera {cam_rate:g} Hz "
            f"{camera.width}x{camera.height}")

    def _kinova_surface(self, pre: str) -> None:
        """kinova-ros (kinova_arm.cpp): the topics, services and fingers action of the j2s7s300 driver."""
        self.create_subscription(JointVelocity, self.arm.velocity_topic, self.on_kinova_velocity, COMMAND_QOS)
        self.pub_js = self.create_publisher(JointState, self.arm.state_topic, 10)
        self.pub_angles = self.create_publisher(JointAngles, f"{pre}/out/joint_angles", 10)
        self.pub_finger_pos = self.create_publisher(FingerPosition, f"{pre}/out/finger_position", 10)
        self.create_service(Start, f"{pre}/in/start", self.srv_start)
        self.create_service(Stop, f"{pre}/in/stop", self.srv_stop)
        self._fingers = SideNode("jaco2_sim_driver_fingers", context=self.context, threads=3)
        self._fingers.node.create_service(HomeArm, f"{pre}/in/home_arm", self.srv_home_arm,
                                          callback_group=ReentrantCallbackGroup())
        self._finger_server = ActionServer(
            self._fingers.node, SetFingersPosition, self.arm.fingers_action,
            execute_callback=self.execute_fingers, goal_callback=lambda _: GoalResponse.ACCEPT,
            cancel_callback=lambda _: CancelResponse.ACCEPT, callback_group=ReentrantCallbackGroup())

    def _ros2_control_surface(self) -> None:
        """ros2_control: forward command controllers and joint_state_broadcaster."""
        for topic, callback in ((VELOCITY_TOPIC, self.on_velocity), (GRIPPER_TOPIC, self.on_gripper)):
            self.create_subscription(Float64MultiArray, topic, self._bounded(topic, callback), COMMAND_QOS, raw=True)
        self.pub_js = self.create_publisher(JointState, self.arm.state_topic, 10)

    def _sensor_publishers(self) -> None:
        """Ground truth, camera, and what robot_state_publisher publishes: the URDF, its fixed joints, the moving
        joints."""
        self.pub_objects = self.create_publisher(ObjectArray, "/sim/objects", LATCHED)
        self.pub_disturbances = self.create_publisher(String, "/sim/disturbances", DISTURBANCES_QOS)
        self.create_subscription(TransformStamped, "/sim/disturb", self.on_disturb, 10)
        self.pub_rgb = self.create_publisher(Image, "/camera/color/image_raw", 2)
        self.pub_info = self.create_publisher(CameraInfo, "/camera/color/camera_info", 2)
        self.pub_depth = self.create_publisher(Image, "/camera/depth/image_rect_raw", 2)
        self.pub_cam_pose = self.create_publisher(PoseStamped, "/camera/color/pose", LATCHED)
        self.pub_description = self.create_publisher(String, "/robot_description", LATCHED)
        self.pub_tf_static = self.create_publisher(TFMessage, "/tf_static", LATCHED)
        self.pub_tf = self.create_publisher(TFMessage, "/tf", TF_QOS)
        self.pub_description.publish(String(data=urdf(hand=True)))
        t, t_cam = self.core.camera_transform()
        static = frames.fixed_transforms() + [(BASE_LINK, OPTICAL_FRAME, t_cam)]
        self.pub_tf_static.publish(self._tf(t, static))

    # ------------------------------------------------------------------ commands
    def on_kinova_velocity(self, msg: JointVelocity) -> None:
        """kinova_msgs/JointVelocity, deg/s; ignored while stopped (kinova_arm.cpp jointVelocityCallback)."""
        if self.core.stopped:
            self.get_logger().info("The velocities could not be set because the arm is stopped",
                                   throttle_duration_sec=2.0)
            return
        v = [msg.joint1, msg.joint2, msg.joint3, msg.joint4, msg.joint5, msg.joint6, msg.joint7]
        self._command(np.radians(np.asarray(v, float)), "joint_velocity")

    def _bounded(self, topic: str, callback: Callable[[Float64MultiArray], None]) -> Callable[[bytes], None]:
        """A raw-subscription callback: a serialized command over MAX_COMMAND_BYTES is refused (the arm holds
        still) without being deserialized; a smaller one is deserialized and passed to `callback`."""
        def on_raw(data: bytes) -> None:
            if len(data) > MAX_COMMAND_BYTES:
                if topic == VELOCITY_TOPIC:
                    self.core.hold()
                self.get_logger().error(f"rejected {topic} command: {len(data)} bytes serialized (at most "
                                        f"{MAX_COMMAND_BYTES}; 7 or 3 values expected)", throttle_duration_sec=1.0)
                return
            callback(deserialize_message(data, Float64MultiArray))
        return on_raw

    def on_velocity(self, msg: Float64MultiArray) -> None:
        """ros2_control JointGroupVelocityController command, rad/s."""
        self._command(msg.data, "velocity_controller/commands")

    def on_gripper(self, msg: Float64MultiArray) -> None:
        """ros2_control JointGroupPositionController over the three finger joints: Kinova's finger joint angles
        (rad, 0 open .. 1.396 closed, as in the joint states)."""
        try:
            self.core.gripper(msg.data)
        except (BadCommandError, ValueError, TypeError) as e:
            self.get_logger().error(f"rejected gripper_controller/commands command: {e}", throttle_duration_sec=1.0)

    def on_disturb(self, m: TransformStamped) -> None:
        """A disturbance (SimDriver.disturb: frames say move, nudge, tip or drop), applied at the next step."""
        t, r = m.transform.translation, m.transform.rotation
        self.core.disturb(m.header.frame_id, m.child_frame_id, (t.x, t.y, t.z), (r.x, r.y, r.z, r.w))

    def _command(self, v: Sequence[float] | np.ndarray, source: str) -> None:
        try:
            self.core.command(v)  # applied by the simulation loop at its next step (no lock wait here)
        except BadCommandError as e:  # the arm holds still
            self.get_logger().error(f"rejected {source} command: {e}", throttle_duration_sec=1.0)

    # ------------------------------------------------------------------ services and the fingers action
    def srv_home_arm(self, req: HomeArm.Request, res: HomeArm.Response) -> HomeArm.Response:
        """kinova_msgs/HomeArm (SimDriver.home). Served on the fingers' side executor: the main one keeps serving
        in/stop."""
        res.homearm_result = self.core.home(self.context.ok)
        return res

    def srv_stop(self, req: Stop.Request, res: Stop.Response) -> Stop.Response:
        """kinova_msgs/Stop: the arm stops at once; commands (velocities, finger goals) are ignored until Start."""
        self.core.stop()
        return Stop.Response(stop_result="Arm stopped")

    def srv_start(self, req: Start.Request, res: Start.Response) -> Start.Response:
        """kinova_msgs/Start."""
        self.core.start()
        return Start.Response(start_result="Arm started")

    def srv_reset(self, req: Trigger.Request, res: Trigger.Response) -> Trigger.Response:
        """The simulator's own: scenario state, arm home, fingers open, sim time 0, started (not stopped)."""
        res.success, res.message = True, f"scene reset to scenario {self.core.reset()}"
        return res

    def execute_fingers(self, gh: ServerGoalHandle) -> SetFingersPosition.Result:
        """kinova_msgs/action/SetFingersPosition (SimDriver.fingers); the result holds the finger positions."""
        f = gh.request.fingers
        outcome, turns = self.core.fingers(
            [f.finger1, f.finger2, f.finger3], cancelled=lambda: gh.is_cancel_requested,
            ok=lambda: self._running and self.context.ok(),
            feedback=lambda p: gh.publish_feedback(SetFingersPosition.Feedback(fingers=finger_msg(p))))
        getattr(gh, outcome)()
        return SetFingersPosition.Result(fingers=finger_msg(turns))

    # ------------------------------------------------------------------ the simulation loop: publishing
    def _sim_loop(self) -> None:
        while self._running:
            tick = self.core.tick()
            if not self._running:  # shutting down: the publishers are about to go
                return
            try:
                self._publish_tick(tick)
            except RCLError:  # the context went away (shutting down)
                if self.context.ok():
                    raise
                return
            if tick.steps <= 0:
                time.sleep(self.core.idle_time())

    def _publish_tick(self, tick: Tick) -> None:
        if tick.state is not None:
            self._publish_state(tick.state)
            self.pub_clock.publish(Clock(clock=time_msg(tick.time)))
        if tick.tf is not None:
            t, q, finger_q, poses = tick.tf
            self.pub_tf.publish(self._tf(t, frames.arm_transforms(q) + frames.finger_transforms(finger_q)
                                         + frames.bottle_transforms(poses)))
        for record in tick.disturbances:
            self.pub_disturbances.publish(String(data=json.dumps(record)))
        if tick.objects is not None:
            self.pub_objects.publish(objects_msg(self.sim.scenario, tick.objects[1], self._stamp(tick.objects[0])))

    def _stamp(self, sim_t: float) -> Time:
        return time_msg(sim_t) if self.sim_stamps else self.get_clock().now().to_msg()

    def _frame_stamp(self, f: Frame) -> Time:
        """A camera frame's stamp: the instant of the state it shows (SimDriver.camera_loop), not of publishing."""
        return time_msg(f.stamp) if self.sim_stamps or f.wall is None else time_msg(f.wall)

    def _publish_state(self, s: Snapshot) -> None:
        """Joint states (and on the kinova surface joint angles and finger positions) of one instant."""
        msg = JointState(name=self.names)
        msg.header.stamp = self._stamp(s.time)
        msg.position, msg.velocity, msg.effort = joint_state(self.interface, s)
        self.pub_js.publish(msg)
        if self.kinova:
            self.pub_angles.publish(joint_angles_msg(s.q))
            self.pub_finger_pos.publish(finger_msg(s.turns))

    def _tf(self, sim_t: float, transforms: Iterable[tuple[str, str, np.ndarray]]) -> TFMessage:
        stamp = self._stamp(sim_t)
        return TFMessage(transforms=transform_msgs(list(transforms), stamp))

    # ------------------------------------------------------------------ camera
    def publish_camera_frame(self, f: Frame) -> bool:
        """One rendered frame (camera.Frame) on the camera's topics: RGB, depth, camera info, pose. False once the
        node is shutting down (the camera loop ends)."""
        try:
            for pub, m in zip((self.pub_rgb, self.pub_depth, self.pub_info, self.pub_cam_pose),
                              camera_msgs(f, self._frame_stamp(f))):
                pub.publish(m)
        except RCLError:
            if self.context.ok():
                raise
            return False
        if not self._camera_up:  # the camera's renderer made and its first frame out: the node is fully running
            self._camera_up = True
            self.get_logger().info("camera: first frame published")
        return self._running

    def close(self) -> None:
        """Stop the loop and camera threads (before the publishers are destroyed) and the fingers' executor."""
        self._running = False
        self._stopping.set()
        self._sim_thread.join(timeout=5.0)  # a loaded machine: seconds
        if self._cam_thread is not None:
            self._cam_thread.join(timeout=5.0)
        if self._fingers is not None:
            self._fingers.close()


def main(args: list[str] | None = None) -> None:
    """The jaco2_sim_driver executable."""
    node_main("jaco2_sim_driver", Jaco2SimDriver, args, threads=1)


if __name__ == "__main__":
    main()
