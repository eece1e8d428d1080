"""Rotations, quaternions, rigid transforms and the distances between poses: the one module every package uses.

Conventions, each named where it is used:
- rotations are 3x3 matrices acting on column vectors; poses are 4x4 homogeneous transforms T_parent_child;
- `rpy` is URDF / ROS fixed-axis roll-pitch-yaw (R = Rz(yaw) Ry(pitch) Rx(roll)), as the scenario's markers and
  URDF origins give it;
- a quaternion's order is in the function's name: `xyzw` as ROS messages carry it (geometry_msgs/Quaternion, tf2),
  `wxyz` as MuJoCo (body quat, xquat) and the simulator's ObjectPose carry it; a quaternion made here has w >= 0.
The conversions are scipy.spatial.transform.Rotation's; numpy where a matrix operation says it more directly.
"""
from __future__ import annotations

import math
import warnings
from collections.abc import Iterable, Sequence

import numpy as np
from scipy.spatial.transform import Rotation

Quaternion = tuple[float, float, float, float]


# ------------------------------------------------------------------------------------------------ rotations
def rpy_matrix(rpy: Sequence[float]) -> np.ndarray:
    """R = Rz(yaw) Ry(pitch) Rx(roll) of URDF roll-pitch-yaw (scipy's extrinsic "xyz")."""
    return Rotation.from_euler("xyz", [float(v) for v in rpy]).as_matrix()


def matrix_rpy(rot: np.ndarray) -> tuple[float, float, float]:
    """URDF roll-pitch-yaw of a rotation matrix, the inverse of `rpy_matrix`; at pitch +-pi/2 (gimbal lock) yaw is
    0 and roll carries the turn about the vertical (scipy's choice too; its warning is silenced: the convention is
    stated here)."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", "Gimbal lock detected", UserWarning)
        r, p, y = Rotation.from_matrix(np.asarray(rot, float)[:3, :3]).as_euler("xyz")
    return float(r), float(p), float(y)


def rotvec_matrix(w: Sequence[float] | np.ndarray) -> np.ndarray:
    """Rotation matrix of a rotation vector (axis times angle in rad; Rodrigues' formula)."""
    return Rotation.from_rotvec(np.asarray(w, float).reshape(3)).as_matrix()


def rotation_angle(rot: np.ndarray) -> float:
    """Angle (rad, in [0, pi]) of a rotation: the magnitude of its rotation vector."""
    return float(Rotation.from_matrix(np.asarray(rot, float)[:3, :3]).magnitude())


def nearest_rotation(m: np.ndarray) -> np.ndarray:
    """The rotation matrix nearest to a 3x3 matrix in the Frobenius norm (SVD, determinant +1)."""
    u, _, vt = np.linalg.svd(m)
    return u @ np.diag([1.0, 1.0, float(np.sign(np.linalg.det(u @ vt)))]) @ vt


def tilt(rot: np.ndarray) -> float:
    """Angle (rad) between the z axis of a rotation and the vertical (base z)."""
    return math.acos(max(-1.0, min(1.0, float(np.asarray(rot, float)[2, 2]))))


# ---------------------------------------------------------------------------------------------- quaternions
def quat_xyzw(rot: np.ndarray) -> Quaternion:
    """Unit quaternion (x, y, z, w), w >= 0, of a rotation matrix (ROS order)."""
    x, y, z, w = quats_xyzw(np.asarray(rot, float)[None, :3, :3])[0]
    return float(x), float(y), float(z), float(w)


def quats_xyzw(rots: np.ndarray) -> np.ndarray:
    """(N, 4) unit quaternions (x, y, z, w), w >= 0, of N rotation matrices (N, 3, 3), in one SciPy call: the sim
    driver's /tf (25 frames at 50 Hz) took a fifth of a core converting one matrix at a time."""
    return Rotation.from_matrix(np.asarray(rots, float)[:, :3, :3]).as_quat(canonical=True)


def quat_wxyz(rot: np.ndarray) -> Quaternion:
    """Unit quaternion (w, x, y, z), w >= 0, of a rotation matrix (MuJoCo order)."""
    x, y, z, w = quat_xyzw(rot)
    return w, x, y, z


def xyzw_matrix(q: Iterable[float]) -> np.ndarray:
    """The 3x3 rotation of a quaternion in ROS order (x, y, z, w), normalised first; a zero one is the identity
    (a message nobody filled in)."""
    v = np.array([float(c) for c in q])
    if not np.any(v):
        return np.eye(3)
    return Rotation.from_quat(v).as_matrix()


def wxyz_matrix(q: Iterable[float]) -> np.ndarray:
    """The 3x3 rotation of a quaternion in MuJoCo order (w, x, y, z), normalised first; a zero one is the
    identity."""
    w, x, y, z = (float(c) for c in q)
    return xyzw_matrix((x, y, z, w))


# ------------------------------------------------------------------------------------------- rigid transforms
def transform(rot: np.ndarray, t: Sequence[float] | np.ndarray) -> np.ndarray:
    """4x4 homogeneous transform of a rotation and a translation."""
    out = np.eye(4)
    out[:3, :3], out[:3, 3] = rot, np.asarray(t, float).reshape(3)
    return out


def invert(t: np.ndarray) -> np.ndarray:
    """Inverse of a rigid 4x4 transform."""
    r = t[:3, :3]
    return transform(r.T, -r.T @ t[:3, 3])


def mean_pose(poses: Iterable[np.ndarray]) -> np.ndarray:
    """Mean of nearby rigid 4x4 poses: positions averaged, the rotation nearest to the sum of the rotations (the
    chordal mean)."""
    poses = list(poses)
    return transform(nearest_rotation(np.sum([t[:3, :3] for t in poses], axis=0)),
                     np.mean([t[:3, 3] for t in poses], axis=0))


# ------------------------------------------------------------------------------------------------- distances
def pose_error(t_est: np.ndarray, t_true: np.ndarray) -> tuple[float, float]:
    """(translation error in m, rotation error in rad) between two 4x4 poses."""
    dt = float(np.linalg.norm(t_est[:3, 3] - t_true[:3, 3]))
    return dt, rotation_angle(t_est[:3, :3].T @ t_true[:3, :3])
