"""MuJoCo scene of the experiment: the Jaco2 arm (from the one robot description), the shelf unit, every object of
a scenario's world (listed and unlisted; cylinders standing or lying, boxes) as free bodies, the ArUco marker as a
texture, the camera and lights. No ROS here.

Frames: the MuJoCo world frame is the robot base frame of the scenario (x towards the shelf, z up, metres).
Everything is generated from `relocation_common.robot_description` and `relocation_common.scenario`, so
the simulated world is the world the planners reason about (Sect. 5 of the paper: top shelf with the
obstacles and the target, bottom shelf where relocated objects go, board above the top shelf).
"""
from __future__ import annotations

import xml.etree.ElementTree as ET
from typing import Any, Iterable

import cv2
import mujoco  # MUJOCO_GL (headless rendering) is set by the package's __init__, imported first
import numpy as np
from numpy.typing import ArrayLike

from relocation_common.geometry import quat_wxyz, rpy_matrix, transform
from relocation_common.robot_description import (
    FINGER_BASE_Z,
    FINGER_CLOSED,
    FINGER_HINGES,
    FINGER_JOINT_NAMES,
    FINGER_LINK_NAMES,
    FINGER_RADIUS,
    GRIPPER_MARKER_DICTIONARY,
    GRIPPER_MARKER_ID,
    GRIPPER_MARKER_SIZE,
    LINK_NAMES,
    T_TOOL_GRIPPER_MARKER,
    finger_tip,
    joint_origins,
    mjcf_arm_body,
)
from relocation_common.scenario import Marker, Scenario, Shelf, ShelfObject

from .params import CameraSpec

CAMERA_NAME = "camera_color"
HAND_BODY = LINK_NAMES[-1]
FINGER_BODY_NAMES = FINGER_LINK_NAMES  # the description's moving fingers (FINGER_HINGES), as MuJoCo bodies
# Static finger capsules of the description (the planner's conservative envelope of the open hand): the simulator
# replaces them with moving finger bodies and switches them off (see Jaco2Sim).
DESCRIPTION_FINGER_GEOMS = ("finger_1", "finger_2", "finger_3")
MARKER_BORDER = 0.25       # white margin around the marker, as a fraction of the marker side
FLOOR_DROP = 0.30          # floor this far below the bottom shelf board


def _f(v: Iterable[float]) -> str:
    return " ".join(f"{float(x):.6g}" for x in v)


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


def _el(parent: ET.Element, tag: str, **attrs: Any) -> ET.Element:
    """A child element; attribute values as text (numbers %.6g, sequences space-separated); `class_` is `class`."""
    def text(v: Any) -> str:
        if isinstance(v, str):
            return v
        if isinstance(v, (list, tuple, np.ndarray)):
            return _f(v)
        return f"{float(v):.6g}" if isinstance(v, float) else str(v)
    return ET.SubElement(parent, tag, {k.rstrip("_"): text(v) for k, v in attrs.items()})


def _hand(last_link: ET.Element) -> None:
    """The description's three fingers (robot_description.FINGER_HINGES) on the last link (its frame: z = approach,
    x = closing direction, grasp centre at z = D67): a hinge at the palm each; the open fingers lie on the
    description's finger capsules, closing rotates the tips towards the grasp centre."""
    for k, (x, y, sign) in enumerate(FINGER_HINGES):
        body = _el(last_link, "body", name=FINGER_BODY_NAMES[k], pos=f"{x} {y} {FINGER_BASE_Z}", gravcomp="1")
        _el(body, "joint", name=FINGER_JOINT_NAMES[k], type="hinge", axis=f"0 {sign:g} 0",
            range=f"0 {FINGER_CLOSED}", limited="true", damping="0.05", armature="0.001")
        _el(body, "geom", name=f"finger_sim_{k + 1}", type="capsule", fromto=f"0 0 0 {_f(finger_tip(k))}",
            size=f"{FINGER_RADIUS}", mass="0.03", class_="finger")


def _box(parent: ET.Element, name: str, lo: ArrayLike, hi: ArrayLike, cls: str = "shelf") -> None:
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    _el(parent, "geom", name=name, type="box", pos=(lo + hi) / 2, size=(hi - lo) / 2, class_=cls)


def _shelf(world: ET.Element, s: Shelf) -> None:
    t, x0, x1, y0, y1 = s.board_thickness, s.x_front, s.x_back, s.y_min, s.y_max
    floor = s.bottom_z - FLOOR_DROP
    _box(world, "shelf_top_board", (x0, y0, s.top_z - t), (x1, y1, s.top_z))
    _box(world, "shelf_ceiling_board", (x0, y0, s.ceiling_z), (x1, y1, s.ceiling_z + t))
    _box(world, "shelf_bottom_board", (x0, y0, s.bottom_z - t), (x1, y1, s.bottom_z))
    _box(world, "shelf_side_left", (x0, y1, floor), (x1, y1 + t, s.ceiling_z + t))
    _box(world, "shelf_side_right", (x0, y0 - t, floor), (x1, y0, s.ceiling_z + t))
    _box(world, "shelf_back_panel", (x1, y0 - t, floor), (x1 + t, y1 + t, s.ceiling_z + t))


def hand_marker() -> Marker:
    """The calibration marker on the hand (robot_description.GRIPPER_MARKER_*; its pose is in the tool frame,
    T_TOOL_GRIPPER_MARKER, so `position` / `rpy` here are unused)."""
    return Marker(GRIPPER_MARKER_ID, GRIPPER_MARKER_DICTIONARY, GRIPPER_MARKER_SIZE, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))


def _marker_plate(parent: ET.Element, name: str, pose: np.ndarray, size: float, material: str) -> None:
    """A thin plate (marker + white margin) whose front face is the marker frame's z = 0 plane (OpenCV convention:
    z out of the face) at `pose` (4x4, in the parent body's frame); no contacts."""
    rot = pose[:3, :3]
    half = size * (1 + 2 * MARKER_BORDER) / 2
    thick = 0.002
    body = _el(parent, "body", name=name, pos=pose[:3, 3] - rot[:, 2] * thick, quat=quat_wxyz(rot))
    _el(body, "geom", name=f"{name}_plate", type="box", size=f"{half:.6g} {half:.6g} {thick}", material=material,
        contype="0", conaffinity="0")


def _marker_name(k: int) -> str:
    """Body, material and texture name of the scenario's k-th marker ('aruco' for the first)."""
    return "aruco" if k == 0 else f"aruco_{k}"


def _marker(world: ET.Element, k: int, m: Marker) -> None:
    """The scenario's k-th marker on its plate (pose from the scenario, in the base frame)."""
    pose = transform(rpy_matrix(m.rpy), m.position)
    _marker_plate(world, f"{_marker_name(k)}_marker", pose, m.size, _marker_name(k))


def _object(world: ET.Element, b: ShelfObject) -> None:
    """An object: a free body whose frame is the centre of its base as built (a cylinder's lower end face, a box's
    bottom face: shelf_object.ShelfObject.base), its z axis the primitive's (a lying cylinder's along its axis);
    the geom `<id>_geom` (cylinder or box) above it along z; mass = weight (kg), colour = rgb."""
    body = _el(world, "body", name=b.id, pos=b.base(), quat=quat_wxyz(b.rotation()))
    _el(body, "freejoint", name=f"{b.id}_free")
    if b.shape == "box":
        sx, sy, sz = b.size
        _el(body, "geom", name=f"{b.id}_geom", type="box", pos=(0.0, 0.0, sz / 2), size=(sx / 2, sy / 2, sz / 2),
            mass=b.weight, rgba=f"{_f(b.rgb)} 1", class_="bottle")
    else:
        _el(body, "geom", name=f"{b.id}_geom", type="cylinder", pos=(0.0, 0.0, b.height / 2),
            size=(b.radius, b.height / 2), mass=b.weight, rgba=f"{_f(b.rgb)} 1", class_="bottle")


def _camera(world: ET.Element, c: CameraSpec, shelf: Shelf) -> None:
    """MuJoCo camera looking from `position` to `look_at` (MuJoCo cameras look along -z with y up)."""
    p, t = c.placed(shelf)
    fwd = (t - p) / np.linalg.norm(t - p)
    right = np.cross(fwd, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, fwd)
    _el(world, "camera", name=CAMERA_NAME, pos=p, xyaxes=f"{_f(right)} {_f(up)}", fovy=c.fovy_deg,
        resolution=f"{c.width} {c.height}")


def _header(root: ET.Element, camera: CameraSpec, markers: int = 1, gripper_marker: bool = False) -> None:
    """Compiler, physics options, visual, the default classes and the assets (materials, marker texture)."""
    _el(root, "compiler", angle="radian", autolimits="true")
    option = _el(root, "option", timestep="0.001", integrator="implicitfast", cone="elliptic", impratio="5")
    _el(option, "flag", multiccd="enable", sleep="enable")
    _el(root, "size", memory="64M")
    visual = _el(root, "visual")
    _el(visual, "global", offwidth=max(camera.width, 640), offheight=max(camera.height, 480))
    _el(visual, "quality", shadowsize="1024")
    _el(visual, "map", znear="0.01", zfar="20")
    default = _el(root, "default")
    # bottles: condim 6 applies the rolling friction their friction triple names (0.001 m; condim 4 left it out, and a
    # bottle lying on a board rolled on at any speed a touch gave it: docs/bench/push.md)
    for cls, geom in (
            ("arm_collision", dict(contype="2", conaffinity="1", rgba="0.15 0.15 0.17 1", group="1")),
            ("finger", dict(contype="2", conaffinity="1", rgba="0.2 0.2 0.22 1", friction="1.2 0.01 0.001",
                            group="1")),
            ("shelf", dict(contype="1", conaffinity="3", rgba="0.72 0.58 0.40 1", friction="0.8 0.01 0.001")),
            ("bottle", dict(contype="1", conaffinity="3", friction="0.8 0.01 0.001", condim="6", solref="0.004 1"))):
        _el(_el(default, "default", class_=cls), "geom", **geom)
    asset = _el(root, "asset")
    for k in range(markers):
        name = _marker_name(k)
        _el(asset, "texture", name=name, type="2d", file=f"{name}.png")
        _el(asset, "material", name=name, texture=name, texrepeat="1 1", texuniform="false", specular="0",
            shininess="0")
    if gripper_marker:
        _el(asset, "texture", name="aruco_gripper", type="2d", file="aruco_gripper.png")
        _el(asset, "material", name="aruco_gripper", texture="aruco_gripper", specular="0", shininess="0")
    _el(asset, "texture", name="grid", type="2d", builtin="checker", rgb1="0.55 0.55 0.55", rgb2="0.45 0.45 0.45",
        width="256", height="256")
    _el(asset, "material", name="floor", texture="grid", texrepeat="8 8")


def scene_xml(scenario: Scenario, camera: CameraSpec | None = None, gripper_marker: bool = False) -> str:
    """MJCF of the whole scene, built with xml.etree.ElementTree (names from a scenario are attribute values,
    escaped, never markup). Physics at 1 kHz (timestep 0.001). The marker textures are the assets 'aruco.png',
    'aruco_<k>.png' (`scene_assets`). Collision groups: arm vs environment and bottles, never arm vs arm.
    `gripper_marker`: the calibration marker on the hand (`hand_marker()`, texture 'aruco_gripper.png'). `camera`
    None: CameraSpec.configured()."""
    s = scenario.shelf
    floor = s.bottom_z - FLOOR_DROP
    root = ET.Element("mujoco", model=f"jaco2_shelf_{scenario.name}")
    camera = camera if camera is not None else CameraSpec.configured()
    _header(root, camera, len(scenario.markers), gripper_marker)
    world = _el(root, "worldbody")
    for name, pos, direction, diffuse in (("key", "0.0 -0.6 1.6", "0.35 0.35 -1", "0.7 0.7 0.7"),
                                          ("fill", "-0.3 0.5 1.2", "0.5 -0.3 -1", "0.4 0.4 0.4"),
                                          ("shelf_light", "0.2 0 0.44", "1 0 -0.4", "0.35 0.35 0.35")):
        _el(world, "light", name=name, pos=pos, dir=direction, diffuse=diffuse, castshadow="false")
    _el(world, "geom", name="floor", type="plane", pos=(0.0, 0.0, floor), size="3 3 0.1", material="floor",
        contype="1", conaffinity="3")
    _el(world, "geom", name="pedestal", type="box", pos=(-0.02, 0.0, floor / 2), size=(0.09, 0.09, -floor / 2),
        rgba="0.3 0.3 0.3 1", contype="1", conaffinity="1")
    _shelf(world, s)
    for k, m in enumerate(scenario.markers):
        _marker(world, k, m)
    _camera(world, camera, s)
    arm = ET.fromstring(mjcf_arm_body())  # the robot description's arm (its own names and numbers only)
    hand = next(b for b in arm.iter("body") if b.get("name") == HAND_BODY)
    _hand(hand)
    if gripper_marker:
        _marker_plate(hand, "gripper_marker", joint_origins()[-1] @ T_TOOL_GRIPPER_MARKER, GRIPPER_MARKER_SIZE,
                      "aruco_gripper")
    world.append(arm)
    for b in scenario.world:
        _object(world, b)
    equality = _el(root, "equality")
    for b in scenario.world:
        _el(equality, "weld", name=f"grasp_{b.id}", body1=HAND_BODY, body2=b.id, active="false", solref="0.004 1")
    _actuators(root)
    return ET.tostring(root, encoding="unicode")


def _actuators(root: ET.Element, kv: float = 200.0) -> None:
    """Velocity actuators (gain kv, gravity compensated bodies: docs/install.md, "Platform notes") for the arm;
    position actuators with a bounded force for the fingers."""
    from relocation_common.robot_description import JOINT_NAMES
    actuator = _el(root, "actuator")
    for j in JOINT_NAMES:
        _el(actuator, "velocity", name=f"v_{j}", joint=j, kv=f"{kv:g}")
    for j in FINGER_JOINT_NAMES:
        _el(actuator, "position", name=f"p_{j}", joint=j, kp="2", dampratio="1", forcerange="-3 3",
            ctrlrange=f"0 {FINGER_CLOSED}")


def _png(marker: Marker) -> bytes:
    ok, png = cv2.imencode(".png", marker_image(marker))
    if not ok:
        raise RuntimeError("could not encode the ArUco marker image")
    return png.tobytes()


def scene_assets(scenario: Scenario, gripper_marker: bool = False) -> dict[str, bytes]:
    """The files the MJCF names: the marker textures 'aruco.png', 'aruco_1.png', ... (and 'aruco_gripper.png' with
    the hand's marker)."""
    assets = {f"{_marker_name(k)}.png": _png(m) for k, m in enumerate(scenario.markers)}
    if gripper_marker:
        assets["aruco_gripper.png"] = _png(hand_marker())
    return assets


def build_model(scenario: Scenario, camera: CameraSpec | None = None, gripper_marker: bool = False) -> mujoco.MjModel:
    """Compile the scene of a scenario (marker textures built in memory); `camera`, `gripper_marker` as in
    `scene_xml`."""
    return mujoco.MjModel.from_xml_string(scene_xml(scenario, camera, gripper_marker),
                                          scene_assets(scenario, gripper_marker))
