"""Feasible means executable (docs/motion_planner.md, "Determinism"): with `seed_per_query`, the execution's pick
(relocation.plan_relocation -> plan_pick) asks the planner the same question as the feasibility answer, so it gets
the answer's trajectory bit for bit, and the rest of the relocation is planned from its end. Every FEASIBLE answer
of the sample is followed by a successful plan_relocation of the same question, on a perturbed layout (scenes
jitter); with `certify_relocation` a feasible answer has planned that carry, retreat and way home already.
Larger sample: scripts/check_same_answer.py --relocate."""
from __future__ import annotations

import dataclasses

import yaml

from relocation_app.evaluation.scenes.jitter import jitter_scene
from relocation_common.paths import resolve_scenario
from relocation_common.scenario import parse_scenario
from stpik_motion_planner.execution.relocation import plan_relocation
from stpik_motion_planner.planning.planner import MotionPlanner, PlannerParams

SAMPLE = [("o3", []), ("T", ["o2", "o3", "o6"])]


def test_every_feasible_answer_is_followed_by_its_relocation_with_the_same_pick():
    data = yaml.safe_load(resolve_scenario("paper_experiment_10").read_text())
    sc = parse_scenario(jitter_scene(data, 0.012, 1))
    params = dataclasses.replace(PlannerParams.load(), seed_per_query=True, screen_at_clearance=True,
                                 certify_relocation=True, timeout=120.0, carry_timeout=120.0)
    asker, executor = MotionPlanner(sc, params), MotionPlanner(sc, params)
    feasible = 0
    for obj, removed in SAMPLE:
        answer = asker.feasibility(obj, frozenset(removed))
        if answer.trajectory is None:
            continue
        feasible += 1
        plan = plan_relocation(executor, obj, removed)  # raises PlanningError if it cannot be planned
        assert plan.pick.positions.tobytes() == answer.trajectory.positions.tobytes(), obj
    assert feasible == len(SAMPLE)
