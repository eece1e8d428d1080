"""MuJoCo scene of the experiment: the Jaco2 arm (from the one robot description), the shelf unit, the bottles of
a scenario as free bodies, the ArUco marker as a texture, the camera and lights. No ROS here.

Frames: the MuJoCo world frame is the robot base frame of the scenario (x towards the shelf, z up, metres).
Everything is generated from `stpik_motion_planner.robot_description` and `relocation_common.scenario`, so
the simulated world is the world the planners reason about (Sect. 5 of the paper: top shelf with the
obstacles and the target, bottom shelf where relocated objects go, board above the top shelf).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import mujoco  # MUJOCO_GL (headless rendering) is set by the package's __init__, imported first
import numpy as np

from relocation_common.scenario import Marker, Scenario
from stpik_motion_planner.robot_description import (
    FINGER_BASE_Z,
    FINGER_CLOSED,
    FINGER_HINGES,
    FINGER_JOINT_NAMES,
    FINGER_LINK_NAMES,
    FINGER_RADIUS,
    LINK_NAMES,
    finger_tip,
    mjcf_arm_body,
)

CAMERA_NAME = "camera_color"
HAND_BODY = LINK_NAMES[-1]
FINGER_BODY_NAMES = FINGER_LINK_NAMES  # the description's moving fingers (FINGER_HINGES), as MuJoCo bodies
# Static finger capsules of the description (the planner's conservative envelope of the open hand): the simulator
# replaces them with moving finger bodies and switches them off (see Jaco2Sim).
DESCRIPTION_FINGER_GEOMS = ("finger_1", "finger_2", "finger_3")
MARKER_BORDER = 0.25       # white margin around the marker, as a fraction of the marker side
FLOOR_DROP = 0.30          # floor this far below the bottom shelf board


# Default camera: fixed in the base frame, front right of the shelf (as the robot sees it), above the top shelf.
# With the arm at Q_HOME every bottle of paper_experiment_10 shows (>= 250 px each at 640x480; test_sim_core checks
# it); perception's tests are tuned on this view.
CAMERA_POSITION = (0.0, -0.35, 0.55)
CAMERA_TARGET = (0.62, 0.0, 0.26)
# Alternative placement relative to the shelf (CameraSpec.for_shelf): chosen with segmentation renders; shows more
# of every bottle of config/scenarios/*.yaml (paper_experiment_10: >= 1100 px each).
CAMERA_OFFSET = (-0.30, -0.30, 0.38)       # from (x_front, y_center, top_z)
CAMERA_LOOK_AT = (0.45, 0.0, 0.06)         # (fraction of the depth, y from y_center, z above top_z)


@dataclass(frozen=True)
class CameraSpec:
    """Pinhole camera of the scene (RealSense-like). position / look_at in the base frame; None = placed from the
    scenario's shelf (CAMERA_OFFSET, CAMERA_LOOK_AT), see `for_shelf`."""

    position: tuple[float, float, float] | None = CAMERA_POSITION
    look_at: tuple[float, float, float] | None = CAMERA_TARGET
    fovy_deg: float = 58.0
    width: int = 640
    height: int = 480

    @classmethod
    def for_shelf(cls, **kw) -> "CameraSpec":
        """The shelf-relative placement (position and look_at from the scenario's shelf)."""
        return cls(position=None, look_at=None, **kw)

    def placed(self, shelf) -> tuple[np.ndarray, np.ndarray]:
        """(position, look_at) for this shelf."""
        p = self.position or (shelf.x_front + CAMERA_OFFSET[0], shelf.y_center + CAMERA_OFFSET[1],
                              shelf.top_z + CAMERA_OFFSET[2])
        t = self.look_at or (shelf.x_front + CAMERA_LOOK_AT[0] * shelf.depth, shelf.y_center + CAMERA_LOOK_AT[1],
                             shelf.top_z + CAMERA_LOOK_AT[2])
        return np.asarray(p, float), np.asarray(t, float)


def _f(v) -> str:
    return " ".join(f"{float(x):.6g}" for x in v)


def rpy_matrix(rpy) -> np.ndarray:
    """R = Rz(yaw) Ry(pitch) Rx(roll) (URDF / ROS fixed-axis roll-pitch-yaw)."""
    r, p, y = rpy
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                     [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                     [-sp, cp * sr, cp * cr]])


def quat_wxyz(rot: np.ndarray) -> np.ndarray:
    """Unit quaternion (w, x, y, z; MuJoCo's order) of a 3x3 rotation matrix."""
    q = np.zeros(4)
    mujoco.mju_mat2Quat(q, np.asarray(rot, float).reshape(9))
    return q


def marker_image(marker: Marker, pixels_per_bit: int = 20) -> np.ndarray:
    """Grayscale image of the ArUco marker (cv2.aruco.generateImageMarker) with a white margin around it."""
    try:
        dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, marker.dictionary))
    except AttributeError:
        raise ValueError(f"unknown ArUco dictionary {marker.dictionary!r}") from None
    bits = dictionary.markerSize + 2
    side = bits * pixels_per_bit
    img = cv2.aruco.generateImageMarker(dictionary, marker.id, side, borderBits=1)
    pad = int(round(MARKER_BORDER * side))
    return cv2.copyMakeBorder(img, pad, pad, pad, pad, cv2.BORDER_CONSTANT, value=255)


def _hand_xml() -> str:
    """The description's three fingers (robot_description.FINGER_HINGES) on the last link (its frame: z = approach,
    x = closing direction, grasp centre at z = D67): a hinge at the palm each; the open fingers lie on the
    description's finger capsules, closing rotates the tips towards the grasp centre."""
    out = []
    for k, (x, y, sign) in enumerate(FINGER_HINGES):
        out.append(
            f'<body name="{FINGER_BODY_NAMES[k]}" pos="{x} {y} {FINGER_BASE_Z}" gravcomp="1">'
            f'<joint name="{FINGER_JOINT_NAMES[k]}" type="hinge" axis="0 {sign:g} 0" range="0 {FINGER_CLOSED}" '
            f'limited="true" damping="0.05" armature="0.001"/>'
            f'<geom name="finger_sim_{k + 1}" type="capsule" fromto="0 0 0 {_f(finger_tip(k))}" '
            f'size="{FINGER_RADIUS}" mass="0.03" class="finger"/></body>')
    return "".join(out)


def _box(name: str, lo, hi, cls: str = "shelf") -> str:
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    return f'<geom name="{name}" type="box" pos="{_f((lo + hi) / 2)}" size="{_f((hi - lo) / 2)}" class="{cls}"/>'


def _shelf_xml(s) -> str:
    t, x0, x1, y0, y1 = s.board_thickness, s.x_front, s.x_back, s.y_min, s.y_max
    floor = s.bottom_z - FLOOR_DROP
    return "".join([
        _box("shelf_top_board", (x0, y0, s.top_z - t), (x1, y1, s.top_z)),
        _box("shelf_ceiling_board", (x0, y0, s.ceiling_z), (x1, y1, s.ceiling_z + t)),
        _box("shelf_bottom_board", (x0, y0, s.bottom_z - t), (x1, y1, s.bottom_z)),
        _box("shelf_side_left", (x0, y1, floor), (x1, y1 + t, s.ceiling_z + t)),
        _box("shelf_side_right", (x0, y0 - t, floor), (x1, y0, s.ceiling_z + t)),
        _box("shelf_back_panel", (x1, y0 - t, floor), (x1 + t, y1 + t, s.ceiling_z + t)),
    ])


def _marker_xml(m: Marker) -> str:
    """A thin plate whose front face (+z of the marker frame, OpenCV convention) carries the marker texture."""
    rot = rpy_matrix(m.rpy)
    half = m.size * (1 + 2 * MARKER_BORDER) / 2
    thick = 0.002
    centre = np.asarray(m.position) - rot[:, 2] * thick
    return (f'<body name="aruco_marker" pos="{_f(centre)}" quat="{_f(quat_wxyz(rot))}">'
            f'<geom name="aruco_plate" type="box" size="{half:.6g} {half:.6g} {thick}" material="aruco" '
            f'contype="0" conaffinity="0"/></body>')


def _bottle_xml(b, z: float) -> str:
    """A bottle: free body whose frame is the centre of its base circle (as ObjectState.pose), mass = weight (kg)."""
    return (f'<body name="{b.id}" pos="{b.x:.6g} {b.y:.6g} {z:.6g}"><freejoint name="{b.id}_free"/>'
            f'<geom name="{b.id}_geom" type="cylinder" pos="0 0 {b.height / 2:.6g}" '
            f'size="{b.radius:.6g} {b.height / 2:.6g}" mass="{b.weight:.6g}" rgba="{_f(b.rgb)} 1" class="bottle"/>'
            f'</body>')


def _camera_xml(c: CameraSpec, shelf) -> str:
    """MuJoCo camera looking from `position` to `look_at` (MuJoCo cameras look along -z with y up)."""
    p, t = c.placed(shelf)
    fwd = (t - p) / np.linalg.norm(t - p)
    right = np.cross(fwd, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, fwd)
    return (f'<camera name="{CAMERA_NAME}" pos="{_f(p)}" xyaxes="{_f(right)} {_f(up)}" fovy="{c.fovy_deg:.6g}" '
            f'resolution="{c.width} {c.height}"/>')


def scene_xml(scenario: Scenario, camera: CameraSpec = CameraSpec()) -> str:
    """MJCF of the whole scene. Physics at 1 kHz (timestep 0.001). The marker texture is the asset 'aruco.png'
    (see `scene_assets`). Collision groups: arm vs environment and bottles, never arm vs arm."""
    s = scenario.shelf
    floor = s.bottom_z - FLOOR_DROP
    bottles = "".join(_bottle_xml(b, s.top_z) for b in scenario.objects)
    welds = "".join(f'<weld name="grasp_{b.id}" body1="{HAND_BODY}" body2="{b.id}" active="false" '
                    f'solref="0.004 1"/>' for b in scenario.objects)
    return f"""<mujoco model="jaco2_shelf_{scenario.name}">
  <compiler angle="radian" autolimits="true"/>
  <option timestep="0.001" integrator="implicitfast" cone="elliptic" impratio="5">
    <flag multiccd="enable" sleep="enable"/>
  </option>
  <size memory="64M"/>
  <visual><global offwidth="{max(camera.width, 640)}" offheight="{max(camera.height, 480)}"/>
    <quality shadowsize="1024"/><map znear="0.01" zfar="20"/></visual>
  <default>
    <default class="arm_collision"><geom contype="2" conaffinity="1" rgba="0.15 0.15 0.17 1" group="1"/></default>
    <default class="finger"><geom contype="2" conaffinity="1" rgba="0.2 0.2 0.22 1" friction="1.2 0.01 0.001"
      group="1"/></default>
    <default class="shelf"><geom contype="1" conaffinity="3" rgba="0.72 0.58 0.40 1" friction="0.8 0.01 0.001"/>
    </default>
    <default class="bottle"><geom contype="1" conaffinity="3" friction="0.8 0.01 0.001" condim="4"
      solref="0.004 1"/></default>
  </default>
  <asset>
    <texture name="aruco" type="2d" file="aruco.png"/>
    <material name="aruco" texture="aruco" texrepeat="1 1" texuniform="false" specular="0" shininess="0"/>
    <texture name="grid" type="2d" builtin="checker" rgb1="0.55 0.55 0.55" rgb2="0.45 0.45 0.45" width="256"
      height="256"/>
    <material name="floor" texture="grid" texrepeat="8 8"/>
  </asset>
  <worldbody>
    <light name="key" pos="0.0 -0.6 1.6" dir="0.35 0.35 -1" diffuse="0.7 0.7 0.7" castshadow="false"/>
    <light name="fill" pos="-0.3 0.5 1.2" dir="0.5 -0.3 -1" diffuse="0.4 0.4 0.4" castshadow="false"/>
    <light name="shelf_light" pos="0.2 0 0.44" dir="1 0 -0.4" diffuse="0.35 0.35 0.35" castshadow="false"/>
    <geom name="floor" type="plane" pos="0 0 {floor:.6g}" size="3 3 0.1" material="floor" contype="1"
      conaffinity="3"/>
    <geom name="pedestal" type="box" pos="-0.02 0 {floor / 2:.6g}" size="0.09 0.09 {-floor / 2:.6g}"
      rgba="0.3 0.3 0.3 1" contype="1" conaffinity="1"/>
    {_shelf_xml(s)}
    {_marker_xml(scenario.marker)}
    {_camera_xml(camera, s)}
    {mjcf_arm_body(_hand_xml())}
    {bottles}
  </worldbody>
  <equality>{welds}</equality>
  {_actuators_xml()}
</mujoco>"""


def _actuators_xml(kv: float = 200.0) -> str:
    """Velocity actuators (gain kv, gravity compensated bodies, STACK-NOTES) for the arm; position actuators with a
    bounded force for the fingers."""
    from stpik_motion_planner.robot_description import JOINT_NAMES
    arm = "".join(f'<velocity name="v_{j}" joint="{j}" kv="{kv:g}"/>' for j in JOINT_NAMES)
    fingers = "".join(f'<position name="p_{j}" joint="{j}" kp="2" dampratio="1" forcerange="-3 3" '
                      f'ctrlrange="0 {FINGER_CLOSED}"/>' for j in FINGER_JOINT_NAMES)
    return f"<actuator>{arm}{fingers}</actuator>"


def scene_assets(scenario: Scenario) -> dict[str, bytes]:
    """The scene's in-memory files for MjModel.from_xml_string: the ArUco marker texture as PNG."""
    ok, png = cv2.imencode(".png", marker_image(scenario.marker))
    if not ok:
        raise RuntimeError("could not encode the ArUco marker image")
    return {"aruco.png": png.tobytes()}


def build_model(scenario: Scenario, camera: CameraSpec = CameraSpec()) -> mujoco.MjModel:
    """Compile the scene of a scenario (marker texture built in memory)."""
    return mujoco.MjModel.from_xml_string(scene_xml(scenario, camera), scene_assets(scenario))
