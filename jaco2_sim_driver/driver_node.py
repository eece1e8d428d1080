"""jaco2_sim_driver node: the MuJoCo Jaco2 behind the interface of a real arm, selected by `command_interface`:

- `kinova`: kinova-ros's j2s7s300 driver surface (kinova_msgs; units and sources in docs/kinova.md) under
  `driver_prefix`: in/joint_velocity, out/joint_state, out/joint_angles, out/finger_position, the action
  fingers_action/finger_positions, the services in/home_arm, in/start, in/stop.
- `ros2_control`: a JointGroupVelocityController (/velocity_controller/commands), the fingers as a
  JointGroupPositionController (/gripper_controller/commands) and a joint_state_broadcaster (/joint_states).

Both: what robot_state_publisher publishes (/robot_description, /tf_static, /tf, plus the bottles' ground truth on
/tf), the camera, /sim/objects, /clock, and the simulator's own `<driver_prefix>/in/reset_scene`.

Thin shell around `Jaco2Sim` (all behaviour is in the core). Threads: the executor (commands, services), the
simulation loop (paced stepping at 1 kHz, joint states, TF, ground truth), the camera (offscreen render on a
snapshot, its own GL context) and, on the kinova surface, the fingers action's own executor (a goal waits until
the fingers stop). One lock serialises access to the simulation. Interface: docs/sim_driver.md.
"""
from __future__ import annotations

import math
import queue
import threading
import time

import mujoco
import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import PoseStamped
from kinova_msgs.action import SetFingersPosition
from kinova_msgs.msg import FingerPosition, JointAngles, JointVelocity
from kinova_msgs.srv import HomeArm, Start, Stop
from qtree_relocation_msgs.msg import ObjectArray, ObjectState
from rclpy._rclpy_pybind11 import RCLError
from rclpy.action import ActionServer, CancelResponse, GoalResponse
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
from relocation_common import kinova as units  # Kinova's units, shared with the planner
from relocation_common.node import SideNode, declare_parameters, node_main
from relocation_common.ros_conversions import transform_msg
from relocation_common.scenario import load_scenario
from stpik_motion_planner.robot_description import FINGER_JOINT_NAMES, JOINT_NAMES, PREFIX, urdf

from . import frames, kinova
from .camera import MJ_TO_OPTICAL, CameraRenderer, Frame
from .scene import CAMERA_NAME, CameraSpec
from .sensor_model import SensorModel
from .sim import BadCommandError, Jaco2Sim, check_velocity_command

BASE_FRAME = "j2s7s300_link_base"
OPTICAL_FRAME = "camera_color_optical_frame"
BOTTLE_FRAME = "bottle_{}"  # TF frame of a bottle (ground truth): centre of its base circle
FINGER_TIP_NAMES = tuple(f"{PREFIX}_joint_finger_tip_{i}" for i in range(1, 4))  # kinova-ros publishes them at 0
INTERFACES = ("kinova", "ros2_control")
HOMED = "KINOVA ARM HAS BEEN RETURNED HOME"  # kinova-ros's HomeArm answer
HOME_SPEED = 0.5  # HomeArm: fraction of Table 7's joint speeds
HOME_GAIN = 3.0  # 1/s, HomeArm's joint-space proportional gain
HOME_TOL = 5e-4  # rad, every joint, to count as home
HOME_TIMEOUT = 30.0  # s (wall) for the arm, then for the fingers
FINGERS_OPEN = 0.02  # rad of finger hinge: open
VELOCITY_TOPIC = "/velocity_controller/commands"   # ros2_control JointGroupVelocityController, rad/s
GRIPPER_TOPIC = "/gripper_controller/commands"     # ros2_control JointGroupPositionController, finger joints rad
# a Float64MultiArray command of 7 values serializes to ~100 bytes; bigger ones are refused before deserialization
# (8 MB arrays deserialized on every message took the driver from 245 to 351 MiB and halved its joint-state rate)
MAX_COMMAND_BYTES = 4096
COMMAND_QOS = 1  # only the newest command matters: no queue of stale (or huge) ones
MAX_LAG = 0.5  # s of simulated time the loop may fall behind before it stops trying to catch up
LATCHED = QoSProfile(depth=1, durability=QoSDurabilityPolicy.TRANSIENT_LOCAL)
TF_QOS = QoSProfile(depth=100)  # tf2_ros TransformBroadcaster's


class Jaco2SimDriver(Node):
    def __init__(self):
        super().__init__("jaco2_sim_driver")
        declare_parameters(self)  # config/jaco2_sim_driver.yaml
        g = lambda k: self.get_parameter(k).value  # noqa: E731
        self._check_parameters(g)
        self.tf_period = 1.0 / float(g("tf_rate")) if g("tf_rate") > 0 else math.inf
        self.finger_params = dict(tolerance=float(g("finger_tolerance")),
                                  stall_threshold=float(g("finger_stall_threshold")),
                                  stall_interval=float(g("finger_stall_interval")))
        self.rtf = float(g("real_time_factor"))
        self.js_period = 1.0 / float(g("joint_state_rate"))
        self.obj_period = 1.0 / float(g("objects_rate"))
        self.state_on_command = bool(g("state_on_command"))
        # use_sim_time (rclpy's own parameter): stamp everything with the simulated time, as Gazebo and ros2_control
        # in simulation do; otherwise with the system clock, as kinova-ros does (ros::Time::now())
        self.sim_stamps = bool(g("sim_time_stamps")) or bool(self.get_parameter("use_sim_time").value)
        cam_rate = float(g("camera_rate"))
        cam_kw = dict(fovy_deg=float(g("camera_fovy")), width=int(g("camera_width")), height=int(g("camera_height")))
        camera = CameraSpec.for_shelf(**cam_kw) if g("camera_relative_to_shelf") else CameraSpec(**cam_kw)
        scenario = load_scenario(g("scenario") or None)
        self.sim = Jaco2Sim(scenario, camera=camera, qdot_max=np.asarray(g("qdot_max"), float),
                            watchdog_timeout=float(g("watchdog_timeout")))
        self.lock = threading.Lock()
        self._commands: queue.SimpleQueue = queue.SimpleQueue()
        self._running = True
        self._stopping = threading.Event()  # wakes the camera thread at once on shutdown (exit within 2 s)
        self._commanded = False
        self._pace_reset = True
        self._stopped = False  # kinova in/stop: commands are ignored until in/start
        self._finger_goal = 0  # sequence number of the newest fingers goal (a newer goal preempts an older one)
        self._fingers = None   # SideNode serving the fingers action (kinova surface)

        pre = str(g("driver_prefix")).rstrip("/")
        self.kinova = self.interface == "kinova"
        self.pub_clock = self.create_publisher(Clock, "/clock", 10)  # simulated time, as simulators publish it
        if self.kinova:
            self._kinova_surface(pre)
        else:
            self._ros2_control_surface()
        self.create_service(Trigger, f"{pre}/in/reset_scene", self.srv_reset)  # the simulator's own
        self._sensor_publishers()

        self._sim_thread = threading.Thread(target=self._sim_loop, name="sim", daemon=True)
        self._sim_thread.start()
        self._cam_thread = None
        if cam_rate > 0:
            self._cam_thread = threading.Thread(target=self._camera_loop, args=(1.0 / cam_rate,), name="camera",
                                                daemon=True)
            self._cam_thread.start()
        self.get_logger().info(
            f"{self.interface} surface, scenario {scenario.name} ({len(scenario.objects)} bottles), real_time_factor "
            f"{self.rtf:g}, joint states {1 / self.js_period:g} Hz, camera {cam_rate:g} Hz "
            f"{camera.width}x{camera.height}")

    def _check_parameters(self, g) -> None:
        """ValueError naming the first unusable parameter (main() prints it as one line, exit 2)."""
        for k, lo in (("joint_state_rate", 0.0), ("objects_rate", 0.0), ("watchdog_timeout", 0.0),
                      ("camera_width", 0), ("camera_height", 0), ("camera_fovy", 0.0), ("finger_tolerance", 0.0),
                      ("finger_stall_threshold", 0.0), ("finger_stall_interval", 0.0)):
            if not g(k) > lo:  # also NaN
                raise ValueError(f"parameter {k} must be > {lo}, got {g(k)!r}")
        if not (g("camera_rate") >= 0 and g("camera_fovy") < 180):
            raise ValueError(f"camera_rate must be >= 0 and camera_fovy < 180, got {g('camera_rate')!r}, "
                             f"{g('camera_fovy')!r}")
        if not g("tf_rate") >= 0:
            raise ValueError(f"parameter tf_rate must be >= 0, got {g('tf_rate')!r}")
        self.sensor = SensorModel.named(str(g("camera_model")))  # camera_model: ideal | realsense_d435
        self.interface = str(g("command_interface"))
        if self.interface not in INTERFACES:
            raise ValueError(f"parameter command_interface must be one of {', '.join(INTERFACES)}, "
                             f"got {self.interface!r}")

    def _kinova_surface(self, pre: str) -> None:
        """kinova-ros (kinova_arm.cpp): the topics, services and fingers action of the j2s7s300 driver."""
        self.create_subscription(JointVelocity, f"{pre}/in/joint_velocity", self.on_kinova_velocity, COMMAND_QOS)
        self.pub_js = self.create_publisher(JointState, f"{pre}/out/joint_state", 10)
        self.pub_angles = self.create_publisher(JointAngles, f"{pre}/out/joint_angles", 10)
        self.pub_finger_pos = self.create_publisher(FingerPosition, f"{pre}/out/finger_position", 10)
        self.create_service(Start, f"{pre}/in/start", self.srv_start)
        self.create_service(Stop, f"{pre}/in/stop", self.srv_stop)
        self._fingers = SideNode("jaco2_sim_driver_fingers", context=self.context, threads=3)
        self._fingers.node.create_service(HomeArm, f"{pre}/in/home_arm", self.srv_home_arm,
                                          callback_group=ReentrantCallbackGroup())
        self._finger_server = ActionServer(
            self._fingers.node, SetFingersPosition, f"{pre}/fingers_action/finger_positions",
            execute_callback=self.execute_fingers, goal_callback=lambda _: GoalResponse.ACCEPT,
            cancel_callback=lambda _: CancelResponse.ACCEPT, callback_group=ReentrantCallbackGroup())
        self.names = list(JOINT_NAMES) + list(FINGER_JOINT_NAMES) + list(FINGER_TIP_NAMES)

    def _ros2_control_surface(self) -> None:
        """ros2_control: forward command controllers and joint_state_broadcaster."""
        for topic, callback in ((VELOCITY_TOPIC, self.on_velocity), (GRIPPER_TOPIC, self.on_gripper)):
            self.create_subscription(Float64MultiArray, topic, self._bounded(topic, callback), COMMAND_QOS, raw=True)
        self.pub_js = self.create_publisher(JointState, "/joint_states", 10)
        self.names = list(JOINT_NAMES) + list(FINGER_JOINT_NAMES)

    def _sensor_publishers(self) -> None:
        """Ground truth, camera, and what robot_state_publisher publishes: the URDF, its fixed joints, the moving
        joints."""
        self.pub_objects = self.create_publisher(ObjectArray, "/sim/objects", LATCHED)
        self.pub_rgb = self.create_publisher(Image, "/camera/color/image_raw", 2)
        self.pub_info = self.create_publisher(CameraInfo, "/camera/color/camera_info", 2)
        self.pub_depth = self.create_publisher(Image, "/camera/depth/image_rect_raw", 2)
        self.pub_cam_pose = self.create_publisher(PoseStamped, "/camera/color/pose", LATCHED)
        self.pub_description = self.create_publisher(String, "/robot_description", LATCHED)
        self.pub_tf_static = self.create_publisher(TFMessage, "/tf_static", LATCHED)
        self.pub_tf = self.create_publisher(TFMessage, "/tf", TF_QOS)
        self.pub_description.publish(String(data=urdf(hand=True)))
        self.pub_tf_static.publish(self._static_transforms())

    # ------------------------------------------------------------------ commands
    def on_kinova_velocity(self, msg: JointVelocity) -> None:
        """kinova_msgs/JointVelocity, deg/s; ignored while stopped (kinova_arm.cpp jointVelocityCallback)."""
        if self._stopped:
            self.get_logger().info("The velocities could not be set because the arm is stopped",
                                   throttle_duration_sec=2.0)
            return
        v = [msg.joint1, msg.joint2, msg.joint3, msg.joint4, msg.joint5, msg.joint6, msg.joint7]
        self._command(np.radians(np.asarray(v, float)), "joint_velocity")

    def _bounded(self, topic: str, callback):
        """A raw-subscription callback: a serialized command over MAX_COMMAND_BYTES is refused (the arm holds
        still) without being deserialized; a smaller one is deserialized and passed to `callback`."""
        def on_raw(data: bytes) -> None:
            if len(data) > MAX_COMMAND_BYTES:
                if topic == VELOCITY_TOPIC:
                    self._commands.put(None)
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
            target = kinova.turns_to_sim(units.joint_to_turns(np.asarray(msg.data, float)))
            with self.lock:
                oid = self.sim.set_fingers(target)
        except (BadCommandError, ValueError, TypeError) as e:
            self.get_logger().error(f"rejected gripper_controller/commands command: {e}", throttle_duration_sec=1.0)
            return
        self._log_grasp(oid, float(np.mean(target)))

    def _log_grasp(self, oid: str | None, target: float) -> None:
        closing = target >= 0.5 * kinova.FINGER_CLOSED
        if oid is not None:
            self.get_logger().info(f"{'grasped' if closing else 'released'} {oid}")

    def _command(self, v, source: str) -> None:
        try:
            v = check_velocity_command(v)
        except BadCommandError as e:
            self._commands.put(None)  # the arm holds still
            self.get_logger().error(f"rejected {source} command: {e}", throttle_duration_sec=1.0)
            return
        self._commands.put(v)  # applied by the simulation loop at its next step (no lock wait here)

    # ------------------------------------------------------------------ services
    def srv_home_arm(self, req, res):
        """kinova_msgs/HomeArm: the arm moves home, then the fingers open (kinova-ros: homeArm + initFingers, both
        waited for); answered when done. Home is the project's Q_HOME, not Kinova's factory home. The motion is
        straight in joint space at up to HOME_SPEED of Table 7 with no collision avoidance, as the firmware's; an
        in/stop meanwhile ends it. Served on the fingers' side executor: the main one keeps serving in/stop."""
        res.homearm_result = self._move_home() if not self._stopped else "Arm is stopped, cannot home"
        if res.homearm_result == HOMED:
            with self.lock:
                self.sim.set_fingers(np.zeros(len(FINGER_JOINT_NAMES)))
            deadline = time.monotonic() + HOME_TIMEOUT
            while self.context.ok() and time.monotonic() < deadline:
                with self.lock:
                    if np.max(np.abs(self.sim.finger_q)) < FINGERS_OPEN:
                        break
                time.sleep(0.01)
        return res

    def _move_home(self) -> str:
        """Joint velocities toward Q_HOME (gain HOME_GAIN, at most HOME_SPEED x Table 7) through the simulation
        loop's command queue, every 10 ms, until every joint is within HOME_TOL; the result message."""
        limit = HOME_SPEED * self.sim.qdot_max
        deadline = time.monotonic() + HOME_TIMEOUT
        while self.context.ok() and not self._stopped:
            with self.lock:
                err = self.sim.q_home - self.sim.q
            if np.max(np.abs(err)) < HOME_TOL or time.monotonic() > deadline:
                self._commands.put(None)
                return HOMED if np.max(np.abs(err)) < HOME_TOL else f"Homing did not end within {HOME_TIMEOUT:g} s"
            self._commands.put(np.clip(HOME_GAIN * err, -limit, limit))
            time.sleep(0.01)
        return "Arm is stopped, cannot home"

    def srv_stop(self, req, res):
        """kinova_msgs/Stop: the arm stops at once; commands (velocities, finger goals) are ignored until Start."""
        self._stopped = True
        self._commands.put(None)
        res.stop_result = "Arm stopped"
        return res

    def srv_start(self, req, res):
        self._stopped = False
        res.start_result = "Arm started"
        return res

    def srv_reset(self, req, res):
        """The simulator's own: scenario state, arm home, fingers open, sim time 0, started (not stopped)."""
        with self.lock:
            self.sim.reset()
            self._pace_reset = True
            self._stopped = False
        res.success, res.message = True, f"scene reset to scenario {self.sim.scenario.name}"
        return res

    # ------------------------------------------------------------------ fingers action (kinova surface)
    def _finger_turns(self) -> tuple[float, np.ndarray]:
        with self.lock:
            return self.sim.time, kinova.sim_to_turns(self.sim.finger_q)

    def execute_fingers(self, gh):
        """kinova_msgs/action/SetFingersPosition as kinova_fingers_action.cpp serves it: succeeded when the fingers
        are within finger_tolerance of the goal, aborted when they stall (closed on an object), when the arm is
        stopped, or when a newer goal comes; the result holds the finger positions either way."""
        with self.lock:
            self._finger_goal += 1
            seq = self._finger_goal
        f = gh.request.fingers
        goal = np.array([f.finger1, f.finger2, f.finger3], float)
        result = SetFingersPosition.Result()
        t, p = self._finger_turns()
        if self._stopped or not np.all(np.isfinite(goal)):
            self.get_logger().info("Could not complete finger action because the arm is stopped" if self._stopped
                                   else f"finger goal rejected: not finite {goal.tolist()}")
            result.fingers = _finger_msg(p)
            gh.abort()
            return result
        with self.lock:
            oid = self.sim.set_fingers(kinova.turns_to_sim(goal))
        self._log_grasp(oid, float(np.mean(kinova.turns_to_sim(goal))))
        monitor = units.FingerMonitor(goal, t, p, **self.finger_params)
        k = 0
        while True:
            time.sleep(0.01)
            t, p = self._finger_turns()
            result.fingers = _finger_msg(p)
            if not self._running or not self.context.ok():
                gh.abort()
                return result
            if gh.is_cancel_requested:  # the fingers stop where they are
                with self.lock:
                    self.sim.set_fingers(self.sim.finger_q)
                gh.canceled()
                return result
            if self._stopped or seq != self._finger_goal:
                gh.abort()
                return result
            status = monitor.update(t, p)
            if status == monitor.REACHED:
                gh.succeed()
                return result
            if status == monitor.STALLED:
                gh.abort()  # as kinova-ros: a stall ends the goal as aborted, with the positions reached
                return result
            if k % 10 == 0:
                gh.publish_feedback(SetFingersPosition.Feedback(fingers=result.fingers))
            k += 1

    # ------------------------------------------------------------------ simulation loop
    def _sim_loop(self) -> None:
        dt = float(self.sim.model.opt.timestep)
        next_js = next_obj = next_tf = 0.0
        wall0 = sim0 = 0.0
        while self._running:
            tf = None
            with self.lock:
                if self._pace_reset:
                    wall0, sim0 = time.monotonic(), self.sim.time
                    next_js = next_obj = next_tf = self.sim.time
                    self._pace_reset = False
                while not self._commands.empty():
                    v = self._commands.get_nowait()
                    if v is None:
                        self.sim.stop()
                    else:
                        self.sim.set_velocity(v)
                        self._commanded = True
                t = self.sim.time
                if self.rtf > 0:
                    target = sim0 + (time.monotonic() - wall0) * self.rtf
                    if target - t > MAX_LAG:  # too slow: drop the backlog instead of racing
                        sim0, wall0 = t, time.monotonic()
                        target = t
                    n = int((target - t) / dt)
                else:
                    n = 1
                n = min(n, 20)  # catch up in batches of up to 20 ms (a late thread gets the GIL back late)
                if n > 0:
                    self.sim.step(n)
                    t = self.sim.time
                publish_js = t >= next_js or (self._commanded and self.state_on_command and n > 0)
                if publish_js:
                    self._commanded = False
                    if t >= next_js:
                        next_js += self.js_period * max(1, int((t - next_js) / self.js_period) + 1)
                    state = self._snapshot()
                if t >= next_tf:
                    next_tf += self.tf_period * max(1, int((t - next_tf) / self.tf_period) + 1)
                    tf = (t, self.sim.q, self.sim.finger_q, self.sim.object_poses())
                objects = None
                if t >= next_obj:
                    next_obj = t + self.obj_period
                    objects = self._objects()
            if not self._running:  # shutting down: the publishers are about to go
                return
            try:
                if publish_js:
                    self._publish_state(*state)
                    self.pub_clock.publish(Clock(clock=_time(t)))
                if tf is not None:
                    self.pub_tf.publish(self._transforms(*tf))
                if objects is not None:
                    self.pub_objects.publish(objects)
            except RCLError:  # the context went away (shutting down)
                if self.context.ok():
                    raise
                return
            if n <= 0:
                time.sleep(0.0003)

    def _snapshot(self) -> tuple:
        s = self.sim
        return (s.time, s.q, s.qdot, s.effort, kinova.sim_to_turns(s.finger_q),
                kinova.sim_to_turns(s.finger_qdot))

    def _stamp(self, sim_t: float) -> Time:
        return _time(sim_t) if self.sim_stamps else self.get_clock().now().to_msg()

    def _publish_state(self, t, q, qdot, effort, turns, turns_dot) -> None:
        """Joint states (and on the kinova surface joint angles and finger positions) of one instant. Fingers as
        Kinova reports them: joint angle = turns * 80/6800 deg (kinova_arm.cpp), no finger velocity or effort on
        the kinova surface; kinova-ros also lists the finger tip joints, always 0."""
        msg = JointState()
        msg.header.stamp = self._stamp(t)
        msg.name = self.names
        fingers = units.turns_to_joint(turns)
        zeros = np.zeros(len(self.names) - len(JOINT_NAMES))
        if self.kinova:
            msg.position = np.concatenate([q, fingers, np.zeros(len(FINGER_TIP_NAMES))]).tolist()
            msg.velocity = np.concatenate([qdot, zeros]).tolist()
            msg.effort = np.concatenate([effort, zeros]).tolist()
            self.pub_js.publish(msg)
            d = np.degrees(q)
            self.pub_angles.publish(JointAngles(**{f"joint{i + 1}": float(d[i]) for i in range(len(JOINT_NAMES))}))
            self.pub_finger_pos.publish(_finger_msg(turns))
        else:
            msg.position = np.concatenate([q, fingers]).tolist()
            msg.velocity = np.concatenate([qdot, units.turns_to_joint(turns_dot)]).tolist()
            msg.effort = np.concatenate([effort, zeros]).tolist()
            self.pub_js.publish(msg)

    def _static_transforms(self) -> TFMessage:
        """/tf_static: the URDF's fixed joint (tool frame on link 7) and the camera's optical frame in the base."""
        with self.lock:
            cam = self.sim.model.camera(CAMERA_NAME).id
            t_cam = np.eye(4)
            t_cam[:3, :3] = self.sim.data.cam_xmat[cam].reshape(3, 3) @ MJ_TO_OPTICAL
            t_cam[:3, 3] = self.sim.data.cam_xpos[cam]
            stamp = self._stamp(self.sim.time)
        out = [transform_msg(t, parent, child, stamp) for parent, child, t in frames.fixed_transforms()]
        out.append(transform_msg(t_cam, BASE_FRAME, OPTICAL_FRAME, stamp))
        return TFMessage(transforms=out)

    def _transforms(self, sim_t, q, finger_q, poses) -> TFMessage:
        """/tf: every arm and finger link from the joint angles (URDF chain, as robot_state_publisher), every bottle
        from the ground truth."""
        stamp = self._stamp(sim_t)
        out = [transform_msg(t, parent, child, stamp)
               for parent, child, t in frames.arm_transforms(q) + frames.finger_transforms(finger_q)]
        for p in poses:
            t = np.eye(4)
            r = np.zeros(9)
            mujoco.mju_quat2Mat(r, np.asarray(p.quat_wxyz, float))
            t[:3, :3], t[:3, 3] = r.reshape(3, 3), p.position
            out.append(transform_msg(t, BASE_FRAME, BOTTLE_FRAME.format(p.id), stamp))
        return TFMessage(transforms=out)

    def _objects(self) -> ObjectArray:
        msg = ObjectArray()
        msg.header.stamp = self._stamp(self.sim.time)
        msg.header.frame_id = BASE_FRAME
        for pose in self.sim.object_poses():
            b = self.sim.scenario.object(pose.id)
            o = ObjectState(id=b.id, label=b.label, weight=b.weight, is_target=b.is_target, radius=b.radius,
                            height=b.height)
            o.pose.position.x, o.pose.position.y, o.pose.position.z = map(float, pose.position)
            (o.pose.orientation.w, o.pose.orientation.x, o.pose.orientation.y,
             o.pose.orientation.z) = map(float, pose.quat_wxyz)
            msg.objects.append(o)
        return msg

    # ------------------------------------------------------------------ camera
    def _camera_loop(self, period: float) -> None:
        model = self.sim.model
        spec = self.sim.camera
        renderer = CameraRenderer(model, spec.width, spec.height, sensor=self.sensor)
        data = mujoco.MjData(model)
        next_t = time.monotonic()
        try:
            while self._running:
                with self.lock:
                    data.qpos[:] = self.sim.data.qpos
                    data.time = self.sim.data.time
                mujoco.mj_kinematics(model, data)
                mujoco.mj_camlight(model, data)
                frame = renderer.render(data)
                try:
                    self._publish_frame(frame)
                except RCLError:
                    if self.context.ok():
                        raise
                    return
                next_t += period
                delay = next_t - time.monotonic()
                if delay > 0:
                    if self._stopping.wait(delay):
                        return
                else:
                    next_t = time.monotonic()
        finally:
            renderer.close()

    def _publish_frame(self, f: Frame) -> None:
        stamp = self._stamp(f.stamp)
        rgb = Image(height=f.height, width=f.width, encoding="rgb8", step=3 * f.width)
        rgb.data = f.rgb.tobytes()
        depth = Image(height=f.height, width=f.width, encoding="32FC1", step=4 * f.width)
        depth.data = f.depth.astype("<f4").tobytes()
        info = CameraInfo(height=f.height, width=f.width, distortion_model="plumb_bob")
        info.d = [0.0] * 5
        info.k = f.K.reshape(9).tolist()
        info.r = np.eye(3).reshape(9).tolist()
        info.p = np.hstack([f.K, np.zeros((3, 1))]).reshape(12).tolist()
        for m in (rgb, depth, info):
            m.header.stamp = stamp
            m.header.frame_id = OPTICAL_FRAME
        pose = PoseStamped()
        pose.header.stamp, pose.header.frame_id = stamp, BASE_FRAME
        t = f.T_base_camera
        pose.pose.position.x, pose.pose.position.y, pose.pose.position.z = map(float, t[:3, 3])
        q = np.zeros(4)
        mujoco.mju_mat2Quat(q, t[:3, :3].reshape(9))
        pose.pose.orientation.w, pose.pose.orientation.x, pose.pose.orientation.y, pose.pose.orientation.z = \
            map(float, q)
        self.pub_rgb.publish(rgb)
        self.pub_depth.publish(depth)
        self.pub_info.publish(info)
        self.pub_cam_pose.publish(pose)

    def close(self) -> None:
        self._running = False
        self._stopping.set()
        self._sim_thread.join(timeout=5.0)  # before the publishers are destroyed (a loaded machine: seconds)
        if self._cam_thread is not None:
            self._cam_thread.join(timeout=5.0)
        if self._fingers is not None:
            self._fingers.close()


def _time(t: float) -> Time:
    sec = int(t)
    return Time(sec=sec, nanosec=int((t - sec) * 1e9))


def _finger_msg(turns) -> FingerPosition:
    return FingerPosition(finger1=float(turns[0]), finger2=float(turns[1]), finger3=float(turns[2]))


def main(args=None) -> None:
    node_main("jaco2_sim_driver", Jaco2SimDriver, args, threads=1)


if __name__ == "__main__":
    main()
