"""One RGB-D frame -> camera pose (marker, checked against the shelf) -> the objects on the shelf, each fitted with a
primitive and named (no rclpy). docs/perception.md.

`Perception(scenario).process(rgb, depth, K)` raises ImageFormatError (bad images), MarkerNotFoundError (no
marker: without the common frame nothing can be placed; MarkerOccludedError when it is partly covered),
MarkerInconsistentError or InconsistentFrameError (a consistency check failed: docs/perception.md, "Consistency
checks"); a frame is never published wrong, it is refused with the reason. The objects are found geometry first
(perception_aruco.objects): the depth points above the boards clustered, each cluster a primitive; the scenario's
listed objects are named by colour, size and position, the other clusters are unlisted objects (u1, u2, ...) with
an estimated weight. A listed object not found is in `missing` with the reason, never guessed; its space, if seen,
is an unlisted object.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import cv2
import numpy as np
from numpy.typing import ArrayLike

from relocation_common.geometry import invert
from relocation_common.scenario import Scenario

from .aruco import (
    MarkerInconsistentError,
    MarkerLocalizer,
    MarkerNotFoundError,
    MarkerObservation,
    MarkerParams,
    PerceptionError,
    fuse_markers,
)
from .debug_image import annotate
from .localize import LocalizeParams
from .objects.clusters import cluster_points, object_mask
from .objects.find import find_objects
from .objects.model import PerceivedObject, box_corners
from .objects.noise import DepthNoise
from .objects.params import ObjectParams
from .objects.self_filter import arm_in_shelf, arm_in_view, on_arm
from .segmentation import (
    PlateLevels,
    SegmentationParams,
    backproject_image,
    check_images,
    on_marker_plates,
    on_plates,
    plate_levels,
    segment_points,
)
from .shelf import InconsistentFrameError, ShelfFit, ShelfParams, corrected_K, fit_shelf
from .tracking import FrameFusion, SceneMemory, identity_conflicts

Seen = list[tuple[MarkerLocalizer, MarkerObservation]]   # the markers seen in a frame
__all__ = ["Perception", "PerceptionResult", "FrameFusion", "SceneMemory", "identity_conflicts"]

# a marker seen farther than this from where the largest one's frame and the scenario put it: one of them is not
# where the scenario says (the shelf fit corrects a shift along the shelf front poorly); the shelf decides which
MARKERS_AGREE_M = 0.03  # depth-refined poses; colour-only: twice the colour-only check
# markers that disagree: the shelf decides when it confirms one marker's own frame within this (the correction at the
# shelf's centre) and every other marker's frame needs SHELF_REJECTS times as much (docs/perception.md)
SHELF_CONFIRMS_M = 0.01   # a single correct marker's frame needs up to 5.3 mm (far, small marker 8)
SHELF_REJECTS = 3.0


class MarkersDisagreeError(MarkerInconsistentError):
    """Two markers seen where their scenario poses cannot both be; `seen`: the (localizer, observation) pairs."""

    def __init__(self, message: str, seen: Seen):
        super().__init__(message)
        self.seen = seen


@dataclass(frozen=True)
class PerceptionResult:
    """One processed frame. objects: every object found, by id (listed ones in scenario order, then the unlisted
    ones); missing: listed id -> why it was not found; T_base_camera: the camera pose used (marker, corrected by the
    shelf fit); marker: the marker as seen (None when it was not, and the caller's `prior` pose stood in); notes:
    what the checks said; uncounted: the unlisted ids (seen now, or candidates not seen) this frame is no evidence
    for (SceneMemory.update: the arm's pose unknown, the arm in the shelf, or moving in front of them); reached: the
    listed ids whose last pose (the memory's) the arm comes within `arm_near` of at the frame's joint states, every
    one without a joint state (SceneMemory.update: only their tracks may jump)."""

    marker: MarkerObservation | None
    objects: dict[str, PerceivedObject]
    missing: dict[str, str]
    T_base_camera: np.ndarray = field(repr=False)
    shelf: ShelfFit | None
    notes: tuple[str, ...]
    uncounted: frozenset[str]
    reached: frozenset[str]

    @property
    def detections(self) -> dict[str, PerceivedObject]:
        """The listed objects found, by id."""
        return {i: o for i, o in self.objects.items() if o.listed}

    @property
    def unlisted(self) -> dict[str, PerceivedObject]:
        """The objects the scenario does not list, by id (u1, u2, ...)."""
        return {i: o for i, o in self.objects.items() if not o.listed}


# rad: joint states this close are the same arm pose to FrameInputs.same. A resting arm's states differ in their last
# bits (the simulator's: 1e-25 rad, its physics settling), so byte equality processed every frame of a scene at rest
# (0.9 of a core at 2 frames/s); a nanoradian moves the arm's capsules a nanometre, against arm_padding's 20 mm.
Q_SAME = 1e-9


@dataclass(frozen=True)
class FrameInputs:
    """What `Perception.process` reads of one frame: the images, K, the arm's joint states and whether its pose is
    unknown, the memory's view (SceneMemory.view) and the prior (None unless the frame read it: only when a marker
    is not detected). Two frames with the same inputs have the same result: every step is deterministic (its RANSAC
    seeded per call)."""

    rgb: np.ndarray
    depth: np.ndarray
    K: np.ndarray
    q: np.ndarray | None
    arm_unknown: bool
    memory: tuple
    prior: np.ndarray | None

    def same(self, other: FrameInputs) -> bool:
        """Whether `other`'s inputs equal these (byte for byte; the prior compared only when this frame read it;
        the joint states within Q_SAME rad). About 1 ms at 640x480: one comparison of each image buffer."""
        def equal(a: np.ndarray | None, b: np.ndarray | None, tol: float | None = None) -> bool:
            if a is None or b is None:
                return a is b
            if tol is not None:
                return a.shape == b.shape and bool(np.all(np.abs(a - b) <= tol))
            return a.shape == b.shape and a.dtype == b.dtype and a.tobytes() == b.tobytes()
        return (self.arm_unknown == other.arm_unknown and self.memory == other.memory and equal(self.K, other.K)
                and equal(self.q, other.q, Q_SAME) and (self.prior is None or equal(self.prior, other.prior))
                and equal(self.rgb, other.rgb) and equal(self.depth, other.depth))


def arm_reaches(memory: SceneMemory, ids: tuple[str, ...], q: np.ndarray | None, near: float) -> frozenset[str]:
    """The listed ids whose last pose (bottom, middle and top of its axis) the arm's capsules at the joint states q
    come within its footprint's reach + `near` of: it may move them. q None (no joint state): every one."""
    last = {i: o for i in ids if (o := memory.expected(i)) is not None}
    if q is None:
        return frozenset(last)
    return frozenset(i for i, o in last.items() if on_arm(
        np.array([[o.x, o.y, o.z + t * o.height] for t in (0.0, 0.5, 1.0)]), q, o.reach + near).any())


class Perception:
    """The perception core of one scenario (module docstring)."""

    def __init__(self, scenario: Scenario, seg: SegmentationParams = SegmentationParams(),
                 loc: LocalizeParams = LocalizeParams(), refine_with_depth: bool = True,
                 shelf: ShelfParams = ShelfParams(), marker: MarkerParams = MarkerParams(),
                 objects: ObjectParams | None = None):
        self.scenario, self.seg, self.loc, self.shelf = scenario, seg, loc, shelf
        self.objects = objects if objects is not None else ObjectParams.configured()
        self.localizers = [MarkerLocalizer(m, refine_with_depth=refine_with_depth, params=marker)
                           for m in scenario.markers]
        self.localizer = self.localizers[0]   # the scenario's first marker
        # the listed objects' colours, each once (two objects of one colour would make its pixels ambiguous): the
        # shelf fit leaves pixels of these colours out
        unique = {o.rgb: o for o in scenario.objects}
        self._colour_classes = replace(scenario, objects=tuple(unique.values()), _by_id={})
        self._last: tuple[FrameInputs, PerceptionResult] | None = None   # the last frame processed and its result
        self._prior_read = False   # whether the frame being processed read its prior (_marker_frame)
        self.processed = self.reused = 0   # frames processed; frames whose inputs were the last one's (`process`)

    def process(self, rgb: ArrayLike, depth: ArrayLike, K: ArrayLike, prior: np.ndarray | None = None,
                memory: SceneMemory | None = None,
                q: np.ndarray | None = None, arm_unknown: bool = False) -> PerceptionResult:
        """The objects of one registered RGB-D frame. `prior`: T_base_camera of earlier frames (the node's fused
        frame); when the marker is not seen now, the prior stands in if the shelf confirms it. `memory`: the objects
        of earlier frames (their tracks: identity, unlisted ids; read, not changed: the caller updates it with the
        result); q: the arm's joint angles at the frame, or one row per joint state around its stamp (the body is left
        out over all of them; None: not filtered, said in notes). arm_unknown: the arm moved and no joint state at or
        after the frame's stamp came yet (tracking.JointHistory.unknown_at): no new objects from this frame.
        The result's `uncounted`: the new unlisted objects (seen now, or candidates the memory counts) this frame
        is no evidence for: the arm's pose unknown, the arm in the shelf within `arm_reach` of them, or moving (q of
        more than one row) in front of them (self_filter.arm_in_view); SceneMemory.update publishes a new one after
        `confirm_frames` frames that count. A first frame (an empty memory) with clusters left out near the arm is
        refused: nothing earlier explains that space.
        A frame whose inputs (FrameInputs) equal those of the last frame processed is not processed again: its result
        is that frame's (the same object; `reused` counts them, `processed` the frames processed): a scene where
        nothing moved and nothing changed in the memory costs the comparison of its images."""
        rgb, depth = check_images(rgb, depth)
        K = np.asarray(K, float).reshape(3, 3)
        memory = memory if memory is not None else SceneMemory(self.scenario.ids, 0, 1)
        inputs = FrameInputs(rgb, depth, K, None if q is None else np.array(q, float), arm_unknown, memory.view(),
                             None if prior is None else np.array(prior, float))
        if self._last is not None and self._last[0].same(inputs):
            self.reused += 1
            return self._last[1]
        self._prior_read = False
        result = self._process(rgb, depth, K, prior, memory, q, arm_unknown)
        self.processed += 1
        self._last = (replace(inputs, rgb=rgb.copy(), depth=depth.copy(),
                              prior=inputs.prior if self._prior_read else None), result)
        return result

    def _process(self, rgb: np.ndarray, depth: np.ndarray, K: np.ndarray, prior: np.ndarray | None,
                 memory: SceneMemory, q: np.ndarray | None, arm_unknown: bool) -> PerceptionResult:
        """`process` of a frame not seen before (its docstring)."""
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
        if q is None:
            notes.append("no joint state: the arm is not filtered out of the depth")
        mask = object_mask(points, depth, self.scenario, self.seg, self.objects, fit.noise, plates, q)
        clusters = cluster_points(points, mask, rgb, levels, self.scenario, self.seg, self.objects)
        # noisier depth: wider fit tolerances (the shelf's residual spread is the depth noise at the shelf); fewer
        # pixels: pixel counts scaled with the image area (the axis uncertainty check still bounds the fit)
        area = min(1.0, depth.size / (640 * 480))
        loc = replace(self.loc, inlier_tol=max(self.loc.inlier_tol, 2.5 * fit.noise),
                      max_rms=max(self.loc.max_rms, 1.5 * fit.noise), depth_noise=fit.noise,
                      min_pixels=max(12, round(self.loc.min_pixels * area)),
                      min_inliers=max(10, round(self.loc.min_inliers * area)))
        in_shelf = arm_in_shelf(q, self.scenario.shelf, self.objects.arm_padding)

        def near_arm(pts: np.ndarray) -> bool:
            """Points the arm may have made (its body, the object in its hand, a piece they cut out of another): the
            arm's pose unknown, or the arm in the shelf within arm_reach of them."""
            return arm_unknown or (in_shelf and bool(on_arm(pts, q, self.objects.arm_reach).any()))
        noise = DepthNoise(fit.noise, fit.noise_1m, T[:3, 3], T[:3, 2])
        objects, missing, left_out = find_objects(clusters, points, self.scenario, memory, self.seg, self.objects,
                                                  loc, T[:3, 3], noise, new_unlisted=lambda pts: not near_arm(pts))
        if left_out and memory.frame == 0:  # nothing earlier explains that space: no scene yet, never a free one
            raise PerceptionError(f"{left_out} cluster(s) matching no listed object in the first frame, with the arm "
                                  "in the shelf (new objects are taken with the arm out of it): no scene until the "
                                  "arm is out of the shelf")
        if left_out:
            notes.append(f"{left_out} cluster(s) matching no known object left out while the arm is in the shelf "
                         "(new objects are taken with the arm out of it)")
        candidates = {**memory.pending(), **{i: o for i, o in objects.items()
                                             if not o.listed and i not in memory.confirmed}}
        moving = q is not None and len(np.atleast_2d(q)) > 1
        uncounted = frozenset(i for i, o in candidates.items() if near_arm(box_corners(o)) or (moving and arm_in_view(
            q, box_corners(o), T, corrected_K(K, fit.intrinsics), self.objects.arm_padding)))
        return PerceptionResult(marker, objects, missing, T, fit, tuple(notes), uncounted,
                                arm_reaches(memory, self.scenario.ids, q, self.objects.arm_near))

    def _seen_plates(self, cam: np.ndarray, seen: Seen) -> np.ndarray:
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

    def _fit_shelf(self, rgb: np.ndarray, cam: np.ndarray, t0: np.ndarray, levels: PlateLevels | None,
                   plates: np.ndarray) -> ShelfFit:
        """The shelf fit (`fit_shelf`) of the frame `t0`, bottles and the further markers' plates left out."""
        r0, p0 = t0[:3, :3].astype(np.float32), t0[:3, 3].astype(np.float32)
        st = self.shelf.stride   # the shelf fit uses every st-th pixel: classify only those to leave bottles out
        sampled = cam[::st, ::st] @ r0.T + p0
        first = segment_points(rgb[::st, ::st], sampled, self._colour_classes,
                               replace(self.seg, erode_px=0, median_px=0), levels, plates[::st, ::st])
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

    def _shelf_decides(self, err: MarkersDisagreeError, rgb: np.ndarray, cam: np.ndarray, notes: list[str]) \
            -> tuple[MarkerObservation, np.ndarray, ShelfFit, PlateLevels | None, np.ndarray]:
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

    def _marker_frame(self, rgb: np.ndarray, K: np.ndarray, depth: np.ndarray, prior: np.ndarray | None,
                      notes: list[str]) -> tuple[MarkerObservation | None, np.ndarray, Seen]:
        """(the marker seen largest in the image, T_base_camera, the (localizer, observation) pairs seen): the
        markers seen fused (`fuse_markers`; a covered or inconsistent one is left out, its reason in `notes`;
        markers that disagree raise MarkersDisagreeError, `_shelf_decides`); none seen: the prior if given and no
        marker was inconsistent, else the marker's error (all markers' reasons)."""
        seen, errors, found = [], [], {}
        self._prior_read = prior is not None   # read below when a marker is not detected (FrameInputs)
        for loc in self.localizers:
            expected = None if prior is None else invert(prior) @ loc.T_base_marker
            if loc.marker.dictionary not in found:  # one detector pass per dictionary
                found[loc.marker.dictionary] = loc.detect_all(rgb)
            try:
                seen.append((loc, loc.locate(rgb, K, depth, expected, found[loc.marker.dictionary])))
            except (MarkerNotFoundError, MarkerInconsistentError) as e:
                errors.append(e)
        self._prior_read = self._prior_read and bool(errors)
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

    def annotate(self, rgb: np.ndarray, result: PerceptionResult | None, K: ArrayLike | None = None,
                 note: str = "") -> np.ndarray:
        """Debug image (debug_image.annotate) with this scenario's marker size."""
        return annotate(rgb, result, K, note, self.scenario.marker.size)
