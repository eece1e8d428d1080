"""A cluster's shape: the primitive that fits its points best (docs/perception.md, "Objects").

The camera sees one side of an object, and every fit uses only what it sees:
- standing cylinder: a circle in x-y with its radius fitted (bounded), through the side points and the cap's rim
  (`localize.circle_points`: the far side is hidden, the visible arc suffices), and through those clear of the top
  face under the depth noise at the cluster's depth (`noise.cap_below`), kept when CLEAR_MARGIN times better;
  height = top - support;
- lying cylinder (axis horizontal, resting on the board): the axis direction is the principal direction of the
  points in x-y; in the cross-section the circle's centre is one radius above the board, radius and offset fitted;
  length = the points' extent along the axis;
- box: started at cv2.minAreaRect of the points in x-y (the top face shows the whole footprint from above; the side
  faces seen, 1 to 3, lie on its edges), refitted on the faces the side points show (their median: the hull's
  rectangle lies a few noise sigma outside every face under depth noise), a face not seen at the other points'
  extent; height = top - support.
Each fit's quality is the rms distance of the cluster's points to the primitive's surface (the faces a camera can
see; a standing cylinder's top face at `noise.top_face`); the smallest rms within `fit_rms` (or `fit_noise` x the
depth noise measured on the shelf's planes) and within the size bounds wins. None fits: a conservative box, the
visible points' bounding box in x-y reaching `hidden_extent` behind them.
`top_seen`: the top face is in view (cap points well inside the circle or the box's top face), else the height is
only a lower bound (something nearer hides the top); `ends_seen`: a lying cylinder's end caps in view. A lying
cylinder is longer than wide (else it is a standing one).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import cv2
import numpy as np

from ..localize import FitError, fit_circle
from .model import BOX, CYLINDER
from .params import ObjectParams

RMS_SAMPLE = 3000  # points a fit's rms is evaluated on (a fixed-step subsample of larger clusters)
SEARCH_SAMPLE = 400  # points the lying cylinder's axis search fits (the best direction is refitted on all)
CAP_BAND = 0.006  # m below the top: the cap (top face) of a standing object
LYING_MARGIN = 1.5  # a lying cylinder wins over a standing one or a box only with this times their rms
CLEAR_MARGIN = 1.5  # the circle of the points clear of the top face (fewer) wins only with this times a lower rms
MIN_TOP_POINTS = 5  # cap points well inside the footprint that show the top face is in view
BOX_ROUNDS = 2  # the box's faces refitted on the points nearest each (_refit_box)
MIN_FACE_POINTS = 10  # side points that show a face of the box
MIN_FACE_FRACTION = 0.1  # of the side points: fewer on a face, it is not seen (placed by the top face's extent)
REFIT_SAMPLE = 400  # points the box's faces are refitted on (a fixed-step subsample; its rms on RMS_SAMPLE)


@dataclass(frozen=True)
class Primitive:
    """A fitted shape (the fields as PerceivedObject's); why: for a conservative box, why no primitive fitted."""

    shape: str
    lying: bool
    x: float
    y: float
    radius: float
    height: float
    size: tuple[float, float, float]
    yaw: float
    rms: float
    conservative: bool
    why: str
    top_seen: bool
    ends_seen: tuple[bool, bool]  # a lying cylinder's end caps in view, at -/+ height / 2 along yaw


def _sample(points: np.ndarray) -> np.ndarray:
    step = max(1, len(points) // RMS_SAMPLE)
    return points[::step]


def _standing_rms(p: np.ndarray, centre: np.ndarray, r: float, face: float) -> float:
    """The rms distance of points p to a standing cylinder's side (circle centre, r) and its top face at `face`."""
    rho = np.linalg.norm(p[:, :2] - centre, axis=1)
    d = np.minimum(np.abs(rho - r), np.abs(p[:, 2] - face) + np.maximum(rho - r, 0.0))
    return float(np.sqrt(np.mean(d ** 2)))


def standing_cylinder(xy: np.ndarray, clear: np.ndarray, points: np.ndarray, support: float, top: float,
                      face: float, camera: np.ndarray, params: ObjectParams, tol: float) -> Primitive:
    """The standing cylinder through the circle points `xy` (side and rim); FitError when they fit no circle. Also
    the circle through the points `clear` of the top face (noise.cap_below: under depth noise the cap's points reach
    below its margin, inside the circle, and pull the radius down), started at the first; it wins with a CLEAR_MARGIN
    times lower rms. The rms: to the side and to the top face at height `face` (noise.top_face)."""
    p = _sample(points)
    centre, r, _ = fit_circle(xy, camera, (params.radius_min, params.radius_max), tol)
    best = (_standing_rms(p, centre, r, face), centre, r)
    if not clear.all():
        try:   # started at the circle of all (the clear points are most of them)
            centre, r, _ = fit_circle(xy[clear], camera, (params.radius_min, params.radius_max), tol, start=(centre, r))
            rms = _standing_rms(p, centre, r, face)
            if rms * CLEAR_MARGIN < best[0]:
                best = (rms, centre, r)
        except FitError:
            pass
    rms, centre, r = best
    h = top - support
    cap_xy = points[points[:, 2] >= top - CAP_BAND, :2]
    seen = int(np.sum(np.linalg.norm(cap_xy - centre, axis=1) < 0.6 * r)) >= MIN_TOP_POINTS
    return Primitive(CYLINDER, False, float(centre[0]), float(centre[1]), r, h, (2 * r, 2 * r, h), 0.0,
                     rms, False, "", seen, (False, False))


def _cross_section(t: np.ndarray, s: np.ndarray, z: np.ndarray, sc: float, r: float,
                   iterations: int) -> tuple[float, float, float]:
    """Gauss-Newton on (s_c, r) of the circle through (s, z) whose centre is one radius above the board, refitted
    twice on the points within CAP_BAND of the circle (an end cap's points lie inside it): (s_c, r, rms of the side
    and end-cap distances)."""
    su, zu = s, z
    for _ in range(3):
        for _ in range(iterations):
            ds, dz = su - sc, zu - r
            rho = np.maximum(np.hypot(ds, dz), 1e-9)
            ja, jb, res = -ds / rho, -dz / rho - 1.0, rho - r   # normal equations of the 2-parameter step
            aa, ab, bb = float(ja @ ja), float(ja @ jb), float(jb @ jb)
            det = aa * bb - ab * ab
            if det <= 1e-18:
                break
            ga, gb = -float(ja @ res), -float(jb @ res)
            step = ((bb * ga - ab * gb) / det, (aa * gb - ab * ga) / det)
            sc, r = sc + step[0], r + step[1]
            if math.hypot(*step) < 1e-7:
                break
        use = np.abs(np.hypot(s - sc, z - r) - r) < CAP_BAND
        if use.sum() < 10:
            break
        su, zu = s[use], z[use]
    lo, hi = np.percentile(t, [0.5, 99.5])
    rho = np.hypot(s - sc, z - r)
    d = np.minimum(np.abs(rho - r), np.abs(np.abs(t - (lo + hi) / 2) - (hi - lo) / 2) + np.maximum(rho - r, 0.0))
    return sc, r, float(np.sqrt(np.mean(d ** 2)))


def _search_rms(t: np.ndarray, s: np.ndarray, z: np.ndarray, sc: np.ndarray, r: np.ndarray,
                iterations: int) -> np.ndarray:
    """_cross_section's rms for many axis directions at once (row k of t, s: the points' coordinates along and
    across direction k; sc, r: the starts): the same Gauss-Newton steps and refits on the points near the circle,
    each row frozen where _cross_section stops it (steps under 1e-7, a singular step, fewer than 10 points near)."""
    use = np.ones(s.shape, bool)
    live = np.ones(len(s), bool)   # rows still refitting (_cross_section's outer loop not left)
    for _ in range(3):
        going = live.copy()        # rows still iterating in this Gauss-Newton loop
        for _ in range(iterations):
            if not going.any():
                break
            ds, dz = s - sc[:, None], z - r[:, None]
            rho = np.maximum(np.hypot(ds, dz), 1e-9)
            ja, jb, res = (-ds / rho) * use, (-dz / rho - 1.0) * use, (rho - r[:, None]) * use
            aa, ab, bb = np.sum(ja * ja, 1), np.sum(ja * jb, 1), np.sum(jb * jb, 1)
            det = aa * bb - ab * ab
            going &= ~(det <= 1e-18)
            ga, gb = -np.sum(ja * res, 1), -np.sum(jb * res, 1)
            with np.errstate(divide="ignore", invalid="ignore"):
                step_s, step_r = (bb * ga - ab * gb) / det, (aa * gb - ab * ga) / det
            sc, r = np.where(going, sc + step_s, sc), np.where(going, r + step_r, r)
            going &= ~(np.hypot(step_s, step_r) < 1e-7)
        near = np.abs(np.hypot(s - sc[:, None], z - r[:, None]) - r[:, None]) < CAP_BAND
        live &= near.sum(axis=1) >= 10
        use = np.where(live[:, None], near, use)
    lo, hi = np.percentile(t, [0.5, 99.5], axis=1)
    rho = np.hypot(s - sc[:, None], z - r[:, None])
    d = np.minimum(np.abs(rho - r[:, None]), np.abs(np.abs(t - ((lo + hi) / 2)[:, None]) - ((hi - lo) / 2)[:, None])
                   + np.maximum(rho - r[:, None], 0.0))
    return np.sqrt(np.mean(d ** 2, axis=1))


@dataclass(frozen=True)
class LyingStart:
    """The lying cylinder's fit on the points' principal direction (`lying_start`), shared by the fit and its axis
    search: the sampled points (x-y, z above the board), their mean, the start radius, the axis and its fit."""

    xy: np.ndarray
    z: np.ndarray
    mean: np.ndarray
    r0: float
    axis: np.ndarray
    fit: tuple[float, float, float]   # (s_c, r, rms) of _cross_section


def _section_start(xy: np.ndarray, mean: np.ndarray, normals: np.ndarray, r0: float,
                   view: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(s, s_c start) for each row of normals: the points across the axis; the circle's centre one radius behind
    their median, seen from `view`."""
    s = normals @ (xy - mean).T
    side = normals @ view[:2]
    return s, np.median(s, axis=1) + r0 * np.where(side == 0, 1.0, np.copysign(1.0, side))


def lying_start(points: np.ndarray, support: float, view: np.ndarray, params: ObjectParams) -> LyingStart:
    """The cross-section fit (_cross_section, 15 iterations) on the points' principal direction in x-y."""
    p = _sample(points)
    xy, z = p[:, :2], p[:, 2] - support
    mean = xy.mean(axis=0)
    r0 = max(float(np.percentile(z, 99)) / 2, params.radius_min)
    axis = np.linalg.eigh(np.cov((xy - mean).T))[1][:, 1]
    normal = np.array([-axis[1], axis[0]])
    s = (xy - mean) @ normal
    sc0 = float(np.median(s)) + r0 * math.copysign(1.0, float(normal @ view[:2]) or 1.0)
    return LyingStart(xy, z, mean, r0, axis, _cross_section((xy - mean) @ axis, s, z, sc0, r0, 15))


def lying_cylinder(points: np.ndarray, support: float, view: np.ndarray, params: ObjectParams,
                   bound: float | None, start: LyingStart | None = None) -> Primitive:
    """A cylinder lying on the board (module docstring); FitError when its radius or length is out of bounds. The
    axis: the points' principal direction in x-y (`start`: that fit, lying_start, when already made); when that fit
    is not within `bound` (an end cap seen more than the side), the best of the directions 10 deg apart, compared on
    a subsample (bound None: no search)."""
    st = start if start is not None else lying_start(points, support, view, params)
    xy, z, mean, axis = st.xy, st.z, st.mean, st.axis
    sc, r, rms = st.fit
    if bound is not None and rms > bound:
        step = max(1, len(xy) // SEARCH_SAMPLE)
        dirs = np.array([[math.cos(a), math.sin(a)] for a in np.radians(np.arange(0, 180, 10))])
        s, sc0 = _section_start(xy[::step], mean, np.c_[-dirs[:, 1], dirs[:, 0]], st.r0, view)
        rms_k = _search_rms(dirs @ (xy[::step] - mean).T, s, z[::step], sc0, np.full(len(dirs), st.r0), 6)
        axis = dirs[int(np.argmin(rms_k))]
        normal = np.array([-axis[1], axis[0]])
        s1 = (xy - mean) @ normal
        sc1 = float(np.median(s1)) + st.r0 * math.copysign(1.0, float(normal @ view[:2]) or 1.0)
        sc, r, rms = _cross_section((xy - mean) @ axis, s1, z, sc1, st.r0, 15)
    normal = np.array([-axis[1], axis[0]])
    t = (xy - mean) @ axis
    lo, hi = np.percentile(t, [0.5, 99.5])
    length = float(hi - lo)
    if not params.radius_min <= r <= params.radius_max or not max(params.size_min, 2 * r) <= length <= \
            params.size_max:
        raise FitError(f"lying cylinder radius {r * 1000:.0f} mm, length {length * 1000:.0f} mm out of bounds")
    centre = mean + axis * (lo + hi) / 2 + normal * sc
    inside = np.hypot((xy - mean) @ normal - sc, z - r) < r - CAP_BAND   # end-cap points lie inside the circle
    ends = (int(np.sum(inside & (t < lo + CAP_BAND))) >= MIN_TOP_POINTS,
            int(np.sum(inside & (t > hi - CAP_BAND))) >= MIN_TOP_POINTS)
    return Primitive(CYLINDER, True, float(centre[0]), float(centre[1]), r, length, (2 * r, 2 * r, length),
                     math.atan2(axis[1], axis[0]), rms, False, "", True, ends)


def _box_frame(xy: np.ndarray, centre: np.ndarray, yaw: float) -> np.ndarray:
    """The points' coordinates (N x 2) in the frame of a box at `centre` turned by `yaw`."""
    c, s = math.cos(yaw), math.sin(yaw)
    return (xy - centre) @ np.array([[c, -s], [s, c]])


def _box_distances(xy: np.ndarray, z: np.ndarray, centre: np.ndarray, yaw: float, a: float, b: float, top: float,
                   camera: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(the points' coordinates in the box's frame (N x 2), their distances to the faces the camera sees: the top
    face and the side faces turned to it; a point outside the footprint as far from the side faces as from the
    footprint's outline, from the top face that far more than its height from it)."""
    c, s = math.cos(yaw), math.sin(yaw)
    rot = np.array([[c, -s], [s, c]])
    loc = _box_frame(xy, centre, yaw)
    half = np.array([a / 2, b / 2])
    gap = np.abs(loc) - half   # > 0: outside that pair of faces
    out = np.hypot(np.maximum(gap[:, 0], 0.0), np.maximum(gap[:, 1], 0.0))
    cam = (camera[:2] - centre) @ rot   # the camera in the box's frame: a side face is seen when it lies beyond it
    seen = [(k, sg) for k in (0, 1) for sg in (-1.0, 1.0) if sg * cam[k] > half[k]]
    side = np.min([np.abs(half[k] - sg * loc[:, k]) for k, sg in seen], axis=0) if seen else np.full(len(xy), np.inf)
    return loc, np.minimum(np.where(out > 0, out, side), np.abs(top - z) + out)


def _face_yaw(xy: np.ndarray, faces: list[np.ndarray], yaw: float) -> float:
    """The box's yaw from the side faces seen (each face's points' principal direction, from their second moments,
    weighted by their number, averaged modulo a quarter turn); `yaw` when no face has MIN_FACE_POINTS."""
    sx = sy = 0.0
    for m in faces:
        n = int(np.count_nonzero(m))
        if n >= MIN_FACE_POINTS:
            q = xy[m]
            q = q - q.mean(axis=0)
            sxx, syy, sxy = float(q[:, 0] @ q[:, 0]), float(q[:, 1] @ q[:, 1]), float(q[:, 0] @ q[:, 1])
            a4 = 2 * math.atan2(2 * sxy, sxx - syy)   # 4 x the principal direction's angle
            sx, sy = sx + n * math.cos(a4), sy + n * math.sin(a4)
    if sx == sy == 0.0:
        return yaw
    turn = math.atan2(sy, sx) / 4 - yaw
    return yaw + (turn + math.pi / 4) % (math.pi / 2) - math.pi / 4   # the nearest of the quarter-turn copies


def _face_end(q: np.ndarray, outer: bool, flat: float) -> float:
    """Where a face goes through its points' coordinates q across it: their median when flat (rms about it within
    `flat`), else their outermost (0.5th / 99.5th percentile; `outer`: the upper one)."""
    q = np.sort(q)
    mid = float(q[len(q) // 2])
    if flat > 0 and float(np.sqrt(np.mean((q - mid) ** 2))) <= flat:
        return mid
    return float(q[min(len(q) - 1, int(0.995 * len(q)))] if outer else q[int(0.005 * len(q))])


def _refit_box(xy: np.ndarray, side: np.ndarray, centre: np.ndarray, yaw: float, a: float, b: float,
               flat: float) -> tuple[np.ndarray, float, float, float]:
    """One refit of the box (centre, yaw, a, b): each side point to its nearest face; the yaw from the faces seen
    (_face_yaw); a face seen (MIN_FACE_FRACTION of the side points) and flat (its points' rms about their median
    within `flat`) where their median puts it, one seen but not flat (a curved surface: a cylinder's) at its points'
    outermost (0.5th / 99.5th percentile, as the hull's rectangle), a face not seen at that percentile of the points
    not on the face opposite it (the top face and the seen faces reaching it)."""
    loc = _box_frame(xy, centre, yaw)
    k = np.argmin(np.abs((a / 2, b / 2) - np.abs(loc)), axis=1)   # 0: a face across u (u = +-a/2), 1: across v
    neg = loc[np.arange(len(loc)), k] < 0
    faces = [side & (k == i) & (neg == n) for i in (0, 1) for n in (True, False)]
    turn = _face_yaw(xy, faces, yaw) - yaw
    yaw, c, s = yaw + turn, math.cos(turn), math.sin(turn)
    loc = loc @ np.array([[c, -s], [s, c]])   # the same points in the box's frame turned by `turn`
    least = max(MIN_FACE_POINTS, MIN_FACE_FRACTION * int(np.count_nonzero(side)))
    ends = [_face_end(loc[m, f // 2], f % 2 == 1, flat) if np.count_nonzero(m) >= least else
            _face_end(loc[~faces[f ^ 1], f // 2], f % 2 == 1, 0.0) for f, m in enumerate(faces)]
    mid = np.array([(ends[0] + ends[1]) / 2, (ends[2] + ends[3]) / 2])
    c, s = math.cos(yaw), math.sin(yaw)
    return centre + np.array([[c, -s], [s, c]]) @ mid, yaw, ends[1] - ends[0], ends[3] - ends[2]


def box(points: np.ndarray, support: float, top: float, camera: np.ndarray, params: ObjectParams,
        flat: float) -> Primitive:
    """The oriented box of the points (module docstring): started at cv2.minAreaRect of their footprint, refitted
    BOX_ROUNDS times on the faces the points show (_refit_box: under depth noise the hull's rectangle lies a few
    noise sigma outside every face; a face is flat when its points' rms about their median is within `flat`:
    `fit_noise` x the depth noise, what the noise spreads a flat face's points by); its rms to the top face at height
    `face` (top_face); FitError when a side is out of bounds."""
    p = _sample(points)
    xy, z = p[:, :2], p[:, 2]
    (cx, cy), (a, b), angle = cv2.minAreaRect(xy.astype(np.float32))
    centre, yaw = np.array([cx, cy], float), math.radians(angle)
    step = max(1, len(p) // REFIT_SAMPLE)
    side = z[::step] < top - CAP_BAND
    for _ in range(BOX_ROUNDS):
        centre, yaw, a, b = _refit_box(xy[::step], side, centre, yaw, a, b, flat)
    h = top - support
    if min(a, b, h) < params.size_min or max(a, b, h) > params.size_max:
        raise FitError(f"box {a * 1000:.0f} x {b * 1000:.0f} x {h * 1000:.0f} mm out of bounds")
    loc, d = _box_distances(xy, z, centre, yaw, a, b, top, camera)
    inner = 0.25 * min(a, b)
    cap = (z >= top - CAP_BAND) & (np.abs(loc[:, 0]) < a / 2 - inner) & (np.abs(loc[:, 1]) < b / 2 - inner)
    return Primitive(BOX, False, float(centre[0]), float(centre[1]), 0.0, h, (float(a), float(b), h), yaw,
                     float(np.sqrt(np.mean(d ** 2))), False, "", int(cap.sum()) >= MIN_TOP_POINTS, (False, False))


def conservative_box(points: np.ndarray, support: float, top: float, view: np.ndarray, params: ObjectParams,
                     why: str) -> Primitive:
    """The points' oriented bounding box in x-y, grown `hidden_extent` away from the camera (what it cannot see),
    from the board to the top: an obstacle that bounds the cluster."""
    ray = view[:2] / max(float(np.linalg.norm(view[:2])), 1e-9)
    xy = points[:, :2]
    (cx, cy), (a, b), angle = cv2.minAreaRect(np.r_[xy, xy + params.hidden_extent * ray].astype(np.float32))
    a, b = max(a, params.size_min), max(b, params.size_min)
    h = max(top - support, params.size_min)
    return Primitive(BOX, False, float(cx), float(cy), 0.0, h, (float(a), float(b), h), math.radians(angle), 0.0,
                     True, why, False, (False, False))


def lying_rms_floor(points: np.ndarray, support: float, params: ObjectParams) -> float:
    """A lower bound of every lying cylinder fit's rms (any axis, radius within its bounds): its surface lies at
    most 2 radius_max above the board, and a point higher than that by dz is at least dz from it (_cross_section's
    distances, on the same sampled points): a cluster taller than any lying cylinder."""
    z = _sample(points)[:, 2] - support
    return float(np.sqrt(np.mean(np.maximum(z - 2 * params.radius_max, 0.0) ** 2)))


def _attempt(fit: Callable[[], Primitive], bound: float) -> Primitive | str:
    """The fitted primitive when its rms is within bound, else why not."""
    try:
        f = fit()
    except (FitError, np.linalg.LinAlgError, ValueError) as e:
        return str(e)
    return f if f.rms <= bound else f"rms {f.rms * 1000:.1f} mm"


def fit_primitive(points: np.ndarray, circle_xy: np.ndarray, clear: np.ndarray, top: float, face: float,
                  support: float, camera: np.ndarray, params: ObjectParams, noise: float, tol: float,
                  search: bool = True) -> Primitive:
    """The best primitive of a cluster (module docstring). points: its base-frame points; circle_xy: its side and
    rim points for the standing cylinder, `clear` the ones clear of its top face; top: the points' 99.5th height
    percentile; face: the top face's height (noise.top_face); camera: the camera's position;
    noise: the frame's depth noise; tol: the circle fit's inlier band. The lying cylinder is not fitted where it
    cannot win (its rms floor, lying_rms_floor, LYING_MARGIN times over a standing cylinder's or box's rms within
    the bound); its search over axis directions runs only when no primitive fits otherwise and `search` (it costs
    as much as all other fits)."""
    view = points.mean(axis=0) - camera
    bound = max(params.fit_rms, params.fit_noise * noise)
    made: list[LyingStart] = []

    def lying() -> LyingStart:
        """The lying cylinder's principal-direction fit, made once for both lying fits."""
        if not made:
            made.append(lying_start(points, support, view, params))
        return made[0]
    attempts: dict[str, Callable[[], Primitive]] = {
        "standing cylinder": lambda: standing_cylinder(circle_xy, clear, points, support, top, face, camera, params,
                                                       tol),
        "lying cylinder": lambda: lying_cylinder(points, support, view, params, None, lying()),
        "box": lambda: box(points, support, top, camera, params, params.fit_noise * noise),
        "lying cylinder, axis searched": lambda: lying_cylinder(points, support, view, params, bound, lying())}
    got = {name: _attempt(attempts[name], bound) for name in ("standing cylinder", "box")}
    others = [f.rms for f in got.values() if isinstance(f, Primitive)]
    if not others or lying_rms_floor(points, support, params) * LYING_MARGIN <= min(others) + 1e-9:  # 1e-9: rounding
        got["lying cylinder"] = _attempt(attempts["lying cylinder"], bound)
    if search and not any(isinstance(f, Primitive) for f in got.values()):   # the search: only when nothing fitted
        got["lying cylinder, axis searched"] = _attempt(attempts["lying cylinder, axis searched"], bound)
    fits = [f for name in attempts if isinstance(f := got.get(name), Primitive)]
    if fits:  # a lying fit must be LYING_MARGIN times better: a narrow standing bottle seen in part fits both
        return min(fits, key=lambda f: f.rms * (LYING_MARGIN if f.lying else 1.0))
    why = {name: got[name] for name in attempts if name in got}   # every one a reason here
    return conservative_box(points, support, top, view, params, f"no primitive within {bound * 1000:.1f} mm rms ("
                            + "; ".join(f"{k}: {v}" for k, v in why.items()) + ")")
