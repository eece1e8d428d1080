"""Which voxels of the top-shelf compartment the camera has observed: free (a depth ray passed through them),
occupied (a ray ended in them) or never observed (behind the objects, under the ceiling board's edge, behind the arm).

Perception publishes what it saw; the planner takes space nobody saw as free unless an object was seen there and is
held (`hold_frames`; docs/perception.md, "Unobserved space"). This map says where that assumption is made.

Each frame is integrated projectively: every voxel centre is put into the camera frame and projected into the depth
image; with the pixel's depth d and the centre's depth z (both along the optical axis), z < d - band is free (the
pixel's ray passed through it), |z - d| <= band occupied (the ray ended in it), z > d + band or no valid depth (0,
NaN: no return) or outside the image not observed by this frame (band: half the voxel's diagonal). A later
observation of a voxel replaces an earlier one. At 640x480 and 0.8 m a pixel covers ~1.5 mm, far less than a voxel,
so a voxel centre's pixel is the ray through it: this is ray casting at the voxel centres, in a few numpy lines
over all voxels at once, without walking each ray. Open3D's VoxelGrid / RaycastingScene would do the same with a
mesh or point cloud built first; it is not installed here (a 400 MB wheel, docs/perception.md, "Objects").
"""
from __future__ import annotations

import math
from typing import Iterable

import numpy as np

from relocation_common.scenario import Shelf

UNOBSERVED, FREE, OCCUPIED = 0, 1, 2


class ObservedSpace:
    """A voxel grid over the box [lo, hi] (base frame) with the state of each voxel (UNOBSERVED, FREE, OCCUPIED)."""

    def __init__(self, lo: np.ndarray, hi: np.ndarray, voxel: float) -> None:
        if voxel <= 0:
            raise ValueError(f"voxel must be > 0, got {voxel}")
        self.lo, self.voxel = np.asarray(lo, float), float(voxel)
        self.shape = tuple(int(n) for n in np.maximum(np.ceil((np.asarray(hi, float) - self.lo) / voxel), 1))
        self.state = np.zeros(self.shape, np.uint8)
        axes = [self.lo[i] + (np.arange(n) + 0.5) * voxel for i, n in enumerate(self.shape)]
        self.centres = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)

    @classmethod
    def top_compartment(cls, shelf: Shelf, voxel: float) -> "ObservedSpace":
        """The space between the top board's surface, the ceiling board's underside, the side panels and the back
        panel, open at the front (x_front)."""
        return cls(np.array([shelf.x_front, shelf.y_min, shelf.top_z]),
                   np.array([shelf.x_back, shelf.y_max, shelf.ceiling_z]), voxel)

    def integrate(self, depth: np.ndarray, K: np.ndarray, T_base_camera: np.ndarray) -> None:
        """Mark the voxels this depth image (HxW, metres along the optical axis, 0 = no return) observes, with the
        pinhole K and the optical frame's pose T_base_camera (module docstring)."""
        depth = np.asarray(depth, float)
        h, w = depth.shape
        to_cam = np.linalg.inv(np.asarray(T_base_camera, float))
        p = self.centres @ to_cam[:3, :3].T + to_cam[:3, 3]
        z = p[:, 2]
        ok = z > 1e-3
        zs = np.where(ok, z, 1.0)
        u = np.rint(K[0, 0] * p[:, 0] / zs + K[0, 2]).astype(np.int64)
        v = np.rint(K[1, 1] * p[:, 1] / zs + K[1, 2]).astype(np.int64)
        ok &= (u >= 0) & (u < w) & (v >= 0) & (v < h)
        d = np.zeros(len(z))
        d[ok] = depth[v[ok], u[ok]]
        ok &= np.isfinite(d) & (d > 0)
        band = self.voxel * math.sqrt(3) / 2
        flat = self.state.reshape(-1)
        flat[ok & (z < d - band)] = FREE
        flat[ok & (np.abs(z - d) <= band)] = OCCUPIED

    def state_at(self, points: np.ndarray) -> np.ndarray:
        """The state of the voxel holding each point (N x 3, base frame); UNOBSERVED outside the grid."""
        k = np.floor((np.atleast_2d(np.asarray(points, float)) - self.lo) / self.voxel).astype(np.int64)
        inside = np.all((k >= 0) & (k < np.asarray(self.shape)), axis=1)
        out = np.full(len(k), UNOBSERVED, np.uint8)
        out[inside] = self.state[tuple(k[inside].T)]
        return out

    @property
    def unobserved(self) -> np.ndarray:
        """Bool over the grid: never observed."""
        return self.state == UNOBSERVED

    def within(self, lo: np.ndarray, hi: np.ndarray) -> tuple[slice, slice, slice]:
        """The index ranges of the voxels whose centres may lie in the box [lo, hi] (empty slices outside)."""
        a = np.clip(np.floor((np.asarray(lo) - self.lo) / self.voxel), 0, self.shape).astype(int)
        b = np.clip(np.ceil((np.asarray(hi) - self.lo) / self.voxel), 0, self.shape).astype(int)
        return (slice(a[0], b[0]), slice(a[1], b[1]), slice(a[2], b[2]))

    def centres_of(self, index: tuple[slice, slice, slice]) -> np.ndarray:
        """The centres (..., 3) of the voxels of an index range."""
        return self.centres.reshape(*self.shape, 3)[index]

    def mark_capsules(self, out: np.ndarray, segments: Iterable[tuple[np.ndarray, np.ndarray, float]]) -> None:
        """Set `out` (bool over the grid) where a voxel centre is inside one of the capsules (p0, p1, radius)."""
        for p0, p1, r in segments:
            p0, p1 = np.asarray(p0, float), np.asarray(p1, float)
            idx = self.within(np.minimum(p0, p1) - r, np.maximum(p0, p1) + r)
            c = self.centres_of(idx)
            if not c.size:
                continue
            seg = p1 - p0
            s = np.clip((c - p0) @ seg / max(float(seg @ seg), 1e-12), 0.0, 1.0)
            out[idx] |= np.linalg.norm(c - (p0 + s[..., None] * seg), axis=-1) <= r

    def mark_primitive(self, out: np.ndarray, pose: np.ndarray, shape: str, dims: tuple[float, float, float]) -> None:
        """Set `out` where a voxel centre is inside a primitive at `pose` (4x4, its centre; SolidPrimitive
        convention): shape "cylinder" with dims (2r, 2r, length) along its z, or "box" with dims its sides."""
        half = np.asarray(dims, float) / 2
        reach = float(np.linalg.norm(half))
        idx = self.within(pose[:3, 3] - reach, pose[:3, 3] + reach)
        c = self.centres_of(idx)
        if not c.size:
            return
        local = (c - pose[:3, 3]) @ pose[:3, :3]
        if shape == "box":
            out[idx] |= np.all(np.abs(local) <= half, axis=-1)
        else:
            out[idx] |= (np.hypot(local[..., 0], local[..., 1]) <= half[0]) & (np.abs(local[..., 2]) <= half[2])
