"""The task planner's job, ROS-free: the exact optimum, then Q-Tree training (Sect. 4.2), then the relocations.

The exact optimum comes from the blocker A* (astar.py: the planner's lane blockers bound the search, the optimum
still proven, Eq. 8) in a handful of planner calls; exact.py's uniform-cost search stays the tested reference.

The node supplies the oracle (its feasibility service behind a CachedOracle), how to get through planner outages
(`until_planner`, qtree_task_planner.outage), where to keep checkpoints, per-episode feedback and how to relocate
one object; everything else (order, what is kept when the planner goes away, when execution stops) is here.
"""
from __future__ import annotations

import dataclasses
from typing import Callable, TypeVar

from . import astar
from .checkpoint import Checkpoint
from .oracles import CachedOracle
from .outage import PlannerUnavailable
from .params import TrainingParams
from .problem import RelocationProblem
from .training import train

T = TypeVar("T")


def solve_then_train(problem: RelocationProblem, oracle: CachedOracle, params: TrainingParams, *,
                     resume: Checkpoint | None, until_planner: Callable[[Callable[[], T]], T],
                     keep: Callable[[Checkpoint], None], on_episode: Callable, checkpoint_every: int,
                     on_solved: Callable = lambda optimum: None):
    """(exact optimum, training result). The answers the exact solve gathered before an outage are kept in a
    checkpoint (`keep`), so nothing asked is asked again; training checkpoints every `checkpoint_every` episodes
    and stops when `on_episode(stats)` returns False (cancel, shutdown)."""
    state = {"ck": resume}

    def solve():
        try:
            return astar.solve(problem, oracle)
        except PlannerUnavailable as e:
            ck = state["ck"] or Checkpoint.initial(problem, params)
            state["ck"] = dataclasses.replace(ck, feasibility=Checkpoint.table_of(oracle), reason=f"interrupted: {e}")
            keep(state["ck"])
            raise

    optimum = until_planner(solve)
    on_solved(optimum)

    def on_checkpoint(ck: Checkpoint) -> None:
        state["ck"] = ck
        keep(ck)

    def run():
        return train(problem, oracle, params, optimal_weight=optimum.total_weight, callback=on_episode,
                     resume=state["ck"], checkpoint_every=checkpoint_every, on_checkpoint=on_checkpoint)

    return optimum, until_planner(run)


def execute_sequence(sequence, relocate_one: Callable[[str, list[str]], tuple[bool, str]],
                     cancelled: Callable[[], bool], before_each: Callable[[], None] = lambda: None
                     ) -> tuple[bool, str, list[str]]:
    """Relocate the learned sequence in order (the target last): (success, message, relocated ids). Stops at the
    first failure or on cancel, saying which object and why."""
    removed: list[str] = []
    for object_id in sequence:
        before_each()
        if cancelled():
            return False, f"cancelled after relocating {removed}", removed
        ok, message = relocate_one(object_id, list(removed))
        if not ok:
            return False, f"relocating {object_id!r} failed: {message}", removed
        removed.append(object_id)
    return True, f"target {sequence[-1]!r} retrieved after {len(removed) - 1} relocations", removed
