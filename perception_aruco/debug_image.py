"""The debug image of a processed frame (no rclpy): the marker outline and axes, each object's id at its pixel
(listed white, unlisted orange, conservative boxes red) with its shape, the missing listed ids or the reason a frame
was refused."""
from __future__ import annotations

from typing import Any

import cv2
import numpy as np
from numpy.typing import ArrayLike

from .objects.model import PerceivedObject


def _label(o: PerceivedObject) -> str:
    shape = "box?" if o.conservative else "lying" if o.lying else o.shape
    return f"{o.id} {o.label} {shape}".strip()


def annotate(rgb: np.ndarray, result: Any, K: ArrayLike | None = None, note: str = "",
             marker_size: float = 0.0) -> np.ndarray:
    """Debug image (RGB) of `result` (pipeline.PerceptionResult, or None for a refused frame with `note`)."""
    img = np.ascontiguousarray(rgb).copy()
    if result is not None and result.marker is not None:
        c = np.round(result.marker.corners).astype(np.int32)
        cv2.polylines(img, [c], True, (0, 255, 0), 2)
        T = result.marker.T_camera_marker
        if K is not None:
            cv2.drawFrameAxes(img, np.asarray(K, float).reshape(3, 3), None, cv2.Rodrigues(T[:3, :3])[0], T[:3, 3],
                              marker_size)
    if result is not None:
        for o in result.objects.values():
            colour = (255, 255, 255) if o.listed else (255, 64, 64) if o.conservative else (255, 160, 0)
            cv2.circle(img, o.pixel, 4, colour, -1)
            cv2.putText(img, _label(o), (o.pixel[0] - 20, o.pixel[1] - 8), cv2.FONT_HERSHEY_SIMPLEX, 0.4, colour, 1,
                        cv2.LINE_AA)
        if result.missing:
            note = (note + " " if note else "") + "missing: " + ", ".join(result.missing)
    if note:
        cv2.putText(img, note[:90], (5, img.shape[0] - 8), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (255, 64, 64), 1,
                    cv2.LINE_AA)
    return img
