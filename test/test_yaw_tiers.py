"""The second yaw tier (docs/motion_planner.md, "A wider grasp set"): yaws tried only for a question the first tier
cannot answer, leaving every first-tier answer as it was; on a perturbed random5_06 (bottles moved <= 12 mm,
`scenes jitter`, seed 0) T's last pick has no first-tier lane at all and is planned at yaw +0.60."""
import dataclasses

import numpy as np
import pytest
import yaml

from relocation_app.evaluation.scenes.jitter import jitter_scene
from relocation_common.feasibility import Label
from relocation_common.paths import scenarios_dir
from relocation_common.scenario import parse_scenario
from stpik_motion_planner.model.blockers import lane_blockers
from stpik_motion_planner.model.grasp import yaw_tiers
from stpik_motion_planner.planning.planner import MotionPlanner, PlannerParams


def test_the_tiers_list_each_yaw_once_straight_in_first():
    first, wide = yaw_tiers(5, 0.5, 9, 0.8)
    assert first == pytest.approx([0.0, 0.25, -0.25, 0.5, -0.5])
    assert wide == pytest.approx([0.2, -0.2, 0.4, -0.4, 0.6, -0.6, 0.8, -0.8])
    assert yaw_tiers(5, 0.5) == [first] and yaw_tiers(5, 0.5, 5, 0.5) == [first]


@pytest.fixture(scope="module")
def planners():
    data = yaml.safe_load((scenarios_dir() / "random5" / "random5_06.yaml").read_text())
    scenario = parse_scenario(jitter_scene(data, 0.012, 0), "random5_06_j12_s0")
    base = dataclasses.replace(PlannerParams.load(), wide_yaws=9, wide_max_yaw=0.8)
    return MotionPlanner(scenario, dataclasses.replace(base, wide_yaws=0)), MotionPlanner(scenario, base)


def test_the_second_tier_answers_what_the_first_cannot(planners):
    first_only, both = planners
    removed = frozenset({"o2", "o3", "o4"})
    refused = first_only.feasibility("T", removed)
    assert refused.label == Label.UNFEASIBLE and "no collision-free pre-grasp" in refused.message
    got = both.feasibility("T", removed)
    assert got.label == Label.TARGET and got.message.startswith("yaw +0.60"), got.message
    # the lane screen stands for both tiers: the lane it opens is clear with those three gone
    assert any(not b.objects and b.lane == "yaw +0.60" for b in lane_blockers(both, removed)["T"])
    assert not any(not b.objects for b in lane_blockers(first_only, removed)["T"])


def test_a_first_tier_answer_is_the_same_with_the_second_tier(planners):
    """The second tier's settings are not part of the question's seed (UNSEEDED): same labels, same trajectories."""
    first_only, both = planners
    for object_id, removed in (("o2", ()), ("o3", ("o2",)), ("o4", ("o2", "o3")), ("o1", ())):
        a, b = (p.feasibility(object_id, frozenset(removed)) for p in (first_only, both))
        assert a.label == b.label and a.message == b.message, (object_id, a.message, b.message)
        if a.trajectory is not None:
            assert np.array_equal(a.trajectory.positions, b.trajectory.positions)
