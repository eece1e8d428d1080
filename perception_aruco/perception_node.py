"""perception node: RealSense-named camera topics -> /scene/objects (ObjectArray, transient local) + debug image.

Thin shell over perception_aruco.pipeline. Colour and depth are paired by stamp (closest within `sync_slop`);
the newest pair is processed at most `process_rate` times a second. Objects hidden in the current frame are kept
at their last perceived pose for `hold_frames` processed frames, then dropped; a new unlisted object is published
once seen in `confirm_frames` frames that count (SceneMemory), and no scene before that many frames (the first holds
the unlisted objects in view); a scene without the target is not
published, unless the motion planner says it placed the target on the bottom shelf (`relocated_topic`), out of the
camera's view: then the scene is what the camera sees, the top shelf without the target (docs/perception.md). The
last scene is republished every `republish_period` s while it is younger than `max_scene_age` (the task planner
refuses stale scenes). Bad input is logged, never fatal. Every frame with the marker also puts on /tf the marker as
seen (camera optical frame -> `aruco_marker_<id>`) and the shelf frame `shelf_frame` on it (front edge of the top
board's surface, centred, axes of the base frame, from the scenario).
Health goes out on /diagnostics (diagnostic_msgs/DiagnosticArray, the ROS convention): OK with the checks' numbers,
WARN with bottles missing, ERROR with the reason a frame was refused. The camera poses of consistent frames are
fused (`pipeline.FrameFusion`); the fused pose stands in when the marker is covered, if the shelf confirms it.
The arm's joint states (on the surface of config/arm_interface.yaml, the driver's and the planner's) leave its body
out of the depth. Every object is published, listed or not (u1, u2, ...: estimated weight, said in weight_note and
the log), as its primitive.
"""
from __future__ import annotations

import json
import os
import threading
import time
from collections import deque
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticStatus
from qtree_relocation_msgs.msg import ObjectArray
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, qos_profile_sensor_data
from sensor_msgs.msg import CameraInfo, Image, JointState
from std_msgs.msg import String
from tf2_msgs.msg import TFMessage

from relocation_common.arm_interface import FILE as ARM_INTERFACE_FILE
from relocation_common.arm_interface import ArmInterface
from relocation_common.geometry import invert
from relocation_common.node import Health, declare_parameters, node_main
from relocation_common.paths import config_file
from relocation_common.robot_description import JOINT_NAMES
from relocation_common.ros_conversions import objects_to_msg, transform_msg
from relocation_common.scenario import load_scenario

from .aruco import PerceptionError, marker_in_base
from .calibration import CalibrationError, apply_calibration, load_calibration
from .camera_check import camera_info_problem, image_problem
from .images import decode_color, decode_depth, encode_color
from .localize import LocalizeParams
from .objects.model import to_shelf_object
from .objects.params import ObjectParams
from .pipeline import FrameFusion, Perception, PerceptionResult, SceneMemory, identity_conflicts
from .segmentation import SegmentationParams
from .tracking import JointHistory


def _stamp_s(msg: Any) -> float:
    return msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec


class PerceptionNode(Node):
    """The perception node (module docstring; docs/perception.md)."""

    def __init__(self) -> None:
        super().__init__("perception")
        values = declare_parameters(self, shared=(ARM_INTERFACE_FILE,))  # config/perception.yaml, arm_interface
        def g(n: str) -> Any:
            return self.get_parameter(n).value

        self.p = g
        for k in ("process_rate", "republish_period", "sync_slop", "max_scene_age", "max_image_pixels"):
            if not g(k) > 0:  # also NaN
                raise ValueError(f"parameter {k} must be > 0, got {g(k)!r}")
        self.scenario = load_scenario(g("scenario") or None)
        if g("calibration_file"):  # the marker's pose measured with the robot (`./run calibrate`)
            self.scenario = apply_calibration(self.scenario, load_calibration(g("calibration_file")))
            self.get_logger().info(f"marker pose from the calibration {g('calibration_file')}")
        self.perception = Perception(self.scenario, SegmentationParams(
            gain_min=g("gain_min"), gain_max=g("gain_max"), max_residual=g("max_residual")),
            LocalizeParams(min_pixels=g("min_pixels"), inlier_tol=g("inlier_tol")),
            refine_with_depth=g("refine_with_depth"), objects=ObjectParams.from_mapping(values))
        self._joints = JointHistory(float(g("arm_sync_window")), float(g("arm_padding")))  # self-filter
        self._lock = threading.Lock()
        self._colors: deque = deque(maxlen=6)
        self._depths: deque = deque(maxlen=6)
        self._info = None
        self._last_pair: float | None = None       # stamp of the last processed pair
        self.memory = SceneMemory(self.scenario.ids, int(g("hold_frames")), int(g("confirm_frames")))
        self.fusion = FrameFusion()
        self._previous: dict = {}                  # id -> PerceivedObject of the last published scene
        self._scene: ObjectArray | None = None
        self._scene_time = 0.0
        self._debug: tuple[PerceptionResult, tuple] | None = None  # the last debug image (encoded) and its result

        sensors = ReentrantCallbackGroup()
        self.create_subscription(Image, g("color_topic"), self._on_color, qos_profile_sensor_data,
                                 callback_group=sensors)
        self.create_subscription(Image, g("depth_topic"), self._on_depth, qos_profile_sensor_data,
                                 callback_group=sensors)
        self.create_subscription(CameraInfo, g("camera_info_topic"), self._on_info, qos_profile_sensor_data,
                                 callback_group=sensors)
        self.create_subscription(JointState, ArmInterface.from_mapping(values).state_topic, self._on_joint_state, 10,
                                 callback_group=sensors)
        self._placed: set[str] = set()  # ids the motion planner placed on the bottom shelf (relocated_topic)
        self.create_subscription(String, g("relocated_topic"), self._on_relocated,
                                 QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL))
        self.pub = self.create_publisher(ObjectArray, g("objects_topic"),
                                         QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL))
        self.debug_pub = self.create_publisher(Image, g("debug_topic"), 1)
        self.tf_pub = self.create_publisher(TFMessage, "/tf", 100)
        self.health = Health(self, "perception: frame", "camera")  # /diagnostics, one status per processed frame
        sh = self.scenario.shelf
        t_base_shelf = np.eye(4)
        t_base_shelf[:3, 3] = (sh.x_front, sh.y_center, sh.top_z)
        self._t_base_marker = marker_in_base(self.scenario.marker)
        self._t_marker_shelf = invert(self._t_base_marker) @ t_base_shelf
        self.create_timer(1.0 / g("process_rate"), self._process, MutuallyExclusiveCallbackGroup())
        self.create_timer(g("republish_period"), self._republish, MutuallyExclusiveCallbackGroup())
        self.get_logger().info(f"perception on scenario {self.scenario.name!r} ({len(self.scenario.objects)} "
                               f"objects, marker id {self.scenario.marker.id}); publishing {g('objects_topic')}")
        if not os.environ.get("FASTRTPS_DEFAULT_PROFILES_FILE") and \
                os.environ.get("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp") == "rmw_fastrtps_cpp":
            self.get_logger().warning(  # 3-6 of 40 frames arrived (docs/sim_driver.md, "Camera images over DDS")
                "FASTRTPS_DEFAULT_PROFILES_FILE is not set: with Fast DDS's defaults most ~1 MB camera images are "
                f"lost. Set it in the environment of every node: export FASTRTPS_DEFAULT_PROFILES_FILE="
                f"{config_file('fastdds.xml')}")

    # ---- inputs
    def _on_color(self, msg: Image) -> None:
        if self._too_large(msg, "colour image"):
            return
        with self._lock:
            self._colors.append(msg)

    def _on_depth(self, msg: Image) -> None:
        if self._too_large(msg, "depth image"):
            return
        with self._lock:
            self._depths.append(msg)

    def _too_large(self, msg: Image, what: str) -> bool:
        """camera_check.image_problem: an image refused before it is kept (logged with the reason)."""
        why = image_problem(msg.width, msg.height, int(self.p("max_image_pixels")), what)
        if why is not None:
            self.get_logger().error(f"frame dropped: {why}", throttle_duration_sec=2.0)
        return why is not None

    def _on_info(self, msg: CameraInfo) -> None:
        self._info = msg

    def _on_relocated(self, msg: String) -> None:
        """The motion planner's placed bottles ({"relocated": {id: slot}}); a malformed message is logged."""
        try:
            self._placed = {str(i) for i in json.loads(msg.data)["relocated"]}
        except (ValueError, KeyError, TypeError) as e:
            self.get_logger().warning(f"relocated message ignored: {e}", throttle_duration_sec=10.0)

    def _on_joint_state(self, msg: JointState) -> None:
        if all(n in msg.name for n in JOINT_NAMES) and len(msg.position) == len(msg.name):
            with self._lock:
                self._joints.add(_stamp_s(msg), np.array([msg.position[msg.name.index(n)] for n in JOINT_NAMES]))

    def _newest_pair(self) -> tuple[Image, Image] | None:
        """Newest (colour, depth) whose stamps differ by at most sync_slop, or None."""
        with self._lock:
            best = None
            for c in self._colors:
                for dpt in self._depths:
                    dt = abs(_stamp_s(c) - _stamp_s(dpt))
                    if dt <= self.p("sync_slop") and (best is None or _stamp_s(c) > _stamp_s(best[0])):
                        best = (c, dpt)
            return best

    # ---- processing
    def _process(self) -> None:
        pair = self._newest_pair()
        log = self.get_logger()
        if pair is None:
            if self._colors and self._depths:
                with self._lock:
                    c, d = max(map(_stamp_s, self._colors)), max(map(_stamp_s, self._depths))
                log.warning(f"no colour/depth pair within sync_slop ({self.p('sync_slop')} s) of each other: newest "
                            f"colour stamp {c:.3f}, depth {d:.3f} (is one of the streams losing messages?)",
                            throttle_duration_sec=5.0)
            return
        color, depth = pair
        if self._last_pair == _stamp_s(color):
            return
        self._last_pair = _stamp_s(color)
        if self._info is None:
            log.warning("no camera_info received yet: cannot use the images", throttle_duration_sec=5.0)
            return
        rgb = None
        try:
            rgb = decode_color(color.encoding, color.height, color.width, color.step, color.data,
                               bool(color.is_bigendian))
            dep = decode_depth(depth.encoding, depth.height, depth.width, depth.step, depth.data,
                               bool(depth.is_bigendian))
            why = camera_info_problem(list(self._info.k), (self._info.width, self._info.height),
                                      (rgb.shape[1], rgb.shape[0]))
            if why is not None:
                raise PerceptionError(why)
            K = np.asarray(self._info.k, float).reshape(3, 3)
            with self._lock:
                q, unknown = self._joints.around(_stamp_s(color)), self._joints.unknown_at(_stamp_s(color))
            result = self.perception.process(rgb, dep, K, self.fusion.fused, self.memory, q, unknown)
            jump = self.fusion.update(result.T_base_camera)
            if jump:
                raise PerceptionError(jump)
        except Exception as e:  # bad input (PerceptionError) or a failure on it: the frame, never the node
            why = str(e) if isinstance(e, PerceptionError) else f"internal error: {type(e).__name__}: {e}"
            log.error(f"frame refused: {why}", throttle_duration_sec=2.0)
            self._publish_health(DiagnosticStatus.ERROR, f"frame refused: {why}", {"error": type(e).__name__})
            if rgb is not None:
                self._publish_debug(color, self.perception.annotate(rgb, None, note=str(e)))
            return
        doubt = identity_conflicts(result.detections, self._previous)
        if doubt:
            result = PerceptionResult(result.marker, {i: d for i, d in result.objects.items() if i not in doubt},
                                      {**result.missing, **doubt}, result.T_base_camera, result.shelf, result.notes,
                                      result.uncounted, result.reached)
        self._report_health(result)
        if self._debug is None or self._debug[0] is not result:   # a result reused: the same images, the same drawing
            self._debug = (result, encode_color(self.perception.annotate(rgb, result, K)))
        self._publish_encoded(color, self._debug[1])
        self._publish_tf(color, result)
        self._publish_scene(color, result)

    def _report_health(self, result: PerceptionResult) -> None:
        fit = result.shelf
        values = {"bottles found": str(len(result.detections)), "missing": ", ".join(sorted(result.missing)),
                  "unlisted": ", ".join(sorted(result.unlisted)), "marker seen": str(result.marker is not None),
                  "frames processed": str(self.perception.processed),
                  "frames reused (inputs unchanged)": str(self.perception.reused)}
        if fit is not None:
            values.update({"shelf vs marker (mm)": f"{fit.shift * 1000:.1f}",
                           "shelf vs marker (deg)": f"{fit.rotation_deg:.2f}",
                           "depth noise at the shelf (mm)": f"{fit.noise * 1000:.1f}"})
        notes = "; ".join(result.notes)
        if result.missing or notes:
            why = "; ".join(f"{i}: {w}" for i, w in sorted(result.missing.items()))
            self._publish_health(DiagnosticStatus.WARN, "; ".join(x for x in (notes, why) if x), values)
        else:
            self._publish_health(DiagnosticStatus.OK, "every bottle located; frame consistent", values)

    def _publish_health(self, level: bytes, message: str, values: dict) -> None:
        """One status on /diagnostics (diagnostic_msgs: OK, WARN, ERROR) for the last processed frame."""
        self.health.send(level[0], message, values)

    def _publish_tf(self, color: Image, result: PerceptionResult) -> None:
        """The marker where this frame's camera pose (marker, corrected by the shelf) puts it, and the shelf on it
        (/tf, stamped with the image)."""
        marker = f"aruco_marker_{self.scenario.marker.id}"
        stamp = color.header.stamp
        self.tf_pub.publish(TFMessage(transforms=[
            transform_msg(invert(result.T_base_camera) @ self._t_base_marker, color.header.frame_id, marker, stamp),
            transform_msg(self._t_marker_shelf, marker, self.p("shelf_frame"), stamp)]))

    def _publish_scene(self, color: Image, result: PerceptionResult) -> None:
        log = self.get_logger()
        objects, held, lost = self.memory.update(result.objects, result.uncounted, result.reached)
        unlisted = [o for o in objects if not o.listed]
        if unlisted:
            log.info("unlisted objects: " + "; ".join(
                f"{o.id} {to_shelf_object(o).describe()}{' (conservative)' if o.conservative else ''} at "
                f"({o.x:.3f}, {o.y:.3f}), {o.weight:.2f} kg estimated: {o.weight_note}" for o in unlisted),
                throttle_duration_sec=5.0)
        dets = [o for o in objects if o.listed]
        if held:
            log.warning(f"not seen in this frame, kept at last pose: {', '.join(held)}", throttle_duration_sec=5.0)
        if lost:
            why = "; ".join(f"{i}: {result.missing.get(i, 'not seen')}" for i in lost)
            log.warning(f"missing from the scene (hidden or out of view): {why}", throttle_duration_sec=5.0)
        if self.memory.frame < self.memory.confirm_frames:   # the first scene holds the objects confirmed by then
            log.info(f"first frames: no scene until {self.memory.confirm_frames} frames confirm the unlisted objects "
                     f"({self.memory.frame} so far)", throttle_duration_sec=2.0)
            return
        target = self.scenario.target_id
        if target not in {d.id for d in dets} and target not in self._placed:
            log.error(f"target {target!r} not seen: no scene published", throttle_duration_sec=2.0)
            return
        msg = objects_to_msg([to_shelf_object(o) for o in objects], color.header.stamp, self.p("frame_id"))
        self._scene, self._scene_time = msg, time.monotonic()
        self._previous = {d.id: d for d in dets}
        self.pub.publish(msg)

    def _republish(self) -> None:
        if self._scene is None:
            return
        age = time.monotonic() - self._scene_time
        if age > self.p("max_scene_age"):
            self.get_logger().warning(f"no scene perceived for {age:.0f} s: not republishing the old one",
                                      throttle_duration_sec=10.0)
            return
        self.pub.publish(self._scene)

    def _publish_debug(self, color: Image, img: np.ndarray) -> None:
        self._publish_encoded(color, encode_color(img))

    def _publish_encoded(self, color: Image, encoded: tuple) -> None:
        enc, h, w, step, data = encoded
        self.debug_pub.publish(Image(header=color.header, encoding=enc, height=h, width=w, step=step, data=data))


def main(args: list[str] | None = None) -> None:
    """Entry point of the perception node."""
    node_main("perception", PerceptionNode, args, errors=(CalibrationError,))  # a bad calibration_file: one line


if __name__ == "__main__":
    main()
