"""The arm's TF frames as robot_state_publisher computes them from the URDF of
`relocation_common.robot_description.urdf()` and the joint angles (no rclpy).

Each revolute joint i moves link i against its parent by origin_i @ Rz(sign_i * Q_i) (the URDF's <origin> and
<axis xyz="0 0 sign_i">); the fixed joint puts the tool frame `j2s7s300_end_effector` on link 7. The product of the
chain equals the DH forward kinematics of Table 5 (tested in test/test_kinova_surface.py against `dh_fk`). The
fingers of `urdf(hand=True)` hang on link 7 (`finger_transforms`; tested against MuJoCo's finger bodies).
"""
from __future__ import annotations

import math
from typing import Iterable, Sequence

import numpy as np

from relocation_common.geometry import transform, wxyz_matrix
from relocation_common.robot_description import (
    BASE_LINK,
    EE_LINK,
    FINGER_BASE_Z,
    FINGER_DRIVE_LINK_NAMES,
    FINGER_GEAR,
    FINGER_HINGES,
    FINGER_LINK_NAMES,
    FINGER_TIP_LINK_NAMES,
    LINK_NAMES,
    N_JOINTS,
    Q_SIGN,
    finger_tip,
    joint_origins,
)

from .sim import ObjectPose

BOTTLE_FRAME = "bottle_{}"  # TF frame of a bottle (ground truth): centre of its base circle
_ORIGINS = joint_origins()
PARENTS = (BASE_LINK,) + LINK_NAMES[:-1]


def _rz(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    m = np.eye(4)
    m[:2, :2] = [[c, -s], [s, c]]
    return m


def arm_transforms(q: Sequence[float] | np.ndarray) -> list[tuple[str, str, np.ndarray]]:
    """(parent, child, 4x4) of the 7 revolute joints at joint angles q (Kinova's Q, rad)."""
    return [(PARENTS[i], LINK_NAMES[i], _ORIGINS[i] @ _rz(Q_SIGN[i] * float(q[i]))) for i in range(N_JOINTS)]


def _tip(k: int) -> np.ndarray:
    m = np.eye(4)
    m[:3, 3] = finger_tip(k)
    return m


_TIPS = tuple(_tip(k) for k in range(len(FINGER_HINGES)))  # the tip joints never move (kinova-ros: always 0)


def _ry(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    m = np.eye(4)
    m[0, 0], m[0, 2], m[2, 0], m[2, 2] = c, s, -s, c
    return m


def finger_transforms(finger_q: Sequence[float] | np.ndarray) -> list[tuple[str, str, np.ndarray]]:
    """(parent, child, 4x4) of the fingers of `urdf(hand=True)` at the simulated hinge angles finger_q (rad): the
    drive frame at the hinge turned by the joint state's angle (finger_q / FINGER_GEAR), the finger on it by the
    mimic joint's (FINGER_GEAR - 1) x that, together the hinge angle; each tip at the finger's end (kinova-ros's tip
    joints, always 0)."""
    out = []
    for k, (x, y, sign) in enumerate(FINGER_HINGES):
        joint = float(finger_q[k]) / FINGER_GEAR
        drive = _ry(sign * joint)
        drive[:3, 3] = (x, y, FINGER_BASE_Z)
        out += [(LINK_NAMES[-1], FINGER_DRIVE_LINK_NAMES[k], drive),
                (FINGER_DRIVE_LINK_NAMES[k], FINGER_LINK_NAMES[k], _ry(sign * (FINGER_GEAR - 1) * joint)),
                (FINGER_LINK_NAMES[k], FINGER_TIP_LINK_NAMES[k], _TIPS[k].copy())]
    return out


def fixed_transforms() -> list[tuple[str, str, np.ndarray]]:
    """(parent, child, 4x4) of the URDF's fixed joints (robot_state_publisher puts them on /tf_static)."""
    return [(LINK_NAMES[-1], EE_LINK, _ORIGINS[N_JOINTS].copy())]


def chain(q: Sequence[float] | np.ndarray) -> dict[str, np.ndarray]:
    """Pose of every link and of the tool frame in the base frame."""
    out, m = {BASE_LINK: np.eye(4)}, np.eye(4)
    for _, child, t in arm_transforms(q):
        m = m @ t
        out[child] = m
    out[EE_LINK] = m @ _ORIGINS[N_JOINTS]
    return out


def bottle_transforms(poses: Iterable[ObjectPose]) -> list[tuple[str, str, np.ndarray]]:
    """(base link, `bottle_<id>`, 4x4) of each bottle's ground truth (sim.ObjectPose: its base centre, w-x-y-z
    quaternion): the bottles' TF frames."""
    out = []
    for p in poses:
        out.append((BASE_LINK, BOTTLE_FRAME.format(p.id), transform(wxyz_matrix(p.quat_wxyz), p.position)))
    return out
