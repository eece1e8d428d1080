"""The shelf as a second, larger marker: its boards and panels must appear in the depth image where the camera pose
(from the ArUco marker) puts them (docs/perception.md, "Consistency checks").

The scenario gives the shelf's planes in the base frame: the top and bottom boards' upper surfaces (z = top_z,
bottom_z) and the ceiling board's (the camera looks down on it), the boards' front edges (x = x_front), the back
panel's front face (x = x_back) and the side panels' inner faces
(y = y_min, y_max). Depth points of the frame (base frame, bottle pixels excluded) near a plane and inside its
extent are its observations. A small rigid correction of the base frame (rotation w, translation t) minimises
sum_i rho(n_i . (p_i + w x p_i + t) - d_i), linear in (w, t), with Huber weights, in four passes with a
narrowing band (the points are re-assigned to planes after each pass). The correction is how far the marker frame
is from where the shelf says it is; `ShelfFit.check` refuses a frame whose correction or plane residuals are out of
bounds, naming the planes. No rclpy here.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from relocation_common.geometry import rotation_angle, rotvec_matrix
from relocation_common.scenario import Scenario

from .aruco import PerceptionError


class InconsistentFrameError(PerceptionError):
    """The frame fails a consistency check (shelf, marker, identities): refused, with the reason."""


@dataclass(frozen=True)
class ShelfParams:
    """Bounds of the shelf fit and its checks (module docstring)."""

    bands: tuple[float, ...] = (0.05, 0.03, 0.015, 0.008)  # m: a plane's observations, per pass
    huber: float = 0.003          # m: residuals beyond this are down-weighted
    edge_margin: float = 0.012    # m kept off a plane's borders (corners belong to two planes)
    min_points: int = 800         # image pixels on a plane (before the stride), to use it
    stride: int = 4               # every stride-th pixel in each direction (speed)
    max_shift: float = 0.05       # m: a larger correction of the marker frame (at the shelf's centre) refuses it
    max_rotation: float = 5.0     # deg
    max_rms: float = 0.006        # m: a used plane's rms residual after the correction
    max_offset: float = 0.003     # m: a used plane's median residual after the correction (the geometry agrees)
    intrinsics: bool = True       # refine the focal scales and principal point too (a camera_info a few % off)
    max_focal: float = 0.05       # bound of the focal scale correction (5 %)
    max_centre: float = 0.03      # bound of the principal-point correction (x focal length: 13 px at 640x480)


@dataclass(frozen=True)
class Plane:
    """A face of the shelf in the base frame."""

    name: str
    axis: int        # 0 x, 1 y, 2 z: the plane is {p: p[axis] = d}
    d: float
    lo: tuple[float, float, float]   # extent (the coordinate on `axis` is ignored)
    hi: tuple[float, float, float]


def shelf_planes(scenario: Scenario) -> list[Plane]:
    """The faces of the scenario's shelf that face into the compartments or up (jaco2_sim_driver.scene builds the
    same boxes)."""
    s = scenario.shelf
    x0, x1, y0, y1 = s.x_front, s.x_back, s.y_min, s.y_max
    low, high, t = s.bottom_z, s.ceiling_z, s.board_thickness
    return [Plane("top board", 2, s.top_z, (x0, y0, 0), (x1, y1, 0)),
            Plane("bottom board", 2, s.bottom_z, (x0, y0, 0), (x1, y1, 0)),
            Plane("ceiling board (upper face)", 2, s.ceiling_z + t, (x0, y0, 0), (x1, y1, 0)),
            Plane("top board front edge", 0, x0, (0, y0, s.top_z - t), (0, y1, s.top_z)),
            Plane("bottom board front edge", 0, x0, (0, y0, s.bottom_z - t), (0, y1, s.bottom_z)),
            Plane("ceiling board front edge", 0, x0, (0, y0, s.ceiling_z), (0, y1, s.ceiling_z + t)),
            Plane("back panel", 0, x1, (0, y0, low), (0, y1, high)),
            Plane("right side panel", 1, y0, (x0, 0, low), (x1, 0, high)),
            Plane("left side panel", 1, y1, (x0, 0, low), (x1, 0, high))]


@dataclass(frozen=True)
class ShelfFit:
    """correction: 4x4 in the base frame (T_base_camera_corrected = correction @ T_base_camera); per used plane
    (name -> (points, rms residual m, median residual m after and before the correction)); unused: planes with too
    few points."""

    correction: np.ndarray
    planes: dict[str, tuple[int, float, float, float]]
    unused: tuple[str, ...]
    noise: float = 0.0            # m: robust spread of the used planes' residuals (the depth noise at the shelf)
    intrinsics: np.ndarray = field(default_factory=lambda: np.zeros(4))  # kx, ky, px, py (see `_to_base`)

    centre: np.ndarray = field(default_factory=lambda: np.zeros(3))  # the shelf's centre (base frame)
    noise_1m: float = 0.0         # m: the depth noise at 1 m of depth: sigma(z) = noise_1m * z^2 (the same residuals)

    @property
    def shift(self) -> float:
        """How far the correction moves the shelf's centre (m)."""
        c = self.centre
        return float(np.linalg.norm(self.correction[:3, :3] @ c + self.correction[:3, 3] - c))

    @property
    def rotation_deg(self) -> float:
        """Rotation of the correction (deg)."""
        return math.degrees(rotation_angle(self.correction[:3, :3]))

    def summary(self) -> str:
        """One line: the correction and the planes used."""
        used = ", ".join(f"{n} {k} pts {rms * 1000:.1f} mm rms (was {m * 1000:+.0f} mm)"
                         for n, (k, rms, _, m) in self.planes.items())
        kx, ky, px, py = self.intrinsics
        return (f"shelf vs marker frame: {self.shift * 1000:.1f} mm, {self.rotation_deg:.2f} deg, focal "
                f"{kx:+.2%}/{ky:+.2%}, centre {px * 1000:+.1f}/{py * 1000:+.1f} mrad; {used}")

    def check(self, params: ShelfParams) -> None:
        """InconsistentFrameError when the shelf does not confirm the marker frame (see the module docstring)."""
        if "top board" not in self.planes and "bottom board" not in self.planes:
            raise InconsistentFrameError("shelf boards not found in the depth where the marker frame puts them "
                                         f"(is the scenario's marker pose right, the shelf in view?); {self.summary()}")
        if self.shift > params.max_shift or self.rotation_deg > params.max_rotation:
            raise InconsistentFrameError(
                f"the shelf is {self.shift * 1000:.0f} mm / {self.rotation_deg:.1f} deg from where the marker frame "
                f"puts it (bounds {params.max_shift * 1000:.0f} mm / {params.max_rotation:.0f} deg): check the "
                f"scenario's marker pose; {self.summary()}")
        kx, ky, px, py = self.intrinsics
        if max(abs(kx), abs(ky)) > params.max_focal or max(abs(px), abs(py)) > params.max_centre:
            raise InconsistentFrameError(
                f"the camera intrinsics would need a correction of {kx:+.1%} / {ky:+.1%} in focal length and "
                f"({px:+.3f}, {py:+.3f}) x f in principal point to fit the shelf: check camera_info (or the scenario's "
                f"marker pose); {self.summary()}")
        bad = [f"{n}: {rms * 1000:.1f} mm rms, {med * 1000:+.1f} mm off" for n, (_, rms, med, _) in self.planes.items()
               if rms > params.max_rms or abs(med) > params.max_offset]
        if bad:
            raise InconsistentFrameError(f"shelf planes do not fit together after aligning the frame ({'; '.join(bad)}"
                                         f"; wrong intrinsics, depth scale or shelf size?): {self.summary()}")


def _assign(pts: np.ndarray, planes: list[Plane], band: float, margin: float) -> tuple[np.ndarray, np.ndarray]:
    """(plane index per point or -1, signed residual) for the nearest plane within `band` whose extent holds it."""
    best = np.full(len(pts), -1)
    res = np.full(len(pts), np.inf)
    for k, pl in enumerate(planes):
        r = pts[:, pl.axis] - pl.d
        inside = np.abs(r) < band
        for a in range(3):
            if a != pl.axis:
                m = min(margin, (pl.hi[a] - pl.lo[a]) / 4)
                inside &= (pts[:, a] > pl.lo[a] + m) & (pts[:, a] < pl.hi[a] - m)
        take = inside & (np.abs(r) < np.abs(res))
        best[take], res[take] = k, r[take]
    return best, res


def fit_shelf(points_cam: np.ndarray, exclude: np.ndarray, T_base_camera: np.ndarray, scenario: Scenario,
              params: ShelfParams = ShelfParams()) -> ShelfFit:
    """Align the observed shelf (HxWx3 camera-frame points, NaN without depth; `exclude`: HxW bool, e.g. bottle
    pixels; T_base_camera: the marker's camera pose) to the scenario's shelf planes (module docstring). With
    `params.intrinsics` the pinhole's focal scales and principal point are refined too (`ShelfFit.K`)."""
    st = params.stride
    c = points_cam[::st, ::st][~exclude[::st, ::st]].astype(float)
    c = c[np.isfinite(c).all(axis=1)]
    planes = shelf_planes(scenario)
    corr, intr = np.eye(4), np.zeros(4)           # intr: focal scale x, y; principal-point shift x, y (per z)
    nx = 10 if params.intrinsics else 6
    before: dict[int, float] = {}
    for band in params.bands:
        rot = corr[:3, :3] @ T_base_camera[:3, :3]
        q = _to_base(c, intr, corr @ T_base_camera)
        idx, res = _assign(q, planes, band, params.edge_margin)
        used = [k for k in range(len(planes)) if np.sum(idx == k) * st * st >= params.min_points]
        if not before:
            before = {k: float(np.median(res[idx == k])) for k in used}
        sel = np.isin(idx, used)
        if not sel.any():
            break
        q, r, k, cs = q[sel], res[sel], idx[sel], c[sel]
        n = np.zeros((len(q), 3))
        n[np.arange(len(q)), [planes[i].axis for i in k]] = 1.0
        jac = np.c_[np.cross(q, n), n]             # d r / d (w, t)
        if params.intrinsics:
            nx0, ny0 = n @ rot[:, 0], n @ rot[:, 1]
            jac = np.c_[jac, nx0 * cs[:, 0], ny0 * cs[:, 1], nx0 * cs[:, 2], ny0 * cs[:, 2]]
        w = np.minimum(1.0, params.huber / np.maximum(np.abs(r), 1e-9))
        sw = np.sqrt(w)
        # a direction the visible planes do not constrain stays put (small ridge term)
        a = jac.T @ (jac * w[:, None]) + 1e-6 * len(q) * np.eye(nx)
        x = np.linalg.solve(a, -(jac * sw[:, None]).T @ (r * sw))
        step = np.eye(4)
        step[:3, :3] = rotvec_matrix(x[:3])
        step[:3, 3] = x[3:6]
        corr = step @ corr
        if params.intrinsics:
            intr = intr + x[6:]
    q = _to_base(c, intr, corr @ T_base_camera)
    idx, res = _assign(q, planes, params.bands[-1], params.edge_margin)
    stats = {planes[k].name: (int(np.sum(idx == k)), float(np.sqrt(np.mean(res[idx == k] ** 2))),
                              float(np.median(res[idx == k])), before.get(k, 0.0))
             for k in range(len(planes)) if np.sum(idx == k) * st * st >= params.min_points}
    on = idx >= 0
    noise, noise_1m = _spread(res[on]), _spread(res[on] / c[on, 2] ** 2)   # a depth camera's noise grows as z^2
    sh = scenario.shelf
    centre = np.array([(sh.x_front + sh.x_back) / 2, sh.y_center, (sh.bottom_z + sh.ceiling_z) / 2])
    return ShelfFit(corr, stats, tuple(pl.name for pl in planes if pl.name not in stats), noise, intr, centre,
                    noise_1m)


def _spread(r: np.ndarray) -> float:
    """The robust sigma of residuals r (1.4826 x their median absolute deviation); 0 without any."""
    return float(1.4826 * np.median(np.abs(r - np.median(r)))) if len(r) else 0.0


def _to_base(c: np.ndarray, intr: np.ndarray, T: np.ndarray) -> np.ndarray:
    """Camera points with the intrinsics correction (x (1 + kx) + px z, y (1 + ky) + py z, z), in the base frame."""
    q = np.c_[c[:, 0] * (1 + intr[0]) + intr[2] * c[:, 2], c[:, 1] * (1 + intr[1]) + intr[3] * c[:, 2], c[:, 2]]
    return q @ T[:3, :3].T + T[:3, 3]


def corrected_K(K: np.ndarray, intr: np.ndarray) -> np.ndarray:
    """The pinhole matrix whose back-projection is the corrected one of `_to_base` (fx / (1 + kx), cx - px fx')."""
    out = np.asarray(K, float).copy()
    out[0, 0], out[1, 1] = K[0, 0] / (1 + intr[0]), K[1, 1] / (1 + intr[1])
    out[0, 2], out[1, 2] = K[0, 2] - intr[2] * out[0, 0], K[1, 2] - intr[3] * out[1, 1]
    return out
