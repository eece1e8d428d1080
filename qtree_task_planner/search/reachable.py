"""Breadth-first search over removed sets: every set reachable from {} by feasible single removals.

Feasibility depends only on (object, removed set), so the sets reachable this way are exactly the states any
training (or the exact solver) can visit. One implementation for exact.brute_force (asking an oracle) and the
evaluation's feasibility cache (reading a table, filling it level by level).
"""
from __future__ import annotations

from typing import Callable, Iterable

Removable = Callable[[str, frozenset], bool]  # removable(o, s): relocating obstacle o after the set s is feasible


def next_level(level: Iterable[frozenset], obstacles: Iterable[str], removable: Removable,
               reached: dict[frozenset, tuple[str, ...]]) -> list[frozenset]:
    """The sets first reached from `level` by one feasible removal, in breadth-first order (for each set of
    `level`, obstacles in the given order). `reached` (set -> the removal sequence that first reached it) is
    updated; `removable` is asked only about sets not reached yet."""
    obstacles = tuple(obstacles)
    nxt = []
    for s in level:
        for o in obstacles:
            if o not in s and s | {o} not in reached and removable(o, s):
                reached[s | {o}] = reached[s] + (o,)
                nxt.append(s | {o})
    return nxt


def reachable_sets(obstacles: Iterable[str], removable: Removable) -> dict[frozenset, tuple[str, ...]]:
    """Every set reachable from {} by feasible single removals -> the removal sequence that first reached it,
    in breadth-first order (the empty set first)."""
    obstacles = tuple(obstacles)
    reached: dict[frozenset, tuple[str, ...]] = {frozenset(): ()}
    level: list[frozenset] = [frozenset()]
    while level:
        level = next_level(level, obstacles, removable, reached)
    return reached
