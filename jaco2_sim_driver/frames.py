"""The arm's TF frames as robot_state_publisher computes them from the URDF of
`stpik_motion_planner.robot_description.urdf()` and the joint angles (no rclpy).

Each revolute joint i moves link i against its parent by origin_i @ Rz(sign_i * Q_i) (the URDF's <origin> and
<axis xyz="0 0 sign_i">); the fixed joint puts the tool frame `j2s7s300_end_effector` on link 7. The product of the
chain equals the DH forward kinematics of Table 5 (tested in test/test_kinova_surface.py against `dh_fk`).
"""
from __future__ import annotations

import math

import numpy as np

from stpik_motion_planner.robot_description import (
    BASE_LINK, EE_LINK, LINK_NAMES, N_JOINTS, Q_SIGN, joint_origins)

_ORIGINS = joint_origins()
PARENTS = (BASE_LINK,) + LINK_NAMES[:-1]


def _rz(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    m = np.eye(4)
    m[:2, :2] = [[c, -s], [s, c]]
    return m


def arm_transforms(q) -> list[tuple[str, str, np.ndarray]]:
    """(parent, child, 4x4) of the 7 revolute joints at joint angles q (Kinova's Q, rad)."""
    return [(PARENTS[i], LINK_NAMES[i], _ORIGINS[i] @ _rz(Q_SIGN[i] * float(q[i]))) for i in range(N_JOINTS)]


def fixed_transforms() -> list[tuple[str, str, np.ndarray]]:
    """(parent, child, 4x4) of the URDF's fixed joints (robot_state_publisher puts them on /tf_static)."""
    return [(LINK_NAMES[-1], EE_LINK, _ORIGINS[N_JOINTS].copy())]


def chain(q) -> dict[str, np.ndarray]:
    """Pose of every link and of the tool frame in the base frame."""
    out, m = {BASE_LINK: np.eye(4)}, np.eye(4)
    for _, child, t in arm_transforms(q):
        m = m @ t
        out[child] = m
    out[EE_LINK] = m @ _ORIGINS[N_JOINTS]
    return out
