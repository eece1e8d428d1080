"""STPIK checks reused across questions (the Stpik.track of the planner's own arm: the picks' paths).

A check (Eq. 9-10 along a path) is a function of its start, its path, its settings and of the obstacles its
broad phase lets through (ArmGeometry.near_pairs: an obstacle enters a step only when the axis-aligned box of
some moving capsule comes within the step's broad-phase distance d_act of its box). A check records, at every
step it evaluated, the boxes of the moving capsules; asked again with the same start, path and settings but
another obstacle set, its result is reused when every obstacle in one set and not in the other stays beyond d_act
of the boxes of every evaluated step (the same test as near_pairs), and the obstacles the two sets share come in
the same order. Then every step sees the same (capsule, obstacle) pairs in the same order, so it computes the
same numbers: the reused result is the one the check would give, bit for bit (by induction over the steps: the
same configuration, the same pairs, the same step). A change of the planner's parameters changes the key.
"""
from __future__ import annotations

import dataclasses
from collections import OrderedDict
from typing import TYPE_CHECKING, Any, Sequence

import numpy as np

from stpik_motion_planner.model.collision import Obstacle, ObstacleSet

if TYPE_CHECKING:
    from stpik_motion_planner.planning.stpik import StpikResult

MAX_KEYS = 256  # (start, path, settings) kept, least recently used first out: a bound on memory, not on answers
MAX_PER_KEY = 4  # checks kept per key (obstacle sets that differ near the path)


@dataclasses.dataclass
class Checked:
    """One STPIK check as run: its obstacles, the moving capsules' boxes at each evaluated step, the broad-phase
    distance, the result, and the configuration the last step evaluated (the Kinematics state it left)."""

    items: list[Obstacle]
    lo: np.ndarray  # (evaluated steps x moving capsules) x 3
    hi: np.ndarray
    d_act: float
    result: StpikResult
    q_last: np.ndarray


class TrackMemo:
    """Checks by (start, path, settings), each reused for an obstacle set as the module docstring says."""

    def __init__(self) -> None:
        self.checks: OrderedDict[tuple, list[Checked]] = OrderedDict()
        self.hits = 0
        self.misses = 0

    def clear(self) -> None:
        """Forget every check (a new scene)."""
        self.checks.clear()

    @staticmethod
    def key(params: object, q0: np.ndarray, path: Sequence[np.ndarray], *settings: object) -> tuple:
        """What a check is a function of besides its obstacles: the STPIK parameters, start, path and settings."""
        parts: list[Any] = [dataclasses.astuple(params), q0.tobytes()]  # type: ignore[call-overload]
        parts += [(len(w), w.tobytes()) for w in path]
        for s in settings:
            parts.append(s.tobytes() if isinstance(s, np.ndarray) else
                         tuple(sorted((k, tuple(sorted(v))) for k, v in s.items())) if isinstance(s, dict) else s)
        return tuple(parts)

    def get(self, key: tuple, obs: ObstacleSet) -> Checked | None:
        """A check of `key` valid for `obs` (the module docstring), or None."""
        for c in self.checks.get(key, ()):
            if c.items is obs.items or same_near(c, obs.items):
                self.checks.move_to_end(key)
                self.hits += 1
                return c
        self.misses += 1
        return None

    def put(self, key: tuple, check: Checked) -> None:
        """Keep `check` (the oldest keys and checks dropped beyond MAX_KEYS and MAX_PER_KEY)."""
        kept = self.checks.setdefault(key, [])
        kept.insert(0, check)
        del kept[MAX_PER_KEY:]
        self.checks.move_to_end(key)
        while len(self.checks) > MAX_KEYS:
            self.checks.popitem(last=False)


def same_near(c: Checked, items: list[Obstacle]) -> bool:
    """Whether a check run with c.items sees the same pairs at every step with `items`: the shared obstacles in the
    same order, and each obstacle of one set only beyond c.d_act of every evaluated step's capsule boxes."""
    old = {id(o) for o in c.items}
    new = {id(o) for o in items}
    if [id(o) for o in c.items if id(o) in new] != [id(o) for o in items if id(o) in old]:
        return False
    diff = [o for o in items if id(o) not in old] + [o for o in c.items if id(o) not in new]
    if not diff:
        return True
    lo = np.array([o.lo for o in diff])
    hi = np.array([o.hi for o in diff])
    gap = np.maximum(np.maximum(lo[None] - c.hi[:, None], c.lo[:, None] - hi[None]), 0.0)
    # near_pairs' test (gap^2 < d_act^2), with a margin for rounding: a pair it could let through is never missed
    return not bool((np.einsum("ijk,ijk->ij", gap, gap) < c.d_act * c.d_act * (1.0 + 1e-6) + 1e-12).any())
