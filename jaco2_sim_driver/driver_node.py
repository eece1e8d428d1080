"""jaco2_sim_driver node: the MuJoCo Jaco2 behind Kinova-compatible topics (a real j2s7s300 driver is a remap away).

Thin shell around `Jaco2Sim` (all behaviour is in the core). Threads: the executor (commands, services), the
simulation loop (paced stepping at 1 kHz, joint states, ground truth) and the camera (offscreen render on a
snapshot, its own GL context). One lock serialises access to the simulation. Interface: docs/sim_driver.md.
"""
from __future__ import annotations

import jaco2_sim_driver  # noqa: F401  (MUJOCO_GL=egl before mujoco is imported)

import queue
import threading
import time

import mujoco
import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import PoseStamped
from rclpy._rclpy_pybind11 import RCLError
from rclpy.node import Node
from rclpy.qos import QoSDurabilityPolicy, QoSProfile
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import CameraInfo, Image, JointState
from std_msgs.msg import Float64MultiArray
from std_srvs.srv import Trigger

from qtree_relocation_msgs.msg import JointVelocity, ObjectArray, ObjectState
from relocation_common.node import declare_parameters, node_main
from relocation_common.scenario import load_scenario
from stpik_motion_planner.robot_description import FINGER_JOINT_NAMES, JOINT_NAMES

from .camera import CameraRenderer, Frame
from .scene import CameraSpec
from .sim import BadCommandError, Jaco2Sim, check_velocity_command

BASE_FRAME = "j2s7s300_link_base"
OPTICAL_FRAME = "camera_color_optical_frame"
MAX_LAG = 0.5  # s of simulated time the loop may fall behind before it stops trying to catch up


class Jaco2SimDriver(Node):
    def __init__(self):
        super().__init__("jaco2_sim_driver")
        declare_parameters(self)  # config/jaco2_sim_driver.yaml
        g = lambda k: self.get_parameter(k).value  # noqa: E731
        for k, lo in (("joint_state_rate", 0.0), ("objects_rate", 0.0), ("watchdog_timeout", 0.0),
                      ("camera_width", 0), ("camera_height", 0), ("camera_fovy", 0.0)):
            if not g(k) > lo:  # also NaN
                raise ValueError(f"parameter {k} must be > {lo}, got {g(k)!r}")
        if not (g("camera_rate") >= 0 and g("camera_fovy") < 180):
            raise ValueError(f"camera_rate must be >= 0 and camera_fovy < 180, got {g('camera_rate')!r}, "
                             f"{g('camera_fovy')!r}")
        self.rtf = float(g("real_time_factor"))
        self.js_period = 1.0 / float(g("joint_state_rate"))
        self.obj_period = 1.0 / float(g("objects_rate"))
        self.state_on_command = bool(g("state_on_command"))
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

        pre = str(g("driver_prefix")).rstrip("/")
        self.create_subscription(JointVelocity, f"{pre}/in/joint_velocity", self.on_kinova_velocity, 10)
        self.create_subscription(Float64MultiArray, "/velocity_controller/commands", self.on_velocity, 10)
        self.pub_clock = self.create_publisher(Clock, "/clock", 10)  # simulated time, as simulators publish it
        self.pub_js = [self.create_publisher(JointState, f"{pre}/out/joint_state", 10),
                       self.create_publisher(JointState, "/joint_states", 10)]
        latched = QoSProfile(depth=1, durability=QoSDurabilityPolicy.TRANSIENT_LOCAL)
        self.pub_objects = self.create_publisher(ObjectArray, "/sim/objects", latched)
        self.pub_rgb = self.create_publisher(Image, "/camera/color/image_raw", 2)
        self.pub_info = self.create_publisher(CameraInfo, "/camera/color/camera_info", 2)
        self.pub_depth = self.create_publisher(Image, "/camera/depth/image_rect_raw", 2)
        self.pub_cam_pose = self.create_publisher(PoseStamped, "/camera/color/pose", latched)
        for name, fn in [("gripper_close", self.srv_close), ("gripper_open", self.srv_open),
                         ("home", self.srv_home), ("reset_scene", self.srv_reset)]:
            self.create_service(Trigger, f"{pre}/in/{name}", fn)

        self.names = list(JOINT_NAMES) + list(FINGER_JOINT_NAMES)
        self._sim_thread = threading.Thread(target=self._sim_loop, name="sim", daemon=True)
        self._sim_thread.start()
        self._cam_thread = None
        if cam_rate > 0:
            self._cam_thread = threading.Thread(target=self._camera_loop, args=(1.0 / cam_rate,), name="camera",
                                                daemon=True)
            self._cam_thread.start()
        self.get_logger().info(
            f"scenario {scenario.name} ({len(scenario.objects)} bottles), real_time_factor {self.rtf:g}, "
            f"joint states {1 / self.js_period:g} Hz, camera {cam_rate:g} Hz {camera.width}x{camera.height}")

    # ------------------------------------------------------------------ commands
    def on_kinova_velocity(self, msg: JointVelocity) -> None:
        """kinova_msgs-style command, deg/s."""
        v = [msg.joint1, msg.joint2, msg.joint3, msg.joint4, msg.joint5, msg.joint6, msg.joint7]
        self._command(np.radians(np.asarray(v, float)), "joint_velocity")

    def on_velocity(self, msg: Float64MultiArray) -> None:
        """ros2_control-style command, rad/s."""
        self._command(msg.data, "velocity_controller/commands")

    def _command(self, v, source: str) -> None:
        try:
            v = check_velocity_command(v)
        except BadCommandError as e:
            self._commands.put(None)  # the arm holds still
            self.get_logger().error(f"rejected {source} command: {e}", throttle_duration_sec=1.0)
            return
        self._commands.put(v)  # applied by the simulation loop at its next step (no lock wait here)

    # ------------------------------------------------------------------ services
    def srv_close(self, req, res):
        with self.lock:
            oid = self.sim.gripper_close()
        res.success = oid is not None
        res.message = f"grasped {oid}" if oid else "closed on nothing: no bottle between the fingers"
        return res

    def srv_open(self, req, res):
        with self.lock:
            oid = self.sim.gripper_open()
        res.success, res.message = True, f"released {oid}" if oid else "opened (nothing held)"
        return res

    def srv_home(self, req, res):
        with self.lock:
            self.sim.home()
        res.success, res.message = True, "arm at home"
        return res

    def srv_reset(self, req, res):
        with self.lock:
            self.sim.reset()
            self._pace_reset = True
        res.success, res.message = True, f"scene reset to scenario {self.sim.scenario.name}"
        return res

    # ------------------------------------------------------------------ simulation loop
    def _sim_loop(self) -> None:
        dt = float(self.sim.model.opt.timestep)
        next_js = next_obj = 0.0
        wall0 = sim0 = 0.0
        while self._running:
            with self.lock:
                if self._pace_reset:
                    wall0, sim0, next_js, next_obj = time.monotonic(), self.sim.time, self.sim.time, self.sim.time
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
                    js = self._joint_state()
                objects = None
                if t >= next_obj:
                    next_obj = t + self.obj_period
                    objects = self._objects()
            try:
                if publish_js:
                    for pub in self.pub_js:
                        pub.publish(js)
                    sec = int(t)
                    self.pub_clock.publish(Clock(clock=Time(sec=sec, nanosec=int((t - sec) * 1e9))))
                if objects is not None:
                    self.pub_objects.publish(objects)
            except RCLError:  # the context went away (shutting down)
                if self.context.ok():
                    raise
                return
            if n <= 0:
                time.sleep(0.0003)

    def _joint_state(self) -> JointState:
        s = self.sim
        msg = JointState()
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.header.frame_id = BASE_FRAME
        msg.name = self.names
        msg.position = np.concatenate([s.q, s.finger_q]).tolist()
        msg.velocity = np.concatenate([s.qdot, s.finger_qdot]).tolist()
        msg.effort = np.concatenate([s.effort, np.zeros(len(FINGER_JOINT_NAMES))]).tolist()
        return msg

    def _objects(self) -> ObjectArray:
        msg = ObjectArray()
        msg.header.stamp = self.get_clock().now().to_msg()
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
        renderer = CameraRenderer(model, spec.width, spec.height)
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
        stamp = self.get_clock().now().to_msg()
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
        self._sim_thread.join(timeout=2.0)
        if self._cam_thread is not None:
            self._cam_thread.join(timeout=5.0)


def main(args=None) -> None:
    node_main("jaco2_sim_driver", Jaco2SimDriver, args, threads=1)


if __name__ == "__main__":
    main()
