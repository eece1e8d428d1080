"""One RGB-D frame -> camera pose (marker, checked against the shelf) -> segmentation -> located bottles, checked;
and the debug image (no rclpy).

`Perception(scenario).process(rgb, depth, K)` raises ImageFormatError (bad images), MarkerNotFoundError (no
marker: without the common frame nothing can be placed; MarkerOccludedError when it is partly covered),
MarkerInconsistentError or InconsistentFrameError (a consistency check failed: docs/perception.md, "Consistency
checks"); a frame is never published wrong, it is refused with the reason. Bottles that are not visible enough,
or whose fit or identity is doubtful, are listed in `missing` with the reason, never guessed. Identity, weight,
radius and height of a located bottle come from its colour class through the scenario (`Perception.bottles`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import cv2
import numpy as np

from relocation_common.geometry import invert, mean_pose, pose_error
from relocation_common.scenario import Scenario, ShelfObject

from .aruco import (
    MarkerInconsistentError,
    MarkerLocalizer,
    MarkerNotFoundError,
    MarkerObservation,
    MarkerParams,
    fuse_markers,
)
from .localize import Detection, FitError, LocalizeParams, locate_bottle
from .segmentation import (
    Segmentation,
    SegmentationParams,
    backproject_image,
    check_images,
    deblur,
    on_marker_plates,
    on_plates,
    plate_levels,
    segment_points,
)
from .shelf import InconsistentFrameError, ShelfFit, ShelfParams, corrected_K, fit_shelf

BOARD_APART = 0.05  # m: base heights further apart than this are different boards (top and bottom shelf)
# a marker seen farther than this from where the largest one's frame and the scenario put it: one of them is not
# where the scenario says (the shelf fit corrects a shift along the shelf front poorly); the shelf decides which
MARKERS_AGREE_M = 0.03  # depth-refined poses; colour-only: twice the colour-only check
# markers that disagree: the shelf decides when it confirms one marker's own frame within this (the correction at the
# shelf's centre) and every other marker's frame needs SHELF_REJECTS times as much (docs/perception.md)
SHELF_CONFIRMS_M = 0.01   # a single correct marker's frame needs up to 5.3 mm (far, small marker 8)
SHELF_REJECTS = 3.0


class MarkersDisagreeError(MarkerInconsistentError):
    """Two markers seen where their scenario poses cannot both be; `seen`: the (localizer, observation) pairs."""

    def __init__(self, message: str, seen: list):
        super().__init__(message)
        self.seen = seen


@dataclass(frozen=True)
class PerceptionResult:
    """One processed frame. T_base_camera: the camera pose used (marker, corrected by the shelf fit); marker: the
    marker as seen (None when it was not, and the caller's `prior` pose stood in); notes: what the checks said."""

    marker: MarkerObservation | None
    detections: dict[str, Detection]
    missing: dict[str, str]                  # id -> why it was not located
    segmentation: Segmentation = field(repr=False)
    T_base_camera: np.ndarray = field(default_factory=lambda: np.eye(4), repr=False)
    shelf: ShelfFit | None = None
    notes: tuple[str, ...] = ()


class Perception:
    """The perception core of one scenario (module docstring)."""

    def __init__(self, scenario: Scenario, seg: SegmentationParams = SegmentationParams(),
                 loc: LocalizeParams = LocalizeParams(), refine_with_depth: bool = True,
                 shelf: ShelfParams = ShelfParams(), marker: MarkerParams = MarkerParams()):
        self.scenario, self.seg, self.loc, self.shelf = scenario, seg, loc, shelf
        self.localizers = [MarkerLocalizer(m, refine_with_depth=refine_with_depth, params=marker)
                           for m in scenario.markers]
        self.localizer = self.localizers[0]   # the scenario's first marker

    def process(self, rgb, depth, K, prior: np.ndarray | None = None) -> PerceptionResult:
        """Bottles of one registered RGB-D frame. `prior`: T_base_camera of earlier frames (the node's fused frame);
        when the marker is not seen now, the prior stands in if the shelf confirms it."""
        rgb, depth = check_images(rgb, depth)
        K = np.asarray(K, float).reshape(3, 3)
        notes: list[str] = []
        cam = backproject_image(depth, K, np.eye(4))
        try:
            marker, t0, seen = self._marker_frame(rgb, K, depth, prior, notes)
            levels = None if marker is None else plate_levels(rgb, marker.corners)
            plates = self._seen_plates(cam, seen)
            fit = self._fit_shelf(rgb, cam, t0, levels, plates)
            fit.check(self.shelf)
        except MarkersDisagreeError as e:
            marker, t0, fit, levels, plates = self._shelf_decides(e, rgb, cam, notes)
        T = fit.correction @ t0
        points = backproject_image(depth, corrected_K(K, fit.intrinsics), T)
        sharp = deblur(rgb, levels, self.seg)
        if sharp is not rgb and marker is not None:  # the plate's white and black as the sharpened image shows them
            levels = plate_levels(sharp, marker.corners)
        seg = segment_points(sharp, points, self.scenario, self.seg.for_frame(float(K[1, 1]), levels), levels, plates)
        # noisier depth: wider fit tolerances (the shelf's residual spread is the depth noise at the shelf); fewer
        # pixels: pixel counts scaled with the image area (the axis uncertainty check still bounds the fit)
        area = min(1.0, depth.size / (640 * 480))
        loc = replace(self.loc, inlier_tol=max(self.loc.inlier_tol, 2.5 * fit.noise),
                      max_rms=max(self.loc.max_rms, 1.5 * fit.noise), depth_noise=fit.noise,
                      min_pixels=max(12, round(self.loc.min_pixels * area)),
                      min_inliers=max(10, round(self.loc.min_inliers * area)))
        found, missing = self._locate_all(seg, T[:3, 3], loc)
        return PerceptionResult(marker, found, missing, seg, T, fit, tuple(notes))

    def _seen_plates(self, cam: np.ndarray, seen) -> np.ndarray:
        """HxW bool: pixels on the plates of the markers as seen (camera-frame points `cam`), never bottles: a
        plate the scenario puts centimetres off would otherwise pass the workspace gate as black and white."""
        h, w = cam.shape[:2]
        out = np.zeros((h, w), bool)
        for loc, obs in seen:
            c = obs.corners
            lo = np.floor(np.maximum(c.mean(0) - 1.2 * np.ptp(c, axis=0), 0)).astype(int)
            hi = np.ceil(np.minimum(c.mean(0) + 1.2 * np.ptp(c, axis=0), (w, h))).astype(int)
            out[lo[1]:hi[1], lo[0]:hi[0]] |= on_plates(cam[lo[1]:hi[1], lo[0]:hi[0]],
                                                       [(obs.T_camera_marker, loc.marker.size)],
                                                       self.seg.marker_margin)
        return out

    def _fit_shelf(self, rgb, cam: np.ndarray, t0: np.ndarray, levels, plates: np.ndarray) -> ShelfFit:
        """The shelf fit (`fit_shelf`) of the frame `t0`, bottles and the further markers' plates left out."""
        r0, p0 = t0[:3, :3].astype(np.float32), t0[:3, 3].astype(np.float32)
        st = self.shelf.stride   # the shelf fit uses every st-th pixel: classify only those to leave bottles out
        sampled = cam[::st, ::st] @ r0.T + p0
        first = segment_points(rgb[::st, ::st], sampled, self.scenario, replace(self.seg, erode_px=0, median_px=0),
                               levels, plates[::st, ::st])
        # out of the shelf fit: bottles and the further markers' plates (a far one at a low resolution pulled the
        # fit 20 cm off; the main marker's plate, 5 mm before the top board's front, has always been in it)
        not_shelf = np.zeros(cam.shape[:2], bool)
        not_shelf[::st, ::st] = (first.labels >= 0) | on_marker_plates(sampled, self.scenario.more_markers,
                                                                         self.seg.marker_margin)
        # a plane's pixel bound scaled with the image area (at 424x240 the side panels fell under it: nothing held
        # the frame along the shelf front, the bottles were 3-9 mm off)
        area = min(1.0, cam.shape[0] * cam.shape[1] / (640 * 480))
        return fit_shelf(cam, not_shelf, t0, self.scenario,
                         replace(self.shelf, min_points=max(100, round(self.shelf.min_points * area))))

    def _shelf_decides(self, err: MarkersDisagreeError, rgb, cam: np.ndarray, notes: list[str]):
        """Markers seen that disagree: each one's own frame is fitted to the shelf; the one the shelf confirms (its
        correction <= SHELF_CONFIRMS_M) while every other needs SHELF_REJECTS times as much and more than
        MARKERS_AGREE_M / 3 is taken, the others named in the notes ("run ./run calibrate"). Otherwise `err` (the
        shelf cannot tell, e.g. a marker moved along the shelf front): the frame is refused.
        Returns (marker, T_base_camera, shelf fit, colour levels, seen plates)."""
        plates = self._seen_plates(cam, err.seen)
        tried = []
        for loc, obs in err.seen:
            levels = plate_levels(rgb, obs.corners)
            tried.append((loc, obs, self._fit_shelf(rgb, cam, obs.T_base_camera, levels, plates), levels))
        tried.sort(key=lambda x: x[2].shift)
        loc, obs, fit, levels = tried[0]
        said = ", ".join(f"marker id {lo.marker.id}'s frame {f.shift * 1000:.0f} mm" for lo, _, f, _ in tried)
        if fit.shift > SHELF_CONFIRMS_M or any(f.shift < max(SHELF_REJECTS * fit.shift, MARKERS_AGREE_M / 3)
                                               for _, _, f, _ in tried[1:]):
            raise MarkerInconsistentError(f"{err}; the shelf cannot tell which ({said} from it)")
        try:
            fit.check(self.shelf)
        except InconsistentFrameError as e:
            raise MarkerInconsistentError(f"{err}; the shelf confirms none ({e})") from None
        others = ", ".join(str(lo.marker.id) for lo, _, _, _ in tried[1:])
        notes.append(f"{err}: the shelf confirms marker id {loc.marker.id} ({said} from it): marker id(s) {others} "
                     "not used, their scenario pose is off: run ./run calibrate")
        return obs, obs.T_base_camera, fit, levels, plates

    def _marker_frame(self, rgb, K, depth, prior, notes: list[str]) -> tuple[MarkerObservation | None, np.ndarray,
                                                                              list]:
        """(the marker seen largest in the image, T_base_camera, the (localizer, observation) pairs seen): the
        markers seen fused (`fuse_markers`; a covered or inconsistent one is left out, its reason in `notes`;
        markers that disagree raise MarkersDisagreeError, `_shelf_decides`); none seen: the prior if given and no
        marker was inconsistent, else the marker's error (all markers' reasons)."""
        seen, errors, found = [], [], {}
        for loc in self.localizers:
            expected = None if prior is None else invert(prior) @ loc.T_base_marker
            if loc.marker.dictionary not in found:  # one detector pass per dictionary
                found[loc.marker.dictionary] = loc.detect_all(rgb)
            try:
                seen.append((loc, loc.locate(rgb, K, depth, expected, found[loc.marker.dictionary])))
            except (MarkerNotFoundError, MarkerInconsistentError) as e:
                errors.append(e)
        if seen:
            notes.extend(f"{e}; the frame from the other markers" for e in errors)
            seen.sort(key=lambda lo: -cv2.contourArea(lo[1].corners.astype(np.float32)))  # largest in the image first
            best = seen[0][1].T_base_camera
            for loc, obs in seen[1:]:
                # where the largest marker's frame puts this marker's centre vs the scenario: positions, not camera
                # poses (a small far marker's own orientation is poor under depth noise; its position is not)
                dt = float(np.linalg.norm(best[:3, :3] @ obs.T_camera_marker[:3, 3] + best[:3, 3]
                                          - loc.T_base_marker[:3, 3]))
                p = loc.params  # colour-only poses (no depth on a marker) agree only as well as the colour check
                bound = MARKERS_AGREE_M if obs.refined and seen[0][1].refined else \
                    2e-3 * p.max_disagreement_mm * max(1.0, 433.0 / K[0, 0])
                if dt > bound:
                    raise MarkersDisagreeError(
                        f"marker id {loc.marker.id} is seen {dt * 1000:.0f} mm from where marker id "
                        f"{seen[0][0].marker.id} and the scenario put it (bound {bound * 1000:.0f} mm): check the "
                        "scenario's marker poses (one was moved?)", seen)
            if len(seen) == 1:
                return seen[0][1], best, seen
            T, rms = fuse_markers(seen)
            notes.append(f"markers {', '.join(str(loc.marker.id) for loc, _ in seen)} fused (corners {rms * 1000:.1f} "
                         "mm rms off their scenario poses; the shelf fit checks the frame)")
            return seen[0][1], T, seen
        if prior is not None and all(isinstance(e, MarkerNotFoundError) for e in errors):
            notes.append(f"{'; '.join(map(str, errors))}; using the fused frame of earlier frames")
            return None, np.asarray(prior, float), []
        if len(errors) == 1:
            raise errors[0]
        raise type(errors[0])("; ".join(map(str, errors)))

    def _locate_all(self, seg: Segmentation, cam: np.ndarray,
                    loc: LocalizeParams) -> tuple[dict[str, Detection], dict[str, str]]:
        """Fit every bottle; then drop fits outside the shelf and pairs of fits on one board that overlap (an identity
        in doubt: two colours on one bottle, or one colour on two), with the reason."""
        found, missing = {}, {}
        v, u = np.nonzero(seg.labels >= 0)
        lab = seg.labels[v, u]
        h, w = seg.labels.shape
        for k, b in enumerate(self.scenario.objects):
            sel = lab == k
            try:
                if not sel.any():
                    raise FitError(f"0 pixels of colour {b.label!r} (need {loc.min_pixels})")
                r0, r1 = max(int(v[sel].min()) - 4, 0), min(int(v[sel].max()) + 5, h)
                c0, c1 = max(int(u[sel].min()) - 4, 0), min(int(u[sel].max()) + 5, w)
                found[b.id] = locate_bottle(b, seg.labels[r0:r1, c0:c1] == k, seg.points[r0:r1, c0:c1],
                                            self.scenario, cam, loc, offset=(r0, c0))
            except FitError as e:
                missing[b.id] = str(e)
        sh, tol = self.scenario.shelf, loc.inlier_tol
        for i, d in list(found.items()):
            r = self.scenario.object(i).radius
            if not (sh.x_front + r - tol <= d.x <= sh.x_back - r + tol and sh.y_min + r - tol <= d.y <= sh.y_max - r
                    + tol):
                missing[i] = f"fit at ({d.x:.3f}, {d.y:.3f}) is not inside the shelf: not this bottle"
                del found[i]
        for i, d in list(found.items()):  # a second bottle-like blob of i's colour not at another located bottle
            if d.elsewhere is not None and not any(
                    j != i and math.hypot(d.elsewhere[0] - e.x, d.elsewhere[1] - e.y) < self.scenario.object(j).radius
                    for j, e in found.items()):
                missing[i] = f"colour {self.scenario.object(i).label!r} seen at two places: identity of {i} in doubt"
                del found[i]
        ids = list(found)
        for a, i in enumerate(ids):
            for j in ids[a + 1:]:
                di, dj = found.get(i), found.get(j)
                if di is None or dj is None or abs(di.z - dj.z) > BOARD_APART:
                    continue  # on different boards (one relocated to the bottom shelf): above each other, not one
                gap = math.hypot(di.x - dj.x, di.y - dj.y) - self.scenario.object(i).radius - \
                    self.scenario.object(j).radius
                if gap < -2 * tol:
                    why = f"overlaps {{}} by {-gap * 1000:.0f} mm: identity in doubt (colours of {i} and {j})"
                    missing[i], missing[j] = why.format(j), why.format(i)
                    del found[i], found[j]
        return found, missing

    def bottles(self, detections) -> list[ShelfObject]:
        """Scenario bottles moved to their perceived (x, y) on the board at their perceived base height: id, label,
        weight, size from the colour class."""
        return [replace(self.scenario.object(d.id), x=d.x, y=d.y, support_z=d.z) for d in detections]

    def annotate(self, rgb: np.ndarray, result: PerceptionResult | None, K=None, note: str = "") -> np.ndarray:
        """Debug image (RGB): marker outline and axes, each located bottle's id at its pixel, missing ids."""
        img = np.ascontiguousarray(rgb).copy()
        if result is not None and result.marker is not None:
            c = np.round(result.marker.corners).astype(np.int32)
            cv2.polylines(img, [c], True, (0, 255, 0), 2)
            T = result.marker.T_camera_marker
            if K is not None:
                cv2.drawFrameAxes(img, np.asarray(K, float).reshape(3, 3), None, cv2.Rodrigues(T[:3, :3])[0], T[:3, 3],
                                  self.scenario.marker.size)
        if result is not None:
            for d in result.detections.values():
                b = self.scenario.object(d.id)
                cv2.circle(img, d.pixel, 4, (255, 255, 255), -1)
                cv2.putText(img, f"{d.id} {b.label}", (d.pixel[0] - 20, d.pixel[1] - 8), cv2.FONT_HERSHEY_SIMPLEX,
                            0.4, (255, 255, 255), 1, cv2.LINE_AA)
            if result.missing:
                note = (note + " " if note else "") + "missing: " + ", ".join(result.missing)
        if note:
            cv2.putText(img, note[:90], (5, img.shape[0] - 8), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (255, 64, 64), 1,
                        cv2.LINE_AA)
        return img


@dataclass
class SceneMemory:
    """The hidden-object policy (docs/perception.md): an object not seen in the current frame keeps its last
    perceived pose for `hold_frames` processed frames, then is dropped; nothing is ever guessed."""

    ids: tuple[str, ...]
    hold_frames: int
    frame: int = 0
    last_seen: dict = field(default_factory=dict)   # id -> (Detection, frame index)

    def update(self, detections: dict[str, Detection]) -> tuple[list[Detection], list[str], list[str]]:
        """Record one processed frame; returns (detections to publish in scenario order, held ids, lost ids)."""
        self.frame += 1
        for d in detections.values():
            self.last_seen[d.id] = (d, self.frame)
        keep = {i: (d, f) for i, (d, f) in self.last_seen.items() if self.frame - f <= self.hold_frames}
        held = [i for i in self.ids if i in keep and keep[i][1] != self.frame]
        lost = [i for i in self.ids if i not in keep]
        return [keep[i][0] for i in self.ids if i in keep], held, lost


class FrameFusion:
    """The shelf does not move: the camera poses of consistent frames are averaged (translation mean, rotation the
    projection of the mean matrix onto SO(3)); a frame more than `max_jump` / `max_jump_deg` from the fused pose is
    refused, unless `reset_after` such frames in a row agree with one another (the camera was moved: start over)."""

    def __init__(self, max_jump: float = 0.005, max_jump_deg: float = 0.5, window: int = 30, reset_after: int = 3):
        self.max_jump, self.max_jump_deg, self.window, self.reset_after = max_jump, max_jump_deg, window, reset_after
        self.poses: list[np.ndarray] = []
        self.outliers: list[np.ndarray] = []

    @property
    def fused(self) -> np.ndarray | None:
        """T_base_camera averaged over the consistent frames, or None before the first."""
        if not self.poses:
            return None
        return mean_pose(self.poses)

    def update(self, T: np.ndarray) -> str | None:
        """Add one frame's pose; None when it agrees (or restarts the fusion), else the reason to refuse it."""
        f = self.fused
        if f is None or self._agrees(T, f):
            self.poses = (self.poses + [np.asarray(T, float)])[-self.window:]
            self.outliers = []
            return None
        self.outliers.append(np.asarray(T, float))
        if len(self.outliers) >= self.reset_after and all(self._agrees(o, self.outliers[-1]) for o in self.outliers):
            self.poses, self.outliers = self.outliers, []
            return None
        dt, dr = pose_error(T, f)
        return (f"camera pose {dt * 1000:.0f} mm / {math.degrees(dr):.1f} deg from the pose fused over "
                f"{len(self.poses)} frames (bounds {self.max_jump * 1000:.0f} mm / {self.max_jump_deg} deg): refused "
                f"until {self.reset_after} frames agree")

    def _agrees(self, a: np.ndarray, b: np.ndarray) -> bool:
        dt, dr = pose_error(a, b)
        return dt <= self.max_jump and math.degrees(dr) <= self.max_jump_deg


def identity_conflicts(detections: dict[str, Detection], previous: dict[str, Detection], scenario: Scenario,
                       moved: float = 0.02) -> dict[str, str]:
    """Detections that take the place of another bottle of the previous scene (overlapping where it stood) while
    that one is not seen now and this one stood elsewhere (> `moved` away): an identity swap is likelier than a
    bottle teleported onto another's place. id -> reason."""
    out = {}
    for i, d in detections.items():
        for j, p in previous.items():
            if j == i or j in detections:
                continue
            gap = math.hypot(d.x - p.x, d.y - p.y) - scenario.object(i).radius - scenario.object(j).radius
            was = previous.get(i)
            if gap < -0.01 and (was is None or math.hypot(d.x - was.x, d.y - was.y) > moved):
                out[i] = f"found where {j} stood in the previous scene, and {j} is not seen: identity in doubt"
    return out
