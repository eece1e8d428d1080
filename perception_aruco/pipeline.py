"""One RGB-D frame -> camera pose (marker) -> segmentation -> located bottles, and the debug image (no rclpy).

`Perception(scenario).process(rgb, depth, K)` raises ImageFormatError (bad images) or MarkerNotFoundError (no
marker: without the common frame nothing can be placed, so nothing is reported); bottles that are not visible
enough are listed in `missing` with the reason, never guessed. Identity, weight, radius and height of a located
bottle come from its colour class through the scenario (`Perception.bottles`).
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import cv2
import numpy as np

from relocation_common.scenario import Bottle, Scenario

from .aruco import MarkerLocalizer, MarkerObservation
from .localize import Detection, FitError, LocalizeParams, locate_bottle
from .segmentation import Segmentation, SegmentationParams, check_images, segment


@dataclass(frozen=True)
class PerceptionResult:
    marker: MarkerObservation
    detections: dict[str, Detection]
    missing: dict[str, str]                  # id -> why it was not located
    segmentation: Segmentation = field(repr=False)

    @property
    def T_base_camera(self) -> np.ndarray:
        return self.marker.T_base_camera


class Perception:
    def __init__(self, scenario: Scenario, seg: SegmentationParams = SegmentationParams(),
                 loc: LocalizeParams = LocalizeParams(), refine_with_depth: bool = True):
        self.scenario, self.seg, self.loc = scenario, seg, loc
        self.localizer = MarkerLocalizer(scenario.marker, refine_with_depth=refine_with_depth)

    def process(self, rgb, depth, K) -> PerceptionResult:
        rgb, depth = check_images(rgb, depth)
        K = np.asarray(K, float).reshape(3, 3)
        marker = self.localizer.locate(rgb, K, depth)
        seg = segment(rgb, depth, K, marker.T_base_camera, self.scenario, self.seg)
        cam = marker.T_base_camera[:3, 3]
        found, missing = {}, {}
        for b in self.scenario.objects:
            try:
                found[b.id] = locate_bottle(b, seg.mask(b.id), seg.points, self.scenario, cam, self.loc)
            except FitError as e:
                missing[b.id] = str(e)
        return PerceptionResult(marker, found, missing, seg)

    def bottles(self, detections) -> list[Bottle]:
        """Scenario bottles moved to their perceived (x, y): id, label, weight, size from the colour class."""
        return [replace(self.scenario.object(d.id), x=d.x, y=d.y) for d in detections]

    def annotate(self, rgb: np.ndarray, result: PerceptionResult | None, K=None, note: str = "") -> np.ndarray:
        """Debug image (RGB): marker outline and axes, each located bottle's id at its pixel, missing ids."""
        img = np.ascontiguousarray(rgb).copy()
        if result is not None:
            c = np.round(result.marker.corners).astype(np.int32)
            cv2.polylines(img, [c], True, (0, 255, 0), 2)
            T = result.marker.T_camera_marker
            if K is not None:
                cv2.drawFrameAxes(img, np.asarray(K, float).reshape(3, 3), None, cv2.Rodrigues(T[:3, :3])[0], T[:3, 3],
                                  self.scenario.marker.size)
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
