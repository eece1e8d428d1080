"""Tight starts (docs/motion_planner.md, "Tight starts"): a bottle whose model on the hand stands closer to a neighbour
than the carried bottle's bound or the Cartesian planner's inflation is still carried away (lifted straight up and
drawn back, it never comes closer to anything than it stood), with the start distance less START_RELIEF as its
bound, whatever that distance is; a hand-placed layout of paper_random5_02 (every bottle moved <= 12 mm, jitter
seed 0: o3 stands 7.6 mm from o5) was refused before ("no Cartesian path out of the shelf")."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from relocation_app.evaluation.scenes.jitter import make_jitter
from relocation_common.feasibility import Label
from relocation_common.scenario import load_scenario
from stpik_motion_planner.model.collision import CARRIED
from stpik_motion_planner.planning.carry import START_RELIEF, carried_models
from stpik_motion_planner.planning.params import PlannerParams
from stpik_motion_planner.planning.planner import MotionPlanner


@pytest.fixture(scope="module")
def planner(tmp_path_factory):
    (path,) = make_jitter("paper_random5/paper_random5_02", 0.012, [0], tmp_path_factory.mktemp("jitter"))
    return MotionPlanner(load_scenario(path), PlannerParams.load())


def test_a_bottle_standing_close_to_a_neighbour_is_carried_away(planner):
    assert planner.feasibility("o3", frozenset({"o1"})).label == Label.OBSTACLE
    answer = planner.certify("o3", frozenset({"o1"}))  # the answer stands for the carry, retreat and way home too
    assert answer.label == Label.OBSTACLE, answer.message
    segments = planner.plan_carry("o3", {"o1"}, 1)
    assert [s.name for s in segments] == ["carry", "retreat"]


def test_a_lift_from_closer_than_the_bound_keeps_the_start_distance(tmp_path):
    """Jitter seed 1: o3's model at the grasp stands 3.5 mm from a neighbour, under the 5 mm bound: before, the lift
    failed at once ("lift: clearance bound violated (-0.0015)")."""
    (path,) = make_jitter("paper_random5/paper_random5_02", 0.012, [1], tmp_path)
    mp = MotionPlanner(load_scenario(path), PlannerParams.load())
    answer = mp.feasibility("o3", frozenset({"o1"}))
    assert answer.label == Label.OBSTACLE, answer.message
    obs = mp.scene.obstacles(frozenset({"o1", "o3"}))
    q = np.asarray(mp.pick_end[("o3", frozenset({"o1"}))])
    _, arm_start, arm_in = carried_models(mp, mp.scenario.object("o3"), q, obs,
                                          {CARRIED: frozenset(["board:top_shelf"])})
    start, full = arm_start.specs[-1].clearance, arm_in.specs[-1].clearance
    assert full == mp.params.carried_clearance and 0 < start < full


def test_a_start_in_contact_within_the_tolerances_is_lifted(tmp_path):
    """scenario1_5 with o1 put 3 mm from T (the closed-loop benchmark's K=3 seed 0 moved it to 4 mm): o1's model at
    the grasp stands 2.3 mm from T (STPIK's final tolerance), under the old floor of 2 mm + START_RELIEF, and the
    lift failed at once ("lift: clearance bound violated (-0.0027)"). The lift and the way out now keep that 2.3 mm
    less START_RELIEF: o1 is carried to its slot, and never comes closer to T than it stood."""
    sc = load_scenario("scenario1_5")
    t, d, a = sc.object("T"), 2 * 0.033 + 0.003, math.radians(140)
    params = dataclasses.replace(PlannerParams.load(), certify_relocation=False)  # the pick alone, then its carry
    mp = MotionPlanner(sc, params)
    mp.update_object("o1", t.x + d * math.cos(a), t.y + d * math.sin(a))
    removed = frozenset({"o5"})
    assert mp.feasibility("o1", removed).label == Label.OBSTACLE
    q = np.asarray(mp.pick_end[("o1", removed)])
    obs = mp.scene.obstacles(removed | {"o1"})
    support = {CARRIED: frozenset(["board:top_shelf"])}
    _, arm_start, arm_in = carried_models(mp, mp.scenario.object("o1"), q, obs, support)
    mp.kin.update(q, jacobians=False)
    arm_in.pose()
    gap = min(d for i, _, d, _, _ in arm_in.obstacle_distances(obs, 0.01, support) if arm_in.specs[i].name == CARRIED)
    assert 0 < gap < 0.0025, gap  # in contact within the tolerances: the case the old floor refused
    segments = mp.plan_carry("o1", removed, 1, q_start=q)
    assert [s.name for s in segments] == ["carry", "retreat"]
    assert arm_start.specs[-1].clearance == pytest.approx(gap - START_RELIEF)
