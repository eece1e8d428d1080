"""The object points of a frame clustered into objects: DBSCAN on voxel centroids.

Object points (`object_mask`): inside a shelf compartment, off the boards and panels by the gate's margin (grown with
the frame's depth noise), off the marker plates (scenario and as seen), off the robot (`self_filter`), and steady (depth
within `occluder_gap` of its 3x3 median: a real sensor's flying pixels between two surfaces are left out). The points
are averaged per voxel (`voxel`) with their colour (3x3 median, normalised by the marker plate), DBSCAN (`dbscan`:
`cluster_eps`, `cluster_min_samples`) labels the voxels in (position, colour scaled so that `cluster_colour` RGB units
count as `cluster_eps`) and every pixel takes its voxel's label; clusters of fewer than `min_cluster_pixels` pixels
(scaled with the image area) are sensor noise. Each cluster's colour: the per-channel median of its pixels normalised by
the marker plate's white and black (segmentation.normalise_colours), with the channels the camera saturated on most of
its pixels.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from relocation_common.scenario import Scenario

from ..segmentation import PlateLevels, SegmentationParams, normalise_colours, workspace_mask
from .params import ObjectParams
from .self_filter import on_arm

STEADY_GAP = 0.01  # m: a pixel whose depth is this far off its 3x3 median is a flying pixel (localize's occluder_gap)


@dataclass(frozen=True)
class Cluster:
    """One object's points: pixel rows and columns (N,), base-frame points (N x 3), the board it rests on (z of its
    surface), its colour (normalised RGB 0..255; `clipped`: channels saturated on most of its pixels)."""

    rows: np.ndarray
    cols: np.ndarray
    points: np.ndarray
    support: float
    colour: np.ndarray
    clipped: np.ndarray

    @property
    def size(self) -> int:
        """Pixels of the cluster."""
        return len(self.rows)


def dbscan(x: np.ndarray, eps: float, min_samples: int) -> np.ndarray:
    """scikit-learn's DBSCAN labels (sklearn.cluster.DBSCAN(eps, min_samples).fit(x).labels_), from scipy's k-d tree
    pairs: core points (min_samples within eps, itself counted) joined by pairs within eps are one cluster, numbered
    in the order of their first core point; a border point takes the first cluster of a core point within eps (as
    DBSCAN's expansion, one cluster after another, reaches it); the rest -1 (noise). Why not DBSCAN itself: its
    ball-tree neighbourhoods cost 55-65 ms on the 15,000 voxels of 30 bottles in these 6 dimensions, the k-d tree's
    pairs 15 ms (test_perception_clusters.py holds the two equal)."""
    n = len(x)
    pairs = cKDTree(x).query_pairs(eps, output_type="ndarray").reshape(-1, 2)
    core = np.bincount(pairs.ravel(), minlength=n) + 1 >= min_samples
    both = pairs[core[pairs[:, 0]] & core[pairs[:, 1]]]
    _, comp = connected_components(coo_matrix((np.ones(len(both)), (both[:, 0], both[:, 1])), shape=(n, n)),
                                   directed=False)
    first = np.full(n, n)      # each component's first core point
    np.minimum.at(first, comp[core], np.nonzero(core)[0])
    number = np.empty(n, int)  # components numbered in the order of their first core point
    number[np.argsort(first)] = np.arange(n)
    labels = np.full(n, -1)
    labels[core] = number[comp[core]]
    edge = np.r_[pairs, pairs[:, ::-1]]           # (core, not core): the border points' candidate clusters
    edge = edge[core[edge[:, 0]] & ~core[edge[:, 1]]]
    border = np.full(n, n)
    np.minimum.at(border, edge[:, 1], labels[edge[:, 0]])
    reached = ~core & (border < n)
    labels[reached] = border[reached]
    return labels


def object_mask(points: np.ndarray, depth: np.ndarray, scenario: Scenario, seg: SegmentationParams,
                params: ObjectParams, noise: float, exclude: np.ndarray | None, q: np.ndarray | None) -> np.ndarray:
    """HxW bool: the pixels that may belong to objects (module docstring). `exclude`: pixels never objects (the
    markers' plates as seen); q: the arm's joint angles, one row per joint state around the frame's stamp (None: the
    arm is not filtered)."""
    gate = workspace_mask(points, scenario, seg.wall_margin + params.wall_noise * noise, seg.marker_margin)
    if exclude is not None:
        gate &= ~exclude
    d = np.where(np.isfinite(depth) & (depth > 0), depth, 0).astype(np.float32)
    gate &= np.abs(d - cv2.medianBlur(d, 3)) < STEADY_GAP
    if q is not None and gate.any():
        gate[gate] = ~on_arm(points[gate], q, params.arm_padding)
    return gate


def cluster_points(points: np.ndarray, mask: np.ndarray, rgb: np.ndarray, levels: PlateLevels | None,
                   scenario: Scenario, seg: SegmentationParams, params: ObjectParams) -> list[Cluster]:
    """The clusters of the masked points (module docstring), largest first."""
    v, u = np.nonzero(mask)
    if not len(v):
        return []
    p = points[v, u].astype(np.float64)
    key = np.floor(p / params.voxel).astype(np.int64)
    key -= key.min(axis=0)
    span = key.max(axis=0) + 1
    flat = (key[:, 0] * span[1] + key[:, 1]) * span[2] + key[:, 2]
    _, inv = np.unique(flat, return_inverse=True)
    inv = inv.ravel()
    count = np.bincount(inv)
    # DBSCAN on (position, colour x cluster_eps / cluster_colour): touching objects of different colours (a bottle
    # and the hand holding it) part; the shading along one object changes slowly from voxel to voxel
    smooth = cv2.medianBlur(np.ascontiguousarray(rgb), 3)[v, u].astype(np.float64)
    feat = np.c_[p, normalise_colours(smooth, levels, seg) * (params.cluster_eps / params.cluster_colour)]
    centroids = np.stack([np.bincount(inv, feat[:, k]) for k in range(6)], axis=1) / count[:, None]
    labels = dbscan(centroids, params.cluster_eps, params.cluster_min_samples)[inv]
    area = min(1.0, mask.size / (640 * 480))
    least = max(10, round(params.min_cluster_pixels * area))
    n = np.bincount(labels[labels >= 0]) if (labels >= 0).any() else np.zeros(0, int)
    s = scenario.shelf
    out = []
    for k in np.argsort(-n):
        if n[k] < least:
            break
        sel = labels == k
        px = rgb[v[sel], u[sel]]
        colour = np.median(normalise_colours(px, levels, seg), axis=0)
        clipped = np.mean(px >= seg.clip_level, axis=0) > 0.5
        support = s.top_z if np.median(p[sel, 2]) > s.top_z - s.board_thickness / 2 else s.bottom_z
        out.append(Cluster(v[sel], u[sel], p[sel], float(support), np.asarray(colour, float), clipped))
    return out
