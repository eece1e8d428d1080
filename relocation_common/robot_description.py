"""The one description of the Kinova Jaco2 7-DoF (j2s7s300) arm of the paper, and the URDF and MJCF made from it.

Source of truth: the paper's DH table (Table 5), joint position limits (Table 6) and joint velocity limits
(Table 7). Joint angles everywhere in this project are Kinova's physical angles Q (the arm is straight up at
Q = pi for every joint), the convention of Table 6 and of the real driver. The DH angles of Table 5 are

    theta_i = sign_i * Q_i + offset_i        (theta1 = -Q1, theta2 = Q2 - pi, theta6 = Q6 - pi,
                                              theta7 = -Q7 - pi/2, the others theta = Q)

Standard (distal) DH: T_i = Rz(theta_i) Tz(d_i) Tx(a_i) Rx(alpha_i). The tool frame is the DH frame 7: its z axis
is the approach direction of the hand and its origin the grasp centre between the fingers.
See docs/robot.md for the derivation and the checks.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Iterable

import numpy as np
from numpy.typing import ArrayLike

from .kinova import FINGER_JOINT_CLOSED

PI = math.pi
PREFIX = "j2s7s300"
N_JOINTS = 7
JOINT_NAMES = tuple(f"{PREFIX}_joint_{i}" for i in range(1, N_JOINTS + 1))
LINK_NAMES = tuple(f"{PREFIX}_link_{i}" for i in range(1, N_JOINTS + 1))
BASE_LINK = f"{PREFIX}_link_base"
EE_LINK = f"{PREFIX}_end_effector"
FINGER_JOINT_NAMES = tuple(f"{PREFIX}_joint_finger_{i}" for i in range(1, 4))
FINGER_LINK_NAMES = tuple(f"{PREFIX}_link_finger_{i}" for i in range(1, 4))
FINGER_TIP_JOINT_NAMES = tuple(f"{PREFIX}_joint_finger_tip_{i}" for i in range(1, 4))  # kinova-ros: always 0
FINGER_TIP_LINK_NAMES = tuple(f"{PREFIX}_link_finger_tip_{i}" for i in range(1, 4))
FINGER_DRIVE_LINK_NAMES = tuple(f"{PREFIX}_link_finger_{i}_drive" for i in range(1, 4))
FINGER_GEAR_JOINT_NAMES = tuple(f"{PREFIX}_joint_finger_{i}_gear" for i in range(1, 4))

# Table 5: lengths of the j2s7s300 (m). D1 base-shoulder, D2+D3 upper arm, e2 elbow offset,
# D4+D5 forearm, D6+D7 wrist to grasp centre.
D1, D23, E2, D45, D67 = 0.2755, 0.410, 0.0098, 0.3111, 0.2638
DH_A = (0.0,) * N_JOINTS
DH_ALPHA = (PI / 2, -PI / 2, PI / 2, PI / 2, PI / 2, -PI / 2, 0.0)
DH_D = (D1, 0.0, D23, E2, D45, 0.0, D67)
Q_SIGN = (-1.0, 1.0, 1.0, 1.0, 1.0, 1.0, -1.0)
Q_OFFSET = (0.0, -PI, 0.0, 0.0, 0.0, -PI, -PI / 2)

# Table 6, in Kinova's physical angles Q (rad). Joints 1, 3, 5, 7 are continuous on the real arm; the
# planner bounds them to +-2 pi around the upright pose so that every model has nq = 7.
Q_LOWER = np.array([-PI, 0.82, -PI, 0.52, -PI, 1.13, -PI])
Q_UPPER = np.array([3 * PI, 5.46, 3 * PI, 5.76, 3 * PI, 5.14, 3 * PI])
CONTINUOUS = (True, False, True, False, True, False, True)
# Table 7 (rad/s): the one place of the joint speed limits. The simulator clamps its commands to them, the planner
# times its paths and the follower clamps its commands to them, the URDF carries them. Kinova's own files use 0.628
# and 0.838 (docs/kinova.md): to run with those, change them here.
QDOT_MAX = np.array([0.81, 0.81, 0.81, 0.81, 1.11, 1.11, 1.11])

# Home: hand horizontal (tool y up), pointing at the shelf (+x), in front of the shelf above its ceiling board,
# elbow up and back with joint 4 0.33 rad inside its limit (the motion planner tracks paths from here).
Q_HOME = np.array([3.1703, 3.45079, -0.00676, 5.42905, 3.1005, 2.1153, -0.02335])  # tool at (0.55, 0.0, 0.40)
Q_UPRIGHT = np.full(N_JOINTS, PI)

# Masses (kg) after Kinova's j2s7s300 URDF, for the simulation's dynamics.
LINK_MASS = (0.7477, 0.99, 0.6763, 0.426, 0.426, 0.426, 0.99)
BASE_MASS = 0.46


@dataclass(frozen=True)
class Capsule:
    """A collision capsule fixed to a link: segment p0-p1 in that link's frame, radius r."""

    name: str
    link: str
    p0: tuple[float, float, float]
    p1: tuple[float, float, float]
    radius: float


# Collision capsules in URDF link frames. Link i's frame sits at joint i with z along joint i's axis, so the
# straight part of link i runs from (0,0,0) to (0,0,d_i). The hand is link 7 beyond the wrist: palm, and the
# open fingers (one on +x, two on -x: x is the closing direction) reaching 3 cm past the grasp centre.
CAPSULES = (
    Capsule("base", BASE_LINK, (0, 0, 0.0), (0, 0, 0.10), 0.055),
    Capsule("shoulder", LINK_NAMES[0], (0, 0, 0.10), (0, 0, D1), 0.050),
    Capsule("upper_arm", LINK_NAMES[2], (0, 0, 0.0), (0, 0, D23), 0.045),
    Capsule("forearm", LINK_NAMES[4], (0, 0, 0.0), (0, 0, D45), 0.040),
    Capsule("wrist", LINK_NAMES[6], (0, 0, 0.0), (0, 0, 0.12), 0.040),
    Capsule("palm", LINK_NAMES[6], (0, 0, 0.12), (0, 0, D67 - 0.07), 0.045),
    Capsule("finger_1", LINK_NAMES[6], (0.045, 0, D67 - 0.07), (0.05, 0, D67 + 0.03), 0.012),
    Capsule("finger_2", LINK_NAMES[6], (-0.045, 0.022, D67 - 0.07), (-0.05, 0.022, D67 + 0.03), 0.012),
    Capsule("finger_3", LINK_NAMES[6], (-0.045, -0.022, D67 - 0.07), (-0.05, -0.022, D67 + 0.03), 0.012),
)
# The moving fingers (the simulator's hand, and the published URDF's finger links): a hinge at the palm on link 7
# at (x, y, FINGER_BASE_Z) turning about (0, sign, 0), from open (0, along the description's finger capsules) to
# FINGER_CLOSED (tips of opposing fingers meet). Finger 1 opposes fingers 2 and 3 across x, as on the j2s7s300.
FINGER_HINGES = ((0.045, 0.0, -1.0), (-0.045, 0.022, 1.0), (-0.045, -0.022, 1.0))  # (x, y, sign)
FINGER_BASE_Z = D67 - 0.07
FINGER_LENGTH = 0.10
FINGER_RADIUS = 0.009  # thinner than the planner's 12 mm capsules: the planner's envelope stays conservative
FINGER_CLOSED = 0.5  # rad


FINGER_GEAR = FINGER_CLOSED / FINGER_JOINT_CLOSED  # hinge angle per joint-state angle (both linear in turns)

# Calibration marker on the hand (`./run calibrate`, docs/perception.md "Calibration to the robot"): an ArUco marker
# on a plate beside the palm, facing the tool frame's +y (up at Q_HOME), its x along the approach (tool z); pose in
# the tool frame (OpenCV marker convention: z out of the face). Only the scene built for calibration carries it
# (jaco2_sim_driver.scene, gripper_marker=True): the arm's kinematics and collision model do not include it.
GRIPPER_MARKER_ID = 3
GRIPPER_MARKER_DICTIONARY = "DICT_4X4_50"
GRIPPER_MARKER_SIZE = 0.04   # m, the black square (the white plate around it is 1.5 x as wide)
T_TOOL_GRIPPER_MARKER = np.array([[0.0, 1.0, 0.0, 0.0],
                                  [0.0, 0.0, 1.0, 0.058],
                                  [1.0, 0.0, 0.0, -0.10],
                                  [0.0, 0.0, 0.0, 1.0]])


def finger_tip(k: int) -> tuple[float, float, float]:
    """Tip of finger k in its own (hinge) frame: FINGER_LENGTH along z, bent 5 mm towards the outside."""
    return (0.005 if FINGER_HINGES[k][0] > 0 else -0.005, 0.0, FINGER_LENGTH)


# Pairs that touch by construction (adjacent links) and are never checked for self-collision.
ADJACENT = frozenset(
    frozenset(p) for p in [("base", "shoulder"), ("shoulder", "upper_arm"), ("upper_arm", "forearm"),
                           ("forearm", "wrist"), ("wrist", "palm"), ("palm", "finger_1"),
                           ("palm", "finger_2"), ("palm", "finger_3"), ("finger_1", "finger_2"),
                           ("finger_1", "finger_3"), ("finger_2", "finger_3"), ("wrist", "finger_1"),
                           ("wrist", "finger_2"), ("wrist", "finger_3")]
)


def dh_theta(q: ArrayLike) -> np.ndarray:
    """Kinova physical angles Q -> DH angles theta of Table 5."""
    return np.asarray(Q_SIGN) * np.asarray(q, dtype=float) + np.asarray(Q_OFFSET)


def _dh(theta: float, d: float, a: float, alpha: float) -> np.ndarray:
    ct, st, ca, sa = math.cos(theta), math.sin(theta), math.cos(alpha), math.sin(alpha)
    return np.array([[ct, -st * ca, st * sa, a * ct],
                     [st, ct * ca, -ct * sa, a * st],
                     [0.0, sa, ca, d],
                     [0.0, 0.0, 0.0, 1.0]])


def dh_fk(q: ArrayLike) -> list[np.ndarray]:
    """Forward kinematics straight from the DH table: the 4x4 poses of DH frames 1..7 in the base frame."""
    out, m = [], np.eye(4)
    for th, d, a, al in zip(dh_theta(q), DH_D, DH_A, DH_ALPHA):
        m = m @ _dh(th, d, a, al)
        out.append(m)
    return out


def _rpy(r: np.ndarray) -> tuple[float, float, float]:
    """Roll-pitch-yaw (URDF fixed-axis XYZ) of a rotation matrix."""
    pitch = math.asin(max(-1.0, min(1.0, -r[2, 0])))
    if abs(abs(pitch) - PI / 2) < 1e-9:
        return (math.atan2(-r[1, 2], r[1, 1]), pitch, 0.0)
    return (math.atan2(r[2, 1], r[2, 2]), pitch, math.atan2(r[1, 0], r[0, 0]))


def joint_origins() -> list[np.ndarray]:
    """Fixed transform from link i-1 (base for i=1) to joint i, so that the joint angle is Q itself.

    Joint i rotates about z by sign_i * Q_i after the constant part of DH row i-1 and the offset of row i:
    origin_i = Tz(d_{i-1}) Tx(a_{i-1}) Rx(alpha_{i-1}) Rz(offset_i); the last entry is the tool frame.
    """
    out = []
    for i in range(N_JOINTS + 1):
        m = np.eye(4) if i == 0 else _dh(0.0, DH_D[i - 1], DH_A[i - 1], DH_ALPHA[i - 1])
        if i < N_JOINTS:
            m = m @ _dh(Q_OFFSET[i], 0.0, 0.0, 0.0)
        out.append(m)
    return out


def _fmt(v: Iterable[float]) -> str:
    return " ".join(f"{float(x):.10g}" for x in v)


def urdf(hand: bool = False) -> str:
    """URDF of the arm for Pinocchio: revolute joints in Q with the limits of Tables 6 and 7, capsule geometry.
    hand=True adds the moving fingers (what /robot_description publishes, for robot_state_publisher and RViz: the
    joints of the driver's joint states); the planner's model has only the 7 arm joints and the finger capsules."""
    origins = joint_origins()
    parts = [f'<robot name="{PREFIX}">', f'  <link name="{BASE_LINK}">{_inertial(BASE_MASS, 0.05)}'
             + _capsules_urdf(BASE_LINK) + "</link>"]
    parent = BASE_LINK
    for i in range(N_JOINTS):
        o = origins[i]
        parts.append(
            f'  <joint name="{JOINT_NAMES[i]}" type="revolute"><parent link="{parent}"/>'
            f'<child link="{LINK_NAMES[i]}"/><origin xyz="{_fmt(o[:3, 3])}" rpy="{_fmt(_rpy(o[:3, :3]))}"/>'
            f'<axis xyz="0 0 {Q_SIGN[i]:g}"/><limit lower="{Q_LOWER[i]:.10g}" upper="{Q_UPPER[i]:.10g}" '
            f'effort="40" velocity="{QDOT_MAX[i]:g}"/></joint>')
        parts.append(f'  <link name="{LINK_NAMES[i]}">{_inertial(LINK_MASS[i], DH_D[i] / 2)}'
                     + _capsules_urdf(LINK_NAMES[i]) + "</link>")
        parent = LINK_NAMES[i]
    o = origins[N_JOINTS]
    parts.append(f'  <joint name="{PREFIX}_joint_end_effector" type="fixed"><parent link="{parent}"/>'
                 f'<child link="{EE_LINK}"/><origin xyz="{_fmt(o[:3, 3])}" rpy="{_fmt(_rpy(o[:3, :3]))}"/></joint>')
    parts.append(f'  <link name="{EE_LINK}"/>')
    if hand:
        parts += _fingers_urdf(parent)
    parts.append("</robot>")
    return "\n".join(parts)


def _fingers_urdf(palm: str) -> list[str]:
    """Finger k in kinova-ros's joint convention: `joint_finger_k` (the joint states' angle, 0 .. 1.396 rad at 6800
    turns: relocation_common.kinova) turns a drive frame at the hinge; a mimic joint `joint_finger_k_gear`
    (multiplier FINGER_GEAR - 1) turns the capsule link on it, so the finger turns FINGER_GEAR x the joint angle,
    the simulated hinge's 0 .. FINGER_CLOSED. A tip joint (kinova-ros's joint_finger_tip_k, published at 0) sits at
    the finger's end."""
    out = []
    for k, (x, y, sign) in enumerate(FINGER_HINGES):
        tip = finger_tip(k)
        c = Capsule(FINGER_LINK_NAMES[k], FINGER_LINK_NAMES[k], (0.0, 0.0, 0.0), tip, FINGER_RADIUS)
        xyz, rpy, length = _segment_pose(c)
        axis = f'<axis xyz="0 {sign:g} 0"/>'
        out.append(f'  <joint name="{FINGER_JOINT_NAMES[k]}" type="revolute"><parent link="{palm}"/>'
                   f'<child link="{FINGER_DRIVE_LINK_NAMES[k]}"/>'
                   f'<origin xyz="{x:g} {y:g} {FINGER_BASE_Z:.10g}" rpy="0 0 0"/>{axis}'
                   f'<limit lower="0" upper="{FINGER_JOINT_CLOSED:.10g}" effort="2" velocity="1"/></joint>')
        out.append(f'  <link name="{FINGER_DRIVE_LINK_NAMES[k]}"/>')
        out.append(f'  <joint name="{FINGER_GEAR_JOINT_NAMES[k]}" type="revolute"><parent '
                   f'link="{FINGER_DRIVE_LINK_NAMES[k]}"/><child link="{FINGER_LINK_NAMES[k]}"/>'
                   f'<origin xyz="0 0 0" rpy="0 0 0"/>{axis}<limit lower="-2" upper="2" effort="2" velocity="1"/>'
                   f'<mimic joint="{FINGER_JOINT_NAMES[k]}" multiplier="{FINGER_GEAR - 1:.10g}" offset="0"/></joint>')
        geometry = (f'<origin xyz="{_fmt(xyz)}" rpy="{_fmt(rpy)}"/>'
                    f'<geometry><cylinder radius="{FINGER_RADIUS:g}" length="{length:.10g}"/></geometry>')
        out.append(f'  <link name="{FINGER_LINK_NAMES[k]}">{_inertial(0.03, FINGER_LENGTH / 2)}'
                   f'<visual>{geometry}</visual><collision>{geometry}</collision></link>')
        out.append(f'  <joint name="{FINGER_TIP_JOINT_NAMES[k]}" type="revolute">'
                   f'<parent link="{FINGER_LINK_NAMES[k]}"/><child link="{FINGER_TIP_LINK_NAMES[k]}"/>'
                   f'<origin xyz="{_fmt(tip)}" rpy="0 0 0"/>{axis}'
                   '<limit lower="0" upper="2" effort="1" velocity="1"/></joint>')
        out.append(f'  <link name="{FINGER_TIP_LINK_NAMES[k]}"/>')
    return out


def _inertial(mass: float, zc: float) -> str:
    i = 0.5 * mass * 0.04 ** 2
    return (f'<inertial><origin xyz="0 0 {zc:g}"/><mass value="{mass:g}"/>'
            f'<inertia ixx="{i:g}" iyy="{i:g}" izz="{i:g}" ixy="0" ixz="0" iyz="0"/></inertial>')


def _capsules_urdf(link: str) -> str:
    """Capsules in Pinocchio's URDF extension: a cylinder (along z, length between the cap centres) that a
    <collision_checking><capsule/> element turns into a capsule."""
    out, names = [], []
    for c in CAPSULES:
        if c.link != link:
            continue
        xyz, rpy, length = _segment_pose(c)
        out.append(f'<collision name="{c.name}"><origin xyz="{_fmt(xyz)}" rpy="{_fmt(rpy)}"/>'
                   f'<geometry><cylinder radius="{c.radius:g}" length="{length:.10g}"/></geometry></collision>')
        names.append(c.name)
    if names:
        out.append("<collision_checking>" + "".join(f'<capsule name="{n}"/>' for n in names)
                   + "</collision_checking>")
    return "".join(out)


def _segment_pose(c: Capsule) -> tuple[np.ndarray, tuple[float, float, float], float]:
    """Centre, orientation (z along the segment) and length of a capsule segment."""
    p0, p1 = np.array(c.p0, float), np.array(c.p1, float)
    axis = p1 - p0
    length = float(np.linalg.norm(axis))
    z = axis / length
    x = np.cross([0.0, 1.0, 0.0], z) if abs(z[1]) < 0.9 else np.cross([1.0, 0.0, 0.0], z)
    x /= np.linalg.norm(x)
    rot = np.column_stack([x, np.cross(z, x), z])
    return (p0 + p1) / 2, _rpy(rot), length


def _quat_wxyz(r: np.ndarray) -> tuple[float, float, float, float]:
    w = math.sqrt(max(0.0, 1.0 + r[0, 0] + r[1, 1] + r[2, 2])) / 2
    x = math.copysign(math.sqrt(max(0.0, 1.0 + r[0, 0] - r[1, 1] - r[2, 2])) / 2, r[2, 1] - r[1, 2])
    y = math.copysign(math.sqrt(max(0.0, 1.0 - r[0, 0] + r[1, 1] - r[2, 2])) / 2, r[0, 2] - r[2, 0])
    z = math.copysign(math.sqrt(max(0.0, 1.0 - r[0, 0] - r[1, 1] + r[2, 2])) / 2, r[1, 0] - r[0, 1])
    return (w, x, y, z)


def mjcf_arm_body(hand_xml: str = "") -> str:
    """MJCF <body> tree of the arm (to place inside <worldbody>): hinge joints in Q, Table 6 ranges, capsules.

    `hand_xml` is inserted in the last link's body (e.g. the simulator's finger bodies); the tool frame is the
    site `end_effector`. Arm bodies carry gravcomp="1" for velocity control (docs/install.md, "Platform notes").
    Joint ranges are in radians: the including model needs <compiler angle="radian"/> (MuJoCo's default is degrees).
    """
    origins = joint_origins()
    xml = []
    xml.append(f'<body name="{BASE_LINK}" pos="0 0 0">'
               f'<inertial pos="0 0 0.05" mass="{BASE_MASS:g}" diaginertia="0.001 0.001 0.001"/>'
               + _capsules_mjcf(BASE_LINK))
    for i in range(N_JOINTS):
        o = origins[i]
        rng = "" if CONTINUOUS[i] else f' range="{Q_LOWER[i]:.10g} {Q_UPPER[i]:.10g}" limited="true"'
        xml.append(
            f'<body name="{LINK_NAMES[i]}" pos="{_fmt(o[:3, 3])}" quat="{_fmt(_quat_wxyz(o[:3, :3]))}" gravcomp="1">'
            f'<joint name="{JOINT_NAMES[i]}" type="hinge" axis="0 0 {Q_SIGN[i]:g}"{rng}/>'
            f'<inertial pos="0 0 {DH_D[i] / 2:g}" mass="{LINK_MASS[i]:g}" diaginertia="0.002 0.002 0.001"/>'
            + _capsules_mjcf(LINK_NAMES[i]))
    o = origins[N_JOINTS]
    xml.append(f'<site name="end_effector" pos="{_fmt(o[:3, 3])}" quat="{_fmt(_quat_wxyz(o[:3, :3]))}" size="0.005"/>')
    xml.append(hand_xml)
    xml.append("</body>" * (N_JOINTS + 1))
    return "".join(xml)


def _capsules_mjcf(link: str) -> str:
    return "".join(
        f'<geom name="{c.name}" type="capsule" fromto="{_fmt(c.p0)} {_fmt(c.p1)}" size="{c.radius:g}" '
        f'class="arm_collision"/>' for c in CAPSULES if c.link == link)
