"""Calibration of the fixed camera to the robot (eye-to-hand): the camera's pose in the robot base frame from a
marker on the gripper seen at several arm poses, and from it the shelf marker's pose in the base frame (the
paper's common frame, Sect. 5, measured instead of taken from the scenario). No rclpy here.

At every arm pose i the forward kinematics give T_base_gripper_i and the camera sees the gripper marker at
T_camera_marker_i; with X = T_gripper_marker and Z = T_base_camera (both constant)

    T_base_gripper_i @ X = Z @ T_camera_marker_i,

the robot-world / hand-eye problem AX = ZB. Solved here as OpenCV's `calibrateRobotWorldHandEye` does with
Shah's method (M. Shah, "Solving the robot-world/hand-eye calibration problem using the Kronecker product", 2013):
the rotations from the null space of the Kronecker system, then the translations by least squares; then refined
(Gauss-Newton) on the marker's corners, which weighs rotation and translation errors as the image measures them.
(The OpenCV 5.0 wheels of this project expose the CALIB_HAND_EYE_* constants but not the functions.) The file
written (`save_calibration`) holds the shelf markers'
poses in the base frame, which perception uses instead of the scenario's (`apply_calibration`).
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import yaml

from relocation_common.geometry import matrix_rpy, mean_pose, nearest_rotation, pose_error, rotvec_matrix, transform
from relocation_common.scenario import Marker, Scenario

from .aruco import PerceptionError

MIN_POSES = 6              # fewer arm poses with the marker seen: the calibration is refused
MAX_RESIDUAL_MM = 3.0      # rms disagreement of the two sides of the equation above at the marker
MAX_RESIDUAL_DEG = 0.5


class CalibrationError(PerceptionError):
    """The calibration cannot be solved or its observations do not agree (the message says what to do)."""


@dataclass(frozen=True)
class HandEye:
    """Solution of the eye-to-hand calibration: T_base_camera, T_gripper_marker, the rms residual over the poses
    (position mm, rotation deg) and the number of poses used."""

    T_base_camera: np.ndarray
    T_gripper_marker: np.ndarray
    residual_mm: float
    residual_deg: float
    poses: int


def solve_hand_eye(T_base_gripper: Sequence[np.ndarray], T_camera_marker: Sequence[np.ndarray]) -> HandEye:
    """T_base_camera and T_gripper_marker from paired arm poses (forward kinematics) and marker observations
    (module docstring); CalibrationError when too few poses or when the observations disagree."""
    if len(T_base_gripper) != len(T_camera_marker):
        raise CalibrationError("calibration: as many marker observations as arm poses are needed")
    if len(T_base_gripper) < MIN_POSES:
        raise CalibrationError(f"calibration: the gripper marker was seen at {len(T_base_gripper)} arm poses, at "
                               f"least {MIN_POSES} are needed: move the arm where the camera sees the marker")
    T_gripper_marker, T_base_camera = _refine(T_base_gripper, T_camera_marker,
                                              *_closed_form(T_base_gripper, T_camera_marker))
    errs = [pose_error(g @ T_gripper_marker, T_base_camera @ m) for g, m in zip(T_base_gripper, T_camera_marker)]
    res_mm = 1000 * math.sqrt(float(np.mean([e[0] ** 2 for e in errs])))
    res_deg = math.degrees(math.sqrt(float(np.mean([e[1] ** 2 for e in errs]))))
    if res_mm > MAX_RESIDUAL_MM or res_deg > MAX_RESIDUAL_DEG:
        raise CalibrationError(
            f"calibration: the arm poses and the marker observations disagree by {res_mm:.1f} mm, {res_deg:.2f} deg "
            f"rms (bounds {MAX_RESIDUAL_MM:g} mm, {MAX_RESIDUAL_DEG:g} deg): the camera or the marker moved "
            "during the calibration, or the joint angles are not those of the images")
    return HandEye(T_base_camera, T_gripper_marker, res_mm, res_deg, len(T_base_gripper))


def _closed_form(A: Sequence[np.ndarray], B: Sequence[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """(X, Z) of A_i X = Z B_i, Shah's method: R_A R_X = R_Z R_B is, with column-major vec,
    (I (x) R_A) vec R_X - (R_B^T (x) I) vec R_Z = 0 (null vector by SVD, scaled to det 1, projected on SO(3));
    then R_A t_X - t_Z = R_Z t_B - t_A by least squares."""
    eye = np.eye(3)
    rows = np.vstack([np.hstack([np.kron(eye, a[:3, :3]), -np.kron(b[:3, :3].T, eye)]) for a, b in zip(A, B)])
    v = np.linalg.svd(rows)[2][-1]
    rx, rz = v[:9].reshape(3, 3, order="F"), v[9:].reshape(3, 3, order="F")
    scale = np.cbrt(np.linalg.det(rx))
    rx, rz = nearest_rotation(rx / scale), nearest_rotation(rz / scale)
    lhs = np.vstack([np.hstack([a[:3, :3], -eye]) for a in A])
    rhs = np.concatenate([rz @ b[:3, 3] - a[:3, 3] for a, b in zip(A, B)])
    t = np.linalg.lstsq(lhs, rhs, rcond=None)[0]
    return transform(rx, t[:3]), transform(rz, t[3:])


def _refine(A: Sequence[np.ndarray], B: Sequence[np.ndarray], X: np.ndarray, Z: np.ndarray,
            iterations: int = 10) -> tuple[np.ndarray, np.ndarray]:
    """Gauss-Newton on sum |A_i X c - Z B_i c|^2 over the corners c of a 4 cm square in the marker's plane (the
    hand marker's scale), numeric Jacobian over 12 parameters (rotation vector and translation of X and of Z)."""
    ch = np.array([[-0.02, 0.02, 0.0, 1.0], [0.02, 0.02, 0.0, 1.0], [0.02, -0.02, 0.0, 1.0],
                   [-0.02, -0.02, 0.0, 1.0]]).T

    def residual(x: np.ndarray) -> np.ndarray:
        xx = transform(rotvec_matrix(x[:3]) @ X[:3, :3], X[:3, 3] + x[3:6])
        zz = transform(rotvec_matrix(x[6:9]) @ Z[:3, :3], Z[:3, 3] + x[9:])
        return np.concatenate([((a @ xx - zz @ b) @ ch)[:3].ravel() for a, b in zip(A, B)])

    for _ in range(iterations):
        r0 = residual(np.zeros(12))
        jac = np.stack([(residual(d) - r0) / 1e-7 for d in 1e-7 * np.eye(12)], axis=1)
        step = np.linalg.lstsq(jac, -r0, rcond=None)[0]
        X = transform(rotvec_matrix(step[:3]) @ X[:3, :3], X[:3, 3] + step[3:6])
        Z = transform(rotvec_matrix(step[6:9]) @ Z[:3, :3], Z[:3, 3] + step[9:])
        if np.linalg.norm(step) < 1e-9:
            break
    return X, Z


def marker_in_base_from(hand_eye: HandEye, marker: Marker, T_camera_marker: Sequence[np.ndarray]) -> Marker:
    """The shelf marker with its pose in the base frame measured: the calibrated camera pose times the marker's
    pose in the camera (the mean over the frames given)."""
    if not len(T_camera_marker):
        raise CalibrationError(f"calibration: the shelf marker id {marker.id} was not seen: clear the camera's view "
                               "of it")
    t = hand_eye.T_base_camera @ mean_pose(T_camera_marker)
    x, y, z = (float(v) for v in t[:3, 3])
    return replace(marker, position=(x, y, z), rpy=matrix_rpy(t[:3, :3]))


def _pose(t: np.ndarray) -> dict:
    return {"position": [round(float(v), 6) for v in t[:3, 3]], "rpy": [round(v, 7) for v in matrix_rpy(t[:3, :3])]}


def save_calibration(path: Path, markers: Sequence[Marker], hand_eye: HandEye, note: str) -> None:
    """The calibration file (YAML): the shelf markers' measured poses in the base frame (what perception reads),
    the camera's, and the hand-eye residuals."""
    doc = {"markers": [{"id": m.id, "dictionary": m.dictionary, "size": m.size,
                        "position": [round(float(v), 6) for v in m.position],
                        "rpy": [round(float(v), 7) for v in m.rpy]} for m in markers],
           "camera_optical_frame": _pose(hand_eye.T_base_camera),
           "hand_eye": {"poses": hand_eye.poses, "residual_mm": round(hand_eye.residual_mm, 3),
                        "residual_deg": round(hand_eye.residual_deg, 4)}}
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(f"# {note}\n# Read by perception (parameter calibration_file): these markers' poses replace the "
                    "scenario's.\n" + yaml.safe_dump(doc, sort_keys=False))


def load_calibration(path: str | Path) -> tuple[Marker, ...]:
    """The shelf markers of a calibration file (CalibrationError naming what is wrong with the file)."""
    p = Path(path)
    try:
        return tuple(Marker(int(m["id"]), str(m["dictionary"]), float(m["size"]),
                            tuple(float(v) for v in m["position"]),  # type: ignore[arg-type]
                            tuple(float(v) for v in m["rpy"]))  # type: ignore[arg-type]
                     for m in yaml.safe_load(p.read_text())["markers"])
    except FileNotFoundError:
        raise CalibrationError(f"calibration file {p} not found: run `./run calibrate` or set calibration_file "
                               "to '' (the scenario's marker poses)") from None
    except (OSError, yaml.YAMLError, KeyError, TypeError, ValueError) as e:
        raise CalibrationError(f"calibration file {p} is not a calibration (markers: id, dictionary, size, "
                               f"position, rpy): {e}; run `./run calibrate` again") from None


def apply_calibration(scenario: Scenario, markers: Sequence[Marker]) -> Scenario:
    """The scenario with the calibrated markers' poses (a scenario marker the calibration did not see keeps its
    pose); CalibrationError when the file has a marker the scenario has not."""
    mine = {(m.id, m.dictionary, round(m.size, 6)): m for m in markers}
    known = {(m.id, m.dictionary, round(m.size, 6)) for m in scenario.markers}
    for key in mine.keys() - known:
        raise CalibrationError(
            f"the calibration has marker id {key[0]} ({key[1]}, {key[2]} m), which the scenario has not (its markers: "
            f"{', '.join(str(m.id) for m in scenario.markers)}): calibrate with this scenario")

    def measured(m: Marker) -> Marker:
        c = mine.get((m.id, m.dictionary, round(m.size, 6)))
        return m if c is None else replace(m, position=c.position, rpy=c.rpy)
    return replace(scenario, marker=measured(scenario.marker), more_markers=tuple(map(measured, scenario.more_markers)))
