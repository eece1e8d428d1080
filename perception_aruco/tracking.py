"""What perception keeps across frames (no rclpy): the objects' last poses and the hidden-object policy
(`SceneMemory`), the fused camera pose (`FrameFusion`) and the identity check against the previous scene
(`identity_conflicts`). docs/perception.md, "Hidden objects" and "Health, fusion"."""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field
from typing import Collection, Mapping

import numpy as np

from relocation_common.geometry import pose_error

from .objects.model import PerceivedObject

UNLISTED_PREFIX = "u"


def unlisted_number(object_id: str) -> int:
    """k of an unlisted object's id u<k> (0 for any other id)."""
    tail = object_id[len(UNLISTED_PREFIX):]
    return int(tail) if object_id.startswith(UNLISTED_PREFIX) and tail.isdigit() else 0


@dataclass
class SceneMemory:
    """The hidden-object policy (docs/perception.md): an object not seen in the current frame keeps its last
    perceived pose for `hold_frames` processed frames, then is dropped; nothing is ever guessed. It also remembers
    every object's last pose (the identity match's expected position) and numbers the unlisted objects u1, u2, ...
    in order of first sight. A new unlisted object is published once seen in `confirm_frames` consecutive frames
    that count for it (the arm's pose known, out of the shelf, and not moving in front of it: the caller says which
    frames do not, `update`'s `uncounted`); a frame that counts without it starts its count over. Until then it
    is a candidate: tracked (its id kept), never published. ids: the scenario's listed ids, in the order the scene
    lists them."""

    ids: tuple[str, ...]
    hold_frames: int
    confirm_frames: int
    frame: int = 0
    last_seen: dict[str, tuple[PerceivedObject, int]] = field(default_factory=dict)  # id -> (object, frame index)
    unlisted_count: int = 0
    streak: dict[str, int] = field(default_factory=dict)   # candidate id -> frames that counted in a row
    confirmed: set[str] = field(default_factory=set)       # unlisted ids published (confirmed)
    reached: set[str] = field(default_factory=set)         # ids the arm came near since last seen (it may have moved)

    def expected(self, object_id: str) -> PerceivedObject | None:
        """The object's last perceived pose (any age), or None if never seen."""
        seen = self.last_seen.get(object_id)
        return None if seen is None else seen[0]

    def view(self) -> tuple:
        """All that Perception.process reads of the memory (the identity's objects.identity.Memory, the pending and
        confirmed candidates, whether it is the first frame): two memories with equal views give a frame the same
        result (pipeline.FrameInputs)."""
        return (self.frame == 0, {i: o for i, (o, _) in self.last_seen.items()}, tuple(self.held()),
                frozenset(self.reached), self.unlisted_count, tuple(self.streak), frozenset(self.confirmed))

    def arm_near(self, object_id: str) -> bool:
        """Whether the arm came near the object's last pose since it was seen there (`update`'s `reached`): only
        then may its track jump (identity.listed_costs)."""
        return object_id in self.reached

    def held(self) -> dict[str, PerceivedObject]:
        """The listed objects the next frame would still publish at their last pose if not seen in it, by id."""
        return {i: o for i, (o, f) in self.last_seen.items()
                if i in self.ids and self.frame + 1 - f <= self.hold_frames}

    def unlisted(self) -> dict[str, PerceivedObject]:
        """The unlisted objects ever seen (candidates too), by id (their last poses)."""
        return {i: o for i, (o, _) in self.last_seen.items() if i not in self.ids}

    def pending(self) -> dict[str, PerceivedObject]:
        """The candidates (unlisted, not yet published) with a count under way, by id (their last poses)."""
        return {i: self.last_seen[i][0] for i in self.streak}

    def new_ids(self, n: int) -> list[str]:
        """The ids the next n unlisted objects seen for the first time get (`update` takes them)."""
        return [f"{UNLISTED_PREFIX}{self.unlisted_count + k + 1}" for k in range(n)]

    def update(self, objects: Mapping[str, PerceivedObject], uncounted: Collection[str],
               reached: Collection[str] = ()) -> tuple[list[PerceivedObject], list[str], list[str]]:
        """Record one processed frame; returns (objects to publish: listed in scenario order, then the confirmed
        unlisted by number; held ids; lost ids: listed objects not held, and confirmed unlisted ones dropped in this
        frame). uncounted: the unlisted ids this frame is no evidence for, seen in it or not (class docstring);
        reached: the ids whose last pose the arm came near in this frame (PerceptionResult.reached)."""
        self.frame += 1
        for i, o in objects.items():
            self.last_seen[i] = (o, self.frame)
            self.reached.discard(i)
            self.unlisted_count = max(self.unlisted_count, unlisted_number(i) if i not in self.ids else 0)
        self.reached |= set(reached)
        for i in [i for i in self.unlisted() if i not in self.confirmed]:
            if i in uncounted:
                continue
            if i in objects:
                self.streak[i] = self.streak.get(i, 0) + 1
            else:
                self.streak.pop(i, None)   # not seen in a frame that counts: its count starts over
            if self.streak.get(i, 0) >= self.confirm_frames:
                self.confirmed.add(i)
                del self.streak[i]
        keep = {i: o for i, (o, f) in self.last_seen.items() if self.frame - f <= self.hold_frames
                and (i in self.ids or i in self.confirmed)}
        order = list(self.ids) + sorted((i for i in keep if i not in self.ids), key=unlisted_number)
        held = [i for i in order if i in keep and i not in objects]
        lost = [i for i in self.ids if i not in keep] + sorted(
            (i for i, (_, f) in self.last_seen.items()
             if i in self.confirmed and self.frame - f == self.hold_frames + 1), key=unlisted_number)
        return [keep[i] for i in order if i in keep], held, lost


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
        m = np.mean([p[:3, :3] for p in self.poses], axis=0)
        u, _, vt = np.linalg.svd(m)
        out = np.eye(4)
        out[:3, :3] = u @ np.diag([1.0, 1.0, np.sign(np.linalg.det(u @ vt))]) @ vt
        out[:3, 3] = np.mean([p[:3, 3] for p in self.poses], axis=0)
        return out

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


def identity_conflicts(detections: Mapping[str, PerceivedObject], previous: Mapping[str, PerceivedObject],
                       moved: float = 0.02) -> dict[str, str]:
    """Listed objects that take the place of another object of the previous scene (overlapping where it stood)
    while that one is not seen now and this one stood elsewhere (> `moved` away): an identity swap is likelier than
    an object teleported onto another's place. id -> reason."""
    out = {}
    for i, d in detections.items():
        for j, p in previous.items():
            if j == i or j in detections or abs(d.z - p.z) > 0.05:
                continue
            gap = math.hypot(d.x - p.x, d.y - p.y) - d.reach - p.reach
            was = previous.get(i)
            if gap < -0.01 and (was is None or math.hypot(d.x - was.x, d.y - was.y) > moved):
                out[i] = f"found where {j} stood in the previous scene, and {j} is not seen: identity in doubt"
    return out


class JointHistory:
    """The arm's recent joint states (stamp, 7 angles), for the self-filter: the ones within `window` s of a frame's
    stamp, with the nearest one on either side, are where the arm may have been when the frame was taken (images and
    joint states come on their own streams and clocks' jitter; the newest joint state alone lags or leads a moving
    arm). Poses within `step` rad of the previous kept one add nothing: with the arm's reach under 1 m, such a pose
    lies within `step` m of the kept one, which the filter's padding (the node passes `arm_padding`) covers."""

    def __init__(self, window: float, step: float, keep: float = 2.0):
        self.window, self.step, self.keep = window, step, keep
        self.states: deque[tuple[float, np.ndarray]] = deque()

    def add(self, t: float, q: np.ndarray) -> None:
        """Record one joint state; states older than `keep` s before the newest are forgotten."""
        self.states.append((t, np.asarray(q, float)))
        while self.states and self.states[0][0] < t - self.keep:
            self.states.popleft()

    def unknown_at(self, t: float) -> bool:
        """Whether the arm's pose at stamp t is not known: no joint state at or after t yet (their delivery lags
        under load) while the arm moved over the last `window` s of the states there are. No joint state at all:
        False (the arm is then not filtered, as the frame's notes say)."""
        if not self.states or self.states[-1][0] >= t:
            return False
        last_t, last_q = self.states[-1]
        recent = [q for s, q in self.states if s >= last_t - self.window]
        return any(float(np.max(np.abs(q - last_q))) > self.step for q in recent)

    def around(self, t: float) -> np.ndarray | None:
        """k x 7: the poses the arm may have had at stamp t (class docstring); None before any joint state."""
        if not self.states:
            return None
        stamps = np.array([s for s, _ in self.states])
        near = np.abs(stamps - t) <= self.window
        before, after = np.nonzero(stamps <= t)[0], np.nonzero(stamps >= t)[0]
        for side in (before[-1:], after[:1]):
            near[side] = True
        if not near.any():
            near[-1] = True
        out: list[np.ndarray] = []
        for i in np.nonzero(near)[0]:
            q = self.states[int(i)][1]
            if not out or float(np.max(np.abs(q - out[-1]))) > self.step:
                out.append(q)
        return np.array(out)
