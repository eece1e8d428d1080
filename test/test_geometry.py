"""relocation_common.geometry against computations it did not make: rotations written out by hand here (elementary
matrices, the quaternion and Rodrigues formulas), MuJoCo's and OpenCV's own conversions, and rotations whose
result is known (quarter turns); the quaternion orders (ROS x-y-z-w, MuJoCo w-x-y-z) checked at every function."""
from __future__ import annotations

import math
import warnings

import cv2
import mujoco
import numpy as np
import pytest

from relocation_common import geometry as g
from relocation_common.shelf_object import tilt_of_quaternion

RNG = np.random.default_rng(20240611)
RPYS = [tuple(RNG.uniform([-math.pi, -math.pi / 2, -math.pi], [math.pi, math.pi / 2, math.pi])) for _ in range(200)]
S = math.sqrt(0.5)


def rx(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def ry(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def rz(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def hand_rpy(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """URDF's fixed-axis roll-pitch-yaw, as the URDF specification writes it."""
    return rz(yaw) @ ry(pitch) @ rx(roll)


def hand_quat_matrix(w: float, x: float, y: float, z: float) -> np.ndarray:
    """The rotation of a unit quaternion (Hamilton's convention, scalar w)."""
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def hand_rodrigues(w: np.ndarray) -> np.ndarray:
    th = float(np.linalg.norm(w))
    if th == 0:
        return np.eye(3)
    k = w / th
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(th) * kx + (1 - math.cos(th)) * kx @ kx


def test_rpy_matrix_is_urdf_roll_pitch_yaw():
    for rpy in RPYS:
        assert np.allclose(g.rpy_matrix(rpy), hand_rpy(*rpy), atol=1e-12)
    # a quarter turn in yaw takes x to y; in roll, y to z; in pitch, z to x
    assert np.allclose(g.rpy_matrix((0, 0, math.pi / 2)) @ [1, 0, 0], [0, 1, 0])
    assert np.allclose(g.rpy_matrix((math.pi / 2, 0, 0)) @ [0, 1, 0], [0, 0, 1])
    assert np.allclose(g.rpy_matrix((0, math.pi / 2, 0)) @ [0, 0, 1], [1, 0, 0])


def test_matrix_rpy_inverts_rpy_matrix_and_keeps_yaw_zero_at_gimbal_lock():
    for rpy in RPYS:
        assert np.allclose(g.matrix_rpy(hand_rpy(*rpy)), rpy, atol=1e-9)
    for pitch in (math.pi / 2, -math.pi / 2):
        with warnings.catch_warnings():
            warnings.simplefilter("error")                     # the stated convention, no warning
            r, p, y = g.matrix_rpy(hand_rpy(0.3, pitch, 0.2))
        assert y == 0.0 and p == pytest.approx(pitch)
        assert np.allclose(hand_rpy(r, p, y), hand_rpy(0.3, pitch, 0.2), atol=1e-9)


def test_quaternions_in_both_orders_against_the_formula_and_mujoco():
    for rpy in RPYS:
        rot = hand_rpy(*rpy)
        x, y, z, w = g.quat_xyzw(rot)
        assert w >= 0 and math.isclose(x * x + y * y + z * z + w * w, 1.0, rel_tol=1e-12)
        assert np.allclose(hand_quat_matrix(w, x, y, z), rot, atol=1e-12)
        assert g.quat_wxyz(rot) == (w, x, y, z)
        mj = np.zeros(4)
        mujoco.mju_mat2Quat(mj, rot.reshape(9))                # MuJoCo's (w, x, y, z), sign left as it comes
        assert np.allclose(np.sign(mj[0] or 1.0) * mj, (w, x, y, z), atol=1e-12)
        assert np.allclose(g.xyzw_matrix((x, y, z, w)), rot, atol=1e-12)
        assert np.allclose(g.wxyz_matrix((w, x, y, z)), rot, atol=1e-12)
        back = np.zeros(9)
        mujoco.mju_quat2Mat(back, np.array([w, x, y, z]))
        assert np.allclose(g.wxyz_matrix(mj), back.reshape(3, 3), atol=1e-12)
    # a quarter turn about z: (x, y, z, w) = (0, 0, s, s); the order matters
    assert np.allclose(g.quat_xyzw(rz(math.pi / 2)), (0, 0, S, S))
    assert np.allclose(g.quat_wxyz(rz(math.pi / 2)), (S, 0, 0, S))
    assert np.allclose(g.xyzw_matrix((S, 0, 0, S)) @ [0, 1, 0], [0, 0, 1])   # about x
    assert np.allclose(g.wxyz_matrix((S, S, 0, 0)) @ [0, 1, 0], [0, 0, 1])   # the same turn, MuJoCo's order


def test_quaternion_matrices_normalise_and_take_a_zero_quaternion_as_the_identity():
    assert np.array_equal(g.xyzw_matrix((0, 0, 0, 0)), np.eye(3))
    assert np.array_equal(g.wxyz_matrix((0, 0, 0, 0)), np.eye(3))
    assert np.allclose(g.wxyz_matrix((3, 3, 0, 0)), rx(math.pi / 2))


def test_rotation_vectors_against_rodrigues_and_opencv():
    for _ in range(200):
        w = RNG.normal(0, 1.5, 3)
        assert np.allclose(g.rotvec_matrix(w), hand_rodrigues(w), atol=1e-12)
        assert np.allclose(g.rotvec_matrix(w), cv2.Rodrigues(w.reshape(3, 1))[0], atol=1e-12)
    assert np.array_equal(g.rotvec_matrix(np.zeros(3)), np.eye(3))
    assert np.allclose(g.rotvec_matrix([0, 0, math.pi / 2]), rz(math.pi / 2))


def test_rotation_angle_and_pose_error_against_the_trace():
    for _ in range(200):
        w = RNG.normal(0, 1.0, 3)
        rot = hand_rodrigues(w)
        truth = math.acos(max(-1.0, min(1.0, (np.trace(rot) - 1) / 2)))
        assert g.rotation_angle(rot) == pytest.approx(truth, abs=1e-7)
        assert g.rotation_angle(rot) == pytest.approx(np.linalg.norm(w) if np.linalg.norm(w) <= math.pi
                                                     else 2 * math.pi - np.linalg.norm(w), abs=1e-9)
    assert g.rotation_angle(rx(math.pi)) == pytest.approx(math.pi)
    assert g.rotation_angle(rz(1e-6)) == pytest.approx(1e-6, rel=1e-6)  # small angles to full precision
    a = g.transform(hand_rpy(0.1, 0.2, 0.3), [1.0, 2.0, 3.0])
    b = a @ g.transform(ry(0.25), [0.03, 0.04, 0.0])
    dt, dr = g.pose_error(a, b)
    assert dt == pytest.approx(0.05) and dr == pytest.approx(0.25)


def test_transforms_invert_and_average():
    for rpy in RPYS[:50]:
        t = g.transform(hand_rpy(*rpy), RNG.normal(0, 1, 3))
        assert np.allclose(t @ g.invert(t), np.eye(4), atol=1e-12)
        assert np.allclose(g.invert(t), np.linalg.inv(t), atol=1e-12)
        # the mean of two poses turned +-a about their own z axis, shifted +-d, is the pose itself
        turn = [t @ g.transform(rz(a), [a, 0, 0]) for a in (0.2, -0.2)]
        assert np.allclose(g.mean_pose(turn), t, atol=1e-12)


def test_nearest_rotation_is_a_rotation_and_the_nearest():
    for rpy in RPYS[:50]:
        rot = hand_rpy(*rpy)
        noisy = rot + RNG.normal(0, 0.05, (3, 3))
        near = g.nearest_rotation(noisy)
        assert np.allclose(near @ near.T, np.eye(3), atol=1e-12) and np.linalg.det(near) == pytest.approx(1.0)
        for _ in range(20):                                   # no nearby rotation is nearer
            other = near @ hand_rodrigues(RNG.normal(0, 0.01, 3))
            assert np.linalg.norm(noisy - near) <= np.linalg.norm(noisy - other) + 1e-12
    assert np.linalg.det(g.nearest_rotation(np.diag([1.0, 1.0, -1.0]))) == pytest.approx(1.0)  # not a reflection


def test_tilt_of_a_tipped_bottle():
    assert tilt_of_quaternion(1, 0, 0, 0) == 0.0
    assert tilt_of_quaternion(0, 0, 0, 0) == 0.0                          # a message nobody filled in: upright
    assert tilt_of_quaternion(S, S, 0, 0) == pytest.approx(math.pi / 2)    # w-x-y-z: a quarter turn about x
    assert tilt_of_quaternion(S, 0, 0, S) == pytest.approx(0.0)           # about z: still standing
    for rpy in RPYS:
        rot = hand_rpy(*rpy)
        axis_z = (rot @ [0, 0, 1])[2]
        assert g.tilt(rot) == pytest.approx(math.acos(max(-1.0, min(1.0, axis_z))), abs=1e-9)
        assert tilt_of_quaternion(*g.quat_wxyz(rot)) == pytest.approx(g.tilt(rot), abs=1e-7)
