"""Honest lanes (docs/motion_planner.md, "Honest lanes"): with `screen_at_clearance` the screen's hand keeps STPIK's
own clearance, so a neighbour STPIK cannot pass at the grasp is a blocker of the lane instead of a failed STPIK
check; the lanes stay exactly the screen's answer (`_candidates`) for any removed set."""
from __future__ import annotations

import dataclasses
import random

import yaml

from relocation_app.evaluation.scenes.jitter import jitter_scene
from relocation_common.paths import resolve_scenario
from relocation_common.scenario import parse_scenario
from stpik_motion_planner.planning.planner import MotionPlanner, PlannerParams


def test_a_neighbour_within_the_clearance_blocks_the_lane_and_the_screen_stays_exact():
    data = yaml.safe_load(resolve_scenario("scenario2_10").read_text())
    sc = parse_scenario(jitter_scene(data, 0.012, 0))  # T's neighbour o10 closer than STPIK's 15 mm to the hand
    params = dataclasses.replace(PlannerParams.load(), screen_at_clearance=True)
    planner = MotionPlanner(sc, params)
    lanes = planner.lane_blockers()
    assert lanes["T"] and all("o10" in b.objects for b in lanes["T"])
    answer = planner.feasibility("T", frozenset({"o3", "o6", "o7"}))
    assert answer.attempts == 0 and all(b.certain and "o10" in b.objects for b in answer.blockers)
    rng = random.Random(0)
    others = [o.id for o in sc.objects if o.id != "T"]
    for _ in range(20):
        removed = frozenset(rng.sample(others, rng.randint(0, len(others))))
        clear = {b.lane for b in planner.lane_blockers(removed)["T"] if not b.objects}
        cands = {f"yaw {g.yaw:+.2f}" for g in planner._candidates("T", planner.scene.obstacles(removed))}
        assert clear == cands, removed
