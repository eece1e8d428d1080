"""The driver's ROS messages (message types only, no rclpy): the driver node's translation of the core's values.

Kinova's messages (joint angles in degrees, finger positions in turns; docs/kinova.md), the ground truth as an
ObjectArray, and a rendered camera frame (camera.Frame) as the topics of a RealSense-like camera driver.
"""
from __future__ import annotations

from dataclasses import replace
from typing import Iterable, Sequence

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import PoseStamped
from kinova_msgs.msg import FingerPosition, JointAngles
from numpy.typing import ArrayLike
from qtree_relocation_msgs.msg import ObjectArray
from sensor_msgs.msg import CameraInfo, Image

from relocation_common.geometry import quat_xyzw, wxyz_matrix
from relocation_common.ros_conversions import BASE_FRAME, objects_to_msg
from relocation_common.scenario import Scenario, ShelfObject
from relocation_common.shelf_object import at_pose, estimated_weight, unlisted_density

from .camera import Frame
from .sim import ObjectPose

OPTICAL_FRAME = "camera_color_optical_frame"


def time_msg(t: float) -> Time:
    """Seconds (simulated time) as a builtin_interfaces/Time."""
    sec = int(t)
    return Time(sec=sec, nanosec=int((t - sec) * 1e9))


def finger_msg(turns: Sequence[float] | np.ndarray) -> FingerPosition:
    """The three fingers in Kinova's turns (0 open .. 6800 closed)."""
    return FingerPosition(finger1=float(turns[0]), finger2=float(turns[1]), finger3=float(turns[2]))


def joint_angles_msg(q: ArrayLike) -> JointAngles:
    """Joint angles (rad, Kinova's Q) as kinova-ros's out/joint_angles: degrees."""
    d = np.degrees(np.asarray(q, float))
    return JointAngles(**{f"joint{i + 1}": float(d[i]) for i in range(len(d))})


def ground_truth(scenario: Scenario, pose: ObjectPose, density: float) -> ShelfObject:
    """The object `pose.id` of the simulator's world (listed or unlisted) where it is (sim.ObjectPose: the centre of
    its base as built and its orientation): its primitive placed there (shelf_object.at_pose). An unlisted one
    carries the weight perception would estimate (volume x `density`, clipped to (0, 1]) with the note saying so,
    whatever the file gave it (that is its mass in the simulation)."""
    o = scenario.world_object(pose.id)
    if not o.listed:
        w, note = estimated_weight(o, density)
        o = replace(o, weight=w, weight_note=note)
    rot = wxyz_matrix(pose.quat_wxyz)
    return at_pose(o, np.asarray(pose.position, float) + rot[:, 2] * o.size[2] / 2, rot)


def objects_msg(scenario: Scenario, poses: Iterable[ObjectPose], stamp: Time,
                density: float | None = None) -> ObjectArray:
    """Every object of the simulator's world at its ground-truth pose (`ground_truth`) in the base frame; `density`
    None: config/perception.yaml's unlisted_density."""
    rho = unlisted_density() if density is None else density
    return objects_to_msg([ground_truth(scenario, p, rho) for p in poses], stamp, BASE_FRAME)


def camera_msgs(f: Frame, stamp: Time) -> tuple[Image, Image, CameraInfo, PoseStamped]:
    """(RGB, depth in m as 32FC1, camera info, camera pose in the base frame) of one rendered frame."""
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
    o = pose.pose.orientation
    o.x, o.y, o.z, o.w = quat_xyzw(t[:3, :3])
    return rgb, depth, info, pose
