"""The admission rule of the drawn scenes (docs/scenarios.md, "Admission"): a layout is kept only when it meets the
scene's stated purpose, and the first seed (in an order fixed before any result) whose layout does is kept.

A purpose is a property of the scene, not of the code under test: what the scene is for (`Purpose`). Every purpose
here asks that the target be retrievable as the system will see the scene at run time: the planners know every
object on the shelf, the scenario's unlisted ones included (perception or the simulator's ground truth gives them,
with their weight estimated), so the check lists them (`planners_view`). `judge` decides, cheapest test first:

1. `hidden` (purposes that ask for it): the unlisted objects show no pixel to the camera with the arm at home.
2. The lane screen (stpik_motion_planner.model.blockers, no motion planning): the exact blocker A*
   (qtree_task_planner.search.astar) on an oracle answering from the lanes alone (`LaneScreen`). The real planner
   refuses every relocation the screen refuses (the screen is step 1 of its feasibility), so a layout with no
   sequence here has none at all: a blocking cycle, or a target without a lane.
3. `unlisted_in_every_lane` (purposes that ask for it): every lane of the target holds an unlisted object, so a
   retrieval must relocate one (and the planner must know it to avoid it).
4. The exact blocker A* with the real motion planner (config/motion_planner.yaml, the evaluation's safety net):
   it proves the least-weight sequence (Eq. 8) or that there is none.
5. The optimum fits the bottom shelf's slots (world.check_capacity: every relocated object takes one).
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any, Mapping

from qtree_task_planner.executive.world import check_capacity
from qtree_task_planner.oracles import CachedOracle
from qtree_task_planner.problem import RelocationProblem
from qtree_task_planner.search import astar
from relocation_common.feasibility import BlockerSet, FeasibilityAnswer, Label
from relocation_common.scenario import Scenario, parse_scenario

RETRIEVABLE = ("the target is retrievable (the exact blocker A*, qtree_task_planner/search/astar.py, with the real "
               "motion planner proves a sequence, every object on the shelf known to the planner)")


@dataclass(frozen=True)
class Purpose:
    """What a scene is for, stated in its header: `text`, and the checks it asks beyond retrievability."""

    text: str
    unlisted_in_every_lane: bool  # every lane of the target holds an unlisted object
    hidden: bool  # the unlisted objects show no pixel to the camera at home, every listed one shows some


@dataclass(frozen=True)
class Verdict:
    """A layout judged by `judge`: admitted, or the stage that refused it and why; the optimum when proven."""

    admitted: bool
    stage: str  # "" (admitted), "fit", "hidden", "screen", "unlisted", "planner" or "slots"
    reason: str
    sequence: tuple[str, ...] | None  # the proven optimum, the target last
    weight: float | None  # its weight (Eq. 8)
    planner_calls: int  # real motion planner calls of the A*
    seconds: float

    def to_dict(self) -> dict[str, Any]:
        """For the log (one JSON line per seed)."""
        return {"admitted": self.admitted, "stage": self.stage, "reason": self.reason,
                "sequence": list(self.sequence) if self.sequence else None, "weight": self.weight,
                "planner_calls": self.planner_calls, "seconds": round(self.seconds, 2)}


def refused(stage: str, reason: str, t0: float, calls: int = 0) -> Verdict:
    """A refusal at `stage` (module docstring) with its reason."""
    return Verdict(False, stage, " ".join(reason.split()), None, None, calls, time.perf_counter() - t0)


class LaneScreen:
    """A feasibility oracle answering from the grasp lanes alone (certain blocker sets with every object present):
    an object is relocatable once all objects of one of its lanes are removed. No motion planning."""

    def __init__(self, lanes: Mapping[str, tuple[BlockerSet, ...]], target: str) -> None:
        self.lanes = {o: tuple(b.objects for b in sets) for o, sets in lanes.items()}
        self.target = target

    def feasibility(self, object_id: str, removed: frozenset[str]) -> FeasibilityAnswer:
        """g_T / g_O once a lane is clear, else g_U with the lanes' remaining blockers (certain)."""
        lanes = self.lanes[object_id]
        if any(b <= removed for b in lanes):
            return FeasibilityAnswer(Label.TARGET if object_id == self.target else Label.OBSTACLE)
        return FeasibilityAnswer(Label.UNFEASIBLE, message="lane screen: every lane blocked",
                                 blockers=tuple(BlockerSet(b - removed) for b in lanes))

    def lane_blockers(self, removed: frozenset[str]) -> dict[str, tuple[BlockerSet, ...]]:
        """Every object not removed -> its lanes without `removed` (an empty tuple: no lane)."""
        return {o: tuple(BlockerSet(b - removed) for b in ls) for o, ls in self.lanes.items() if o not in removed}


def planners_view(data: Mapping[str, Any]) -> Scenario:
    """The scene as the planners see it at run time: every object, the unlisted ones included (listed false, their
    weight estimated as perception does)."""
    sc = parse_scenario(dict(data), str(data["name"]))
    return sc.with_objects(sc.world)


def unlisted_gaps(sc: Scenario, lanes: Mapping[str, tuple[BlockerSet, ...]]) -> str:
    """'' when every lane of the target holds an unlisted object of `sc`, else the first lane that does not."""
    unlisted = {o.id for o in sc.objects if not o.listed}
    mine = lanes.get(sc.target_id, ())
    if not mine:
        return f"{sc.target_id} has no lane"
    for b in mine:
        if not b.objects & unlisted:
            return f"lane {b.lane} of {sc.target_id} ({{{', '.join(sorted(b.objects))}}}) holds no unlisted object"
    return ""


def judge(data: Mapping[str, Any], purpose: Purpose, params: Any) -> Verdict:
    """Whether the drawn scene `data` meets `purpose` (module docstring: the checks in order, cheapest first).
    `params`: the motion planner's (feasibility_cache.planner_params)."""
    from relocation_app.evaluation.feasibility_cache import worker_planner
    from stpik_motion_planner.model.grasp import WorkspaceError
    t0 = time.perf_counter()
    if purpose.hidden:
        why = hidden(data)
        if why:
            return refused("hidden", why, t0)
    sc = planners_view(data)
    problem = RelocationProblem.from_bottles(sc.objects)
    try:
        planner = worker_planner(sc, params)
        lanes = planner.lane_blockers(frozenset())
        screened = astar.solve(problem, LaneScreen(lanes, sc.target_id))
        if screened.sequence is None:
            return refused("screen", screened.reason, t0)
        if purpose.unlisted_in_every_lane:
            why = unlisted_gaps(sc, lanes)
            if why:
                return refused("unlisted", why, t0)
        oracle = CachedOracle(planner)
        found = astar.solve(problem, oracle)
    except WorkspaceError as e:
        return refused("planner", f"out of reach: {e}", t0)
    if found.sequence is None:
        return refused("planner", found.reason, t0, oracle.calls)
    full = check_capacity(found.sequence, len(sc.slots))
    if full:
        return refused("slots", f"optimum {' '.join(found.sequence)}: {full}", t0, oracle.calls)
    return Verdict(True, "", "", tuple(found.sequence), found.total_weight, oracle.calls, time.perf_counter() - t0)


HIDDEN_MIN_PIXELS = 250  # a listed object this many pixels or more is visible (test_sim_core's bound)


def hidden(data: Mapping[str, Any]) -> str:
    """'' when the unlisted objects show no pixel to the driver's camera with the arm at home and every listed one
    shows at least HIDDEN_MIN_PIXELS (jaco2_sim_driver.camera.visible_pixels), else what is seen or not."""
    from jaco2_sim_driver.camera import visible_pixels
    sc = parse_scenario(dict(data), str(data["name"]))
    pixels = visible_pixels(sc)
    seen = [f"{o.id} shows {pixels[o.id]} px" for o in sc.unlisted if pixels[o.id] > 0]
    lost = [f"{o.id} shows only {pixels[o.id]} px" for o in sc.objects if pixels[o.id] < HIDDEN_MIN_PIXELS]
    return "; ".join(seen + lost)
