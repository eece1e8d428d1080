"""Tight starts (docs/motion_planner.md, "Tight starts"): a bottle whose model on the hand stands closer to a neighbour
than the carried bottle's bound or the Cartesian planner's inflation is still carried away (lifted straight up and
drawn back, it only moves away), with a bound never under MIN_START_BOUND; a hand-placed layout of paper_random5_02
(every bottle moved <= 12 mm, jitter seed 0: o3 stands 7.6 mm from o5) was refused before ("no Cartesian path out
of the shelf")."""
from __future__ import annotations

import pytest

from relocation_app.evaluation.make_scenes import make_jitter
from relocation_common.feasibility import Label
from relocation_common.scenario import load_scenario
from stpik_motion_planner.feasibility import MIN_START_BOUND, MotionPlanner, PlannerParams


@pytest.fixture(scope="module")
def planner(tmp_path_factory):
    (path,) = make_jitter("paper_random5/paper_random5_02", 0.012, [0], tmp_path_factory.mktemp("jitter"))
    return MotionPlanner(load_scenario(path), PlannerParams.load())


def test_a_bottle_standing_close_to_a_neighbour_is_carried_away(planner):
    assert planner.params.certify_relocation  # the answer stands for the carry, retreat and way home too
    answer = planner.feasibility("o3", frozenset({"o1"}))
    assert answer.label == Label.OBSTACLE, answer.message
    segments = planner.plan_carry("o3", {"o1"}, 1)
    assert [s.name for s in segments] == ["carry", "retreat"]


def test_a_lift_from_closer_than_the_bound_keeps_the_start_distance(tmp_path):
    """Jitter seed 1: o3's model at the grasp stands 3.5 mm from a neighbour, under the 5 mm bound: before, the lift
    failed at once ("lift: clearance bound violated (-0.0015)")."""
    import numpy as np

    from stpik_motion_planner.collision import CARRIED

    (path,) = make_jitter("paper_random5/paper_random5_02", 0.012, [1], tmp_path)
    mp = MotionPlanner(load_scenario(path), PlannerParams.load())
    answer = mp.feasibility("o3", frozenset({"o1"}))
    assert answer.label == Label.OBSTACLE, answer.message
    obs = mp.scene.obstacles(frozenset({"o1", "o3"}))
    q = np.asarray(mp._pick_end[("o3", frozenset({"o1"}))])
    _, arm_start, arm_in = mp._carried_models(mp.scenario.object("o3"), q, obs,
                                              {CARRIED: frozenset(["board:top_shelf"])})
    start, full = arm_start.specs[-1].clearance, arm_in.specs[-1].clearance
    assert full == mp.params.carried_clearance and MIN_START_BOUND <= start < full
