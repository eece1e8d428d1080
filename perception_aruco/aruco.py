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
from typing import Any, Sequence

import cv2
import numpy as np

from relocation_common.geometry import invert, pose_error, rotvec_matrix, rpy_matrix, transform
from relocation_common.scenario import Marker


class PerceptionError(RuntimeError):
    """Base class of every perception failure (the node logs it and keeps running)."""


class MarkerNotFoundError(PerceptionError):
    """The scenario's ArUco marker is not in the image (or is too damaged to decode)."""


class MarkerOccludedError(MarkerNotFoundError):
    """The marker is in view but partly covered: too few of its corners lie on the marker plane to place it."""


class MarkerInconsistentError(PerceptionError):
    """The marker was found but its colour-only and depth poses, or its size in depth, disagree."""


class ImageFormatError(PerceptionError):
    """An image with an unexpected shape, dtype or encoding, or colour and depth of different sizes."""


def fuse_markers(seen: Sequence[tuple[Any, Any]]) -> tuple[np.ndarray, float]:
    """(T_base_camera, rms corner residual in m) from several markers seen in one frame, given as (MarkerLocalizer,
    MarkerObservation) pairs: one rigid fit (Kabsch) of every marker's corners in the camera (its depth-refined
    pose) to the same corners in the base frame (the scenario's poses); markers far apart constrain the rotation
    better than any one of them."""
    cam = np.vstack([loc.object_points @ obs.T_camera_marker[:3, :3].T + obs.T_camera_marker[:3, 3]
                     for loc, obs in seen])
    base = np.vstack([loc.object_points @ loc.T_base_marker[:3, :3].T + loc.T_base_marker[:3, 3] for loc, _ in seen])
    t = kabsch(cam, base)
    return t, float(np.sqrt(np.mean(np.sum((cam @ t[:3, :3].T + t[:3, 3] - base) ** 2, axis=1))))


def marker_in_base(marker: Marker) -> np.ndarray:
    """T_base_marker (4x4) from the scenario."""
    return transform(rpy_matrix(marker.rpy), marker.position)


def marker_corners_3d(size: float) -> np.ndarray:
    """Corners in the marker frame in ArUco order (top-left, top-right, bottom-right, bottom-left as seen from the
    front), the order SOLVEPNP_IPPE_SQUARE requires."""
    h = size / 2
    return np.array([[-h, h, 0.0], [h, h, 0.0], [h, -h, 0.0], [-h, -h, 0.0]])


@dataclass(frozen=True)
class MarkerObservation:
    """The marker seen in one image: pixel corners (4x2, ArUco order), T_camera_marker, and the resulting
    T_base_camera; `refined` tells whether the depth refinement was applied; `T_camera_marker_pnp` is the
    colour-only pose; `covered`: fraction of the marker face with something in front; `dropped`: corners on an
    occluding edge (not used)."""

    corners: np.ndarray
    T_camera_marker: np.ndarray
    T_base_camera: np.ndarray
    refined: bool
    T_camera_marker_pnp: np.ndarray | None = None
    covered: float = 0.0
    dropped: tuple[int, ...] = ()


@dataclass(frozen=True)
class MarkerParams:
    """Bounds of the marker checks (docs/perception.md, "Consistency checks")."""

    min_plane_points: int = 30
    plane_tol: float = 0.003        # m: RANSAC inlier distance (raised to 3 x the robust noise estimate)
    occluder_gap: float = 0.01      # m: a point this much nearer than the marker plane is something in front
    corner_covered: float = 0.1     # fraction of a corner's neighbourhood in front: the corner is not used
    max_disagreement_mm: float = 30.0   # colour-only vs depth marker position, at fx = 433 px (640x480; x 433/fx)
    max_disagreement_deg: float = 8.0   # colour-only vs depth marker orientation
    size_tol: float = 0.004         # m (+ 5 %): corner distances from depth vs the marker's size
    ransac_iterations: int = 60
    # corner refinement of cv2.aruco: "subpix" (cornerSubPix; the colour-only pose, which the depth pose is checked
    # against, is 3x closer at 640x480 and holds at 480x360) or "contour" (lines fitted to the border: the marker's
    # rotation about its normal 0.05 deg instead of 0.31 deg at 640x480; used by the calibration)
    corner_refinement: str = "subpix"


CORNER_NAMES = ("top-left", "top-right", "bottom-right", "bottom-left")


def _backproject(K: np.ndarray, uv: np.ndarray, z: np.ndarray) -> np.ndarray:
    x = (uv[:, 0] - K[0, 2]) / K[0, 0] * z
    y = (uv[:, 1] - K[1, 2]) / K[1, 1] * z
    return np.stack([x, y, z], axis=1)


def kabsch(src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """Rigid T with dst ~ T src (least squares)."""
    cs, cd = src.mean(0), dst.mean(0)
    u, _, vt = np.linalg.svd((src - cs).T @ (dst - cd))
    d = np.sign(np.linalg.det(vt.T @ u.T))
    rot = vt.T @ np.diag([1.0, 1.0, d]) @ u.T
    return transform(rot, cd - rot @ cs)


def robust_plane(pts: np.ndarray, tol: float, iterations: int, rng: np.random.Generator) -> tuple[np.ndarray, float]:
    """(unit normal n, offset c) of the plane n.p = c through most of the points: RANSAC on 3-point samples, then
    least squares on the inliers (tolerance raised to 3 x the inliers' robust spread when the depth is noisier)."""
    idx = rng.integers(0, len(pts), (iterations, 3))          # all samples at once (vectorised scoring)
    a, b, c = pts[idx[:, 0]], pts[idx[:, 1]], pts[idx[:, 2]]
    normals = np.cross(b - a, c - a)
    length = np.linalg.norm(normals, axis=1)
    ok = length > 1e-12
    if not ok.any():
        raise MarkerInconsistentError("marker depth is degenerate (no plane)")
    normals, a = normals[ok] / length[ok, None], a[ok]
    offsets = np.sum(normals * a, axis=1)
    scores = np.sum(np.abs(pts @ normals.T - offsets) < tol, axis=0)
    k = int(np.argmax(scores))
    best = (normals[k], float(offsets[k]))
    n, off = best
    for _ in range(3):
        r = pts @ n - off
        spread = 1.4826 * float(np.median(np.abs(r - np.median(r))))
        inl = np.abs(r) < max(tol, 3 * spread)
        q = pts[inl]
        cen = q.mean(0)
        n_new = np.linalg.eigh(np.cov((q - cen).T))[1][:, 0]
        n, off = (n_new if n_new @ n > 0 else -n_new), float((n_new if n_new @ n > 0 else -n_new) @ cen)
    return n, off


class MarkerLocalizer:
    """Finds the scenario's marker and returns the camera pose in the base frame."""

    def __init__(self, marker: Marker, refine_with_depth: bool = True, params: MarkerParams = MarkerParams()):
        try:
            dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, marker.dictionary))
        except AttributeError:
            raise ValueError(f"unknown ArUco dictionary {marker.dictionary!r}") from None
        det = cv2.aruco.DetectorParameters()
        det.cornerRefinementMethod = {"subpix": cv2.aruco.CORNER_REFINE_SUBPIX,
                                      "contour": cv2.aruco.CORNER_REFINE_CONTOUR}[params.corner_refinement]
        self.detector = cv2.aruco.ArucoDetector(dictionary, det)
        self.marker = marker
        self.T_base_marker = marker_in_base(marker)
        self.object_points = marker_corners_3d(marker.size)
        self.refine_with_depth = refine_with_depth
        self.params = params

    def detect_all(self, rgb: np.ndarray) -> tuple[list[np.ndarray], list[int]]:
        """(pixel corners, ids) of every marker of this dictionary in the image (one detector pass, shared by the
        localizers of the other markers of the same dictionary)."""
        gray = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY) if rgb.ndim == 3 else rgb
        corners, ids, _ = self.detector.detectMarkers(gray)
        return list(corners), ([] if ids is None else [int(i) for i in np.asarray(ids).reshape(-1)])

    def detect(self, rgb: np.ndarray, found: tuple[list[np.ndarray], list[int]] | None = None) -> np.ndarray:
        """Pixel corners (4x2) of the scenario's marker id; MarkerNotFoundError if it is not seen. `found`: the
        frame's `detect_all` (same dictionary), else the image is searched here."""
        corners, seen = self.detect_all(rgb) if found is None else found
        if self.marker.id not in seen:
            raise MarkerNotFoundError(
                f"ArUco marker id {self.marker.id} ({self.marker.dictionary}) not detected: not in view, covered or "
                "blurred" + (f" (saw ids {seen})" if seen else " (no marker detected)"))
        return np.asarray(corners[seen.index(self.marker.id)], float).reshape(4, 2)

    def locate(self, rgb: np.ndarray, K: np.ndarray, depth: np.ndarray | None = None,
               expected: np.ndarray | None = None, found: Any = None) -> MarkerObservation:
        """Camera pose in the base frame from the marker (and depth, when given and valid on the marker).
        `expected`: T_camera_marker of earlier frames (the node's fused frame): when the marker is not decoded,
        the depth there tells whether it is covered (MarkerOccludedError names how much). `found`: as in
        `detect`."""
        K = np.asarray(K, float)
        try:
            corners = self.detect(rgb, found)
        except MarkerNotFoundError:
            if expected is not None and depth is not None:
                self.diagnose_cover(K, depth, expected)
            raise
        ok, rvec, tvec = cv2.solvePnP(self.object_points, corners, K, None, flags=cv2.SOLVEPNP_IPPE_SQUARE)
        if not ok:
            raise MarkerNotFoundError(f"solvePnP failed on marker {self.marker.id}")
        t_pnp = transform(rotvec_matrix(rvec), tvec)
        if not (self.refine_with_depth and depth is not None):
            return MarkerObservation(corners, t_pnp, self.T_base_marker @ invert(t_pnp), False, t_pnp)
        refined = self._refine(corners, t_pnp, K, depth)
        if refined is None:
            return MarkerObservation(corners, t_pnp, self.T_base_marker @ invert(t_pnp), False, t_pnp)
        t, covered, dropped = refined
        return MarkerObservation(corners, t, self.T_base_marker @ invert(t), True, t_pnp, covered, dropped)

    def _plate_points(self, K: np.ndarray, depth: np.ndarray, quad: np.ndarray,
                      scale: float) -> tuple[np.ndarray, np.ndarray]:
        """(pixels N x 2, camera points N x 3) with depth inside the quad scaled by `scale` about its centre."""
        h, w = depth.shape
        mask = np.zeros((h, w), np.uint8)
        centre = quad.mean(0)
        cv2.fillConvexPoly(mask, np.round(centre + scale * (quad - centre)).astype(np.int32), 1)
        v, u = np.nonzero(mask & (depth > 0))
        uv = np.stack([u, v], 1).astype(float)
        return uv, _backproject(K, uv, depth[v, u].astype(float))

    def _covered_corners(self, K: np.ndarray, depth: np.ndarray, corners: np.ndarray, n: np.ndarray,
                         off: float) -> tuple[float, list[int]]:
        """(fraction of the plate with something in front, corners whose neighbourhood has something in front)."""
        p = self.params
        uv, pts = self._plate_points(K, depth, corners, 1.3)
        front = (pts @ n - off) > p.occluder_gap          # nearer to the camera than the plane (n faces it)
        side = float(np.mean(np.linalg.norm(corners - np.roll(corners, 1, 0), axis=1)))
        radius = max(3.0, 0.15 * side)
        bad = []
        for k, c in enumerate(corners):
            near = np.linalg.norm(uv - c, axis=1) < radius
            if not near.any() or np.mean(front[near]) > p.corner_covered:
                bad.append(k)
        return float(np.mean(front)) if len(front) else 1.0, bad

    def _refine(self, corners: np.ndarray, t_pnp: np.ndarray, K: np.ndarray, depth: np.ndarray) -> Any:
        """(T_camera_marker, covered fraction, dropped corners) from a robust plane fit to the marker's depth and
        the unoccluded corners' rays; None when too few depth pixels (the colour-only pose stands).
        Raises MarkerOccludedError / MarkerInconsistentError when the checks fail."""
        p = self.params
        _, pts = self._plate_points(K, depth, corners, 1.25)  # the plate's white margin is a quarter side
        if len(pts) < p.min_plane_points:
            return None
        n, off = robust_plane(pts, p.plane_tol, p.ransac_iterations, np.random.default_rng(0))
        if n[2] > 0:  # normal towards the camera
            n, off = -n, -off
        covered, bad = self._covered_corners(K, depth, corners, n, off)
        good = [k for k in range(4) if k not in bad]
        mid = self.marker.id
        if len(good) < 3:
            raise MarkerOccludedError(
                f"marker id {mid} partly covered: {len(bad)} corners on an occluding edge "
                f"({', '.join(CORNER_NAMES[k] for k in bad)}; {covered:.0%} of the plate has something in front)")
        rays = np.c_[(corners[:, 0] - K[0, 2]) / K[0, 0], (corners[:, 1] - K[1, 2]) / K[1, 1], np.ones(4)]
        denom = rays @ n
        if np.any(np.abs(denom[good]) < 1e-6):
            return None
        cam = rays * (off / denom)[:, None]
        obj = self.object_points
        for i in good:
            for j in good:
                if i < j:
                    want = float(np.linalg.norm(obj[i] - obj[j]))
                    got = float(np.linalg.norm(cam[i] - cam[j]))
                    if abs(got - want) > p.size_tol + 0.05 * want:
                        raise MarkerInconsistentError(
                            f"marker id {mid}: corners {CORNER_NAMES[i]}-{CORNER_NAMES[j]} are {got * 1000:.0f} mm "
                            f"apart on the depth plane, expected {want * 1000:.0f} mm (a corner misplaced: partly "
                            f"covered, or the depth not registered to the colour image?)")
        t = kabsch(obj[good], cam[good])
        dt, dr = pose_error(t, t_pnp)
        bound_mm = p.max_disagreement_mm * max(1.0, 433.0 / K[0, 0])  # the colour-only pose degrades with pixel size
        if dt * 1000 > bound_mm or math.degrees(dr) > p.max_disagreement_deg:
            raise MarkerInconsistentError(
                f"marker id {mid}: colour-only and depth poses disagree by {dt * 1000:.0f} mm, "
                f"{math.degrees(dr):.1f} deg (bounds {bound_mm:.0f} mm, {p.max_disagreement_deg:.0f} deg)")
        return t, covered, tuple(bad)

    def diagnose_cover(self, K: np.ndarray, depth: np.ndarray, expected: np.ndarray) -> None:
        """MarkerOccludedError when the marker where `expected` (T_camera_marker) puts it has something in front."""
        obj = self.object_points
        cam = obj @ expected[:3, :3].T + expected[:3, 3]
        if np.any(cam[:, 2] <= 0):
            return
        px = np.c_[K[0, 0] * cam[:, 0] / cam[:, 2] + K[0, 2], K[1, 1] * cam[:, 1] / cam[:, 2] + K[1, 2]]
        n = expected[:3, 2]
        n = -n if n[2] > 0 else n
        covered, bad = self._covered_corners(K, depth, px, n, float(n @ expected[:3, 3]))
        if bad or covered > 0.02:
            raise MarkerOccludedError(
                f"marker id {self.marker.id} not decoded: partly covered, {len(bad)} corners on an occluding edge"
                + (f" ({', '.join(CORNER_NAMES[k] for k in bad)})" if bad else "")
                + f"; {covered:.0%} of the plate has something in front")
