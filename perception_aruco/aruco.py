"""ArUco marker -> camera pose in the robot base frame (the paper's common frame, Sect. 5: "an ArUco marker on the
shelf gives the transformation between camera and robot").

The marker's pose in the base frame is known (scenario `marker`: OpenCV convention, z out of the face, x right,
y up as seen from the front). Its pose in the camera optical frame comes from the four detected corners
(`cv2.aruco.ArucoDetector`, sub-pixel corners, `cv2.solvePnP` with `SOLVEPNP_IPPE_SQUARE`), optionally refined with
the depth image (plane fit over the marker face: the normal from depth is far more precise than from a 40-pixel
square). Then  T_base_camera = T_base_marker @ inv(T_camera_marker).  No rclpy here.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from relocation_common.scenario import Marker


class PerceptionError(RuntimeError):
    """Base class of every perception failure (the node logs it and keeps running)."""


class MarkerNotFoundError(PerceptionError):
    """The scenario's ArUco marker is not in the image (or is too damaged to decode)."""


class ImageFormatError(PerceptionError):
    """An image with an unexpected shape, dtype or encoding, or colour and depth of different sizes."""


def rpy_matrix(rpy) -> np.ndarray:
    """R = Rz(yaw) Ry(pitch) Rx(roll): URDF / ROS fixed-axis roll-pitch-yaw (the scenario's `rpy`)."""
    r, p, y = (float(v) for v in rpy)
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                     [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                     [-sp, cp * sr, cp * cr]])


def transform(rot: np.ndarray, t) -> np.ndarray:
    out = np.eye(4)
    out[:3, :3], out[:3, 3] = rot, np.asarray(t, float).reshape(3)
    return out


def invert(t: np.ndarray) -> np.ndarray:
    r = t[:3, :3]
    return transform(r.T, -r.T @ t[:3, 3])


def marker_in_base(marker: Marker) -> np.ndarray:
    """T_base_marker (4x4) from the scenario."""
    return transform(rpy_matrix(marker.rpy), marker.position)


def marker_corners_3d(size: float) -> np.ndarray:
    """Corners in the marker frame in ArUco order (top-left, top-right, bottom-right, bottom-left as seen from the
    front), the order SOLVEPNP_IPPE_SQUARE requires."""
    h = size / 2
    return np.array([[-h, h, 0.0], [h, h, 0.0], [h, -h, 0.0], [-h, -h, 0.0]])


def pose_error(t_est: np.ndarray, t_true: np.ndarray) -> tuple[float, float]:
    """(translation error in m, rotation error in rad) between two 4x4 poses."""
    dt = float(np.linalg.norm(t_est[:3, 3] - t_true[:3, 3]))
    c = (np.trace(t_est[:3, :3].T @ t_true[:3, :3]) - 1) / 2
    return dt, float(math.acos(max(-1.0, min(1.0, c))))


@dataclass(frozen=True)
class MarkerObservation:
    """The marker seen in one image: pixel corners (4x2, ArUco order), T_camera_marker, and the resulting
    T_base_camera; `refined` tells whether the depth plane refinement was applied."""

    corners: np.ndarray
    T_camera_marker: np.ndarray
    T_base_camera: np.ndarray
    refined: bool


def _backproject(K: np.ndarray, uv: np.ndarray, z: np.ndarray) -> np.ndarray:
    x = (uv[:, 0] - K[0, 2]) / K[0, 0] * z
    y = (uv[:, 1] - K[1, 2]) / K[1, 1] * z
    return np.stack([x, y, z], axis=1)


def _kabsch(src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """Rigid T with dst ~ T src (least squares)."""
    cs, cd = src.mean(0), dst.mean(0)
    u, _, vt = np.linalg.svd((src - cs).T @ (dst - cd))
    d = np.sign(np.linalg.det(vt.T @ u.T))
    rot = vt.T @ np.diag([1.0, 1.0, d]) @ u.T
    return transform(rot, cd - rot @ cs)


class MarkerLocalizer:
    """Finds the scenario's marker and returns the camera pose in the base frame."""

    def __init__(self, marker: Marker, refine_with_depth: bool = True, min_plane_points: int = 30):
        try:
            dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, marker.dictionary))
        except AttributeError:
            raise ValueError(f"unknown ArUco dictionary {marker.dictionary!r}") from None
        params = cv2.aruco.DetectorParameters()
        params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
        self.detector = cv2.aruco.ArucoDetector(dictionary, params)
        self.marker = marker
        self.T_base_marker = marker_in_base(marker)
        self.object_points = marker_corners_3d(marker.size)
        self.refine_with_depth = refine_with_depth
        self.min_plane_points = min_plane_points

    def detect(self, rgb: np.ndarray) -> np.ndarray:
        """Pixel corners (4x2) of the scenario's marker id; MarkerNotFoundError if it is not seen."""
        gray = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY) if rgb.ndim == 3 else rgb
        corners, ids, _ = self.detector.detectMarkers(gray)
        seen = [] if ids is None else [int(i) for i in np.asarray(ids).reshape(-1)]
        if self.marker.id not in seen:
            raise MarkerNotFoundError(
                f"ArUco marker id {self.marker.id} ({self.marker.dictionary}) not in view"
                + (f" (saw ids {seen})" if seen else " (no marker detected)"))
        return np.asarray(corners[seen.index(self.marker.id)], float).reshape(4, 2)

    def locate(self, rgb: np.ndarray, K: np.ndarray, depth: np.ndarray | None = None) -> MarkerObservation:
        """Camera pose in the base frame from the marker (and depth, when given and valid on the marker)."""
        corners = self.detect(rgb)
        ok, rvec, tvec = cv2.solvePnP(self.object_points, corners, np.asarray(K, float), None,
                                      flags=cv2.SOLVEPNP_IPPE_SQUARE)
        if not ok:
            raise MarkerNotFoundError(f"solvePnP failed on marker {self.marker.id}")
        t_cam_marker = transform(cv2.Rodrigues(rvec)[0], tvec)
        refined = False
        if self.refine_with_depth and depth is not None:
            t = self._refine(corners, t_cam_marker, K, depth)
            if t is not None:
                t_cam_marker, refined = t, True
        return MarkerObservation(corners, t_cam_marker, self.T_base_marker @ invert(t_cam_marker), refined)

    def _refine(self, corners, t_cam_marker, K, depth) -> np.ndarray | None:
        """Fit a plane to the depth pixels inside the marker quad; intersect the corner rays with it; Kabsch.
        None when too few valid depth pixels (then the PnP pose stands)."""
        h, w = depth.shape
        mask = np.zeros((h, w), np.uint8)
        centre = corners.mean(0)
        inner = centre + 0.8 * (corners - centre)  # stay off the silhouette edges
        cv2.fillConvexPoly(mask, np.round(inner).astype(np.int32), 1)
        v, u = np.nonzero(mask & (depth > 0))
        if len(u) < self.min_plane_points:
            return None
        pts = _backproject(K, np.stack([u, v], 1).astype(float), depth[v, u].astype(float))
        c = pts.mean(0)
        n = np.linalg.eigh(np.cov((pts - c).T))[1][:, 0]  # normal: direction of least spread
        rays = np.c_[(corners[:, 0] - K[0, 2]) / K[0, 0], (corners[:, 1] - K[1, 2]) / K[1, 1], np.ones(4)]
        denom = rays @ n
        if np.any(np.abs(denom) < 1e-6):
            return None
        corners_cam = rays * ((c @ n) / denom)[:, None]
        t = _kabsch(self.object_points, corners_cam)
        # reject a refinement that disagrees grossly with PnP (depth of something else inside the quad)
        dt, dr = pose_error(t, t_cam_marker)
        return t if dt < 0.05 and dr < math.radians(20) else None
