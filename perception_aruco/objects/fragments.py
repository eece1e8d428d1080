"""One object seen in pieces: an object partly hidden by a nearer one shows disconnected parts (above and beside
it), which DBSCAN keeps apart. Two clusters on one board, of one colour (each within half `max_residual` of the
other shaded), whose footprints are within `merge_gap` of each other, are one object when their union fits a
primitive (not a conservative box): then they are merged, nearest pairs first, until no pair merges."""
from __future__ import annotations

from typing import Callable

import numpy as np

from ..segmentation import SegmentationParams, colour_residuals
from .clusters import Cluster
from .identity import Fitted


def union(a: Cluster, b: Cluster) -> Cluster:
    """The points of both clusters; colour the size-weighted mean, clipped where both are."""
    n = a.size + b.size
    return Cluster(np.r_[a.rows, b.rows], np.r_[a.cols, b.cols], np.r_[a.points, b.points], a.support,
                   (a.colour * a.size + b.colour * b.size) / n, a.clipped & b.clipped)


def _gap(a: np.ndarray, b: np.ndarray) -> float:
    """Distance between two x-y bounding boxes (x0, y0, x1, y1; 0 when they overlap)."""
    return float(np.linalg.norm(np.maximum(np.maximum(a[:2], b[:2]) - np.minimum(a[2:], b[2:]), 0.0)))


def _box(c: Cluster) -> np.ndarray:
    return np.r_[c.points[:, :2].min(0), c.points[:, :2].max(0)]


def _same_colour(a: Cluster, b: Cluster, seg: SegmentationParams) -> bool:
    ab = colour_residuals(a.colour[None, :], b.colour[None, :], seg)[0, 0]
    ba = colour_residuals(b.colour[None, :], a.colour[None, :], seg)[0, 0]
    return min(float(ab), float(ba)) <= seg.max_residual / 2


def merge_fragments(fitted: list[Fitted], refit: Callable[[Cluster], Fitted], seg: SegmentationParams,
                    merge_gap: float) -> list[Fitted]:
    """The clusters with the pieces of one object merged (module docstring); `refit` fits a cluster."""
    out = list(fitted)
    tried: set[tuple[int, int]] = set()
    box_of = {id(f): _box(f.cluster) for f in out}   # each cluster's x-y box, made once
    kept = list(out)   # every cluster tried stays alive: the ids in `tried` and `box_of` are never reused
    while True:
        b = np.array([box_of[id(f)] for f in out]).reshape(-1, 4)
        sup = np.array([f.cluster.support for f in out])
        gaps = np.maximum(np.maximum(b[:, None, :2], b[None, :, :2]) - np.minimum(b[:, None, 2:], b[None, :, 2:]), 0.0)
        gap = np.sqrt(gaps[..., 0] * gaps[..., 0] + gaps[..., 1] * gaps[..., 1])   # _gap of every pair
        near = (np.abs(sup[:, None] - sup[None, :]) < 1e-6) & (gap <= merge_gap)
        pairs = sorted((float(gap[i, j]), i, j) for i, j in zip(*np.nonzero(np.triu(near, 1)))
                       if (id(out[i]), id(out[j])) not in tried)
        merged = False
        for _, i, j in pairs:
            tried.add((id(out[i]), id(out[j])))
            if not _same_colour(out[i].cluster, out[j].cluster, seg):
                continue
            u = refit(union(out[i].cluster, out[j].cluster))
            kept.append(u)
            if not u.prim.conservative:
                box_of[id(u)] = _box(u.cluster)
                out = [f for k, f in enumerate(out) if k not in (i, j)] + [u]
                merged = True
                break
        if not merged:
            return out
