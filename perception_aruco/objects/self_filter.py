"""The robot's own body in the depth image: points within its collision capsules (robot_description.CAPSULES at
the joint angles of the frame) plus a padding are not objects, as MoveIt's depth self-filter does. The capsules are
the motion planner's conservative envelope of the open hand, so closed fingers lie inside them too."""
from __future__ import annotations

import math

import cv2
import numpy as np

from relocation_common import robot_description as rd
from relocation_common.scenario import Shelf


def link_frames(q: np.ndarray) -> dict[str, np.ndarray]:
    """4x4 pose of every arm link in the base frame at joint angles q (the URDF chain: joint_origins, then a rotation
    about z by Q_SIGN x q; the MuJoCo scene is built from the same description)."""
    origins = rd.joint_origins()
    t = np.eye(4)
    out = {rd.BASE_LINK: t.copy()}
    for i in range(rd.N_JOINTS):
        a = rd.Q_SIGN[i] * float(q[i])
        rz = np.array([[math.cos(a), -math.sin(a), 0, 0], [math.sin(a), math.cos(a), 0, 0], [0, 0, 1, 0],
                       [0, 0, 0, 1]])
        t = t @ origins[i] @ rz
        out[rd.LINK_NAMES[i]] = t.copy()
    return out


def arm_segments(q: np.ndarray) -> list[tuple[np.ndarray, np.ndarray, float]]:
    """(p0, p1, radius) of each collision capsule in the base frame at joint angles q."""
    frames = link_frames(q)
    out = []
    for c in rd.CAPSULES:
        f = frames[c.link]
        out.append((f[:3, :3] @ np.asarray(c.p0) + f[:3, 3], f[:3, :3] @ np.asarray(c.p1) + f[:3, 3], c.radius))
    return out


def on_arm(points: np.ndarray, q: np.ndarray | None, padding: float) -> np.ndarray:
    """Bool per point (N x 3, base frame): within `padding` of the arm's capsules at q (none when q is None). q: one
    joint state (7), or the joint states around the frame's stamp (k x 7): the arm's swept volume over them, since
    a moving arm is seen at the image's stamp, not at the newest joint state's."""
    out = np.zeros(len(points), bool)
    if q is None or not len(points):
        return out
    p = np.asarray(points, float)
    for qi in np.atleast_2d(np.asarray(q, float)):
        for p0, p1, r in arm_segments(qi):
            seg = p1 - p0
            s = np.clip((p - p0) @ seg / max(float(seg @ seg), 1e-12), 0.0, 1.0)
            d = np.linalg.norm(p - (p0 + s[:, None] * seg), axis=1)
            out |= d < r + padding
    return out


def arm_in_shelf(q: np.ndarray | None, shelf: Shelf, margin: float) -> bool:
    """Whether the arm, at any of the joint states around a frame (k x 7, or one), comes within `margin` of the
    shelf's inside (its capsules sampled along their axes). With the arm in the shelf its body, the object in its
    hand and the pieces they cut out of others show as clusters of their own. No joint state: not known to be in
    (the arm is then not filtered at all, said in the frame's notes, and what it shows is published)."""
    if q is None:
        return False
    lo = np.array([shelf.x_front, shelf.y_min, shelf.bottom_z])
    hi = np.array([shelf.x_back, shelf.y_max, shelf.ceiling_z])
    s = np.linspace(0.0, 1.0, 8)[:, None]
    for qi in np.atleast_2d(np.asarray(q, float)):
        for p0, p1, r in arm_segments(qi):
            pts = p0 + s * (p1 - p0)
            gap = np.linalg.norm(np.maximum(np.maximum(lo - pts, pts - hi), 0.0), axis=1)
            if float(gap.min()) < r + margin:
                return True
    return False


def arm_in_view(q: np.ndarray | None, corners: np.ndarray, T_base_camera: np.ndarray, K: np.ndarray,
                margin: float) -> bool:
    """Whether the arm, at any of the joint states around a frame (k x 7, or one), is between the camera and the
    box of `corners` (N x 3, base frame; an object's bounding box) or touches it in the image: a capsule, sampled
    along its axis, nearer than the box's farthest corner and projecting within its radius + `margin` (in pixels at
    its depth) of the box's image (the convex hull of its corners). Such a frame shows the arm, the object in its
    hand and the pieces they cut out of the objects behind them there: no evidence of an object. No joint state:
    False (as `arm_in_shelf`)."""
    if q is None:
        return False
    to_cam = np.linalg.inv(T_base_camera)
    c = np.asarray(corners, float) @ to_cam[:3, :3].T + to_cam[:3, 3]
    if np.any(c[:, 2] <= 1e-3):
        return True   # the box reaches behind the camera: its view cannot be told
    hull = cv2.convexHull(((K @ c.T).T[:, :2] / c[:, 2:]).astype(np.float32))
    far = float(c[:, 2].max())
    s = np.linspace(0.0, 1.0, 8)[:, None]
    for qi in np.atleast_2d(np.asarray(q, float)):
        for p0, p1, r in arm_segments(qi):
            pts = (p0 + s * (p1 - p0)) @ to_cam[:3, :3].T + to_cam[:3, 3]
            for p in pts[(pts[:, 2] > 1e-3) & (pts[:, 2] < far + r + margin)]:
                uv = (float(K[0, 0] * p[0] / p[2] + K[0, 2]), float(K[1, 1] * p[1] / p[2] + K[1, 2]))
                if cv2.pointPolygonTest(hull, uv, True) > -K[0, 0] * (r + margin) / p[2]:
                    return True
    return False
