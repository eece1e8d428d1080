"""A lane whose straight approach passes between obstacles nearer on both sides than STPIK's activation distance
(stpik.clearance + stpik.act) is skipped before its path is planned (model/approach.py): scenario3_15's o15 at yaw
+0.40 passes between the target T (15.6 mm from the hand: the screen's 15 mm lets it through) and o11, STPIK holds
the fingers 19 mm from both and stops 31 mm short, on every attempt. A lane STPIK tracks is not skipped."""
from __future__ import annotations

import time

import numpy as np
import pytest

from relocation_common import robot_description as rd
from relocation_common.feasibility import Label
from relocation_common.scenario import load_scenario
from stpik_motion_planner.model.approach import squeezed_approach
from stpik_motion_planner.model.collision import HandProxy, approach_skip
from stpik_motion_planner.planning.params import PlannerParams
from stpik_motion_planner.planning.pick import candidates, cartesian_path
from stpik_motion_planner.planning.planner import MotionPlanner
from stpik_motion_planner.planning.results import QueryStats

NARROW = frozenset({"o1", "o4", "o10"})  # o15's only clear lane: yaw +0.40, between T and o11
OPEN = frozenset({"o1", "o2", "o4", "o5", "o10", "o11"})  # o15 feasible at yaw +0.00


@pytest.fixture(scope="module")
def planner() -> MotionPlanner:
    return MotionPlanner(load_scenario("scenario3_15"), PlannerParams.load())


def test_a_lane_too_narrow_for_stpik_is_skipped_with_its_reason_before_any_planning(planner):
    t = time.process_time()
    answer = planner.feasibility("o15", NARROW)
    spent = time.process_time() - t
    stats = planner.last_stats
    assert answer.label == Label.UNFEASIBLE and answer.attempts == 6
    assert "yaw +0.40" in answer.message and "activation distance" in answer.message
    assert "bottle:T" in answer.message and "bottle:o11" in answer.message
    assert stats.rrt_calls == 0 and stats.stpik_time == 0.0 and not stats.stpik_reject  # nothing planned or tracked
    print(f"o15 answered in {spent * 1000:.0f} ms CPU: {answer.message}")


def test_the_skipped_lane_is_one_stpik_stops_on(planner):
    """The pick's own steps on the lane the planner skips: the path to the pre-grasp tracks, the approach does not."""
    obs, p = planner.scene.obstacles(NARROW), planner.params
    (lane,) = candidates(planner, "o15", obs)
    stats, deadline = QueryStats(), time.perf_counter() + 300.0
    path = cartesian_path(planner, planner.home, lane.pre_grasp, obs, planner.hand, p.rrt_max_checks, deadline, stats,
                          False, planner.question_rng("pick", "o15", NARROW))
    r1 = planner.track(rd.Q_HOME, path, obs, deadline, stats)
    assert r1.ok
    r2 = planner.track(r1.q[-1], [np.array(lane.pre_grasp), np.array(lane.grasp)], obs, deadline, stats,
                       approach_skip(planner.scenario.object("o15")), speed=p.stpik.approach_speed,
                       yaw_tol=p.stpik.grasp_yaw_tol)
    assert not r2.ok and "tracking failed" in r2.reason, r2.reason


# feasible answers of scenario3_15 (the task planner's training) whose lane passes one obstacle within the band: the
# hand shifts away from it, so one side is no squeeze
ONE_SIDED = [("o12", frozenset({"o2", "o7"}), -0.4, "bottle:o13"),
             ("o9", frozenset({"o4", "o5", "o10"}), -0.8, "bottle:o3"),
             ("o11", frozenset({"o1", "o2", "o5"}), 0.0, "board:side_left")]


def test_a_lane_stpik_tracks_is_not_skipped(planner):
    answer = planner.feasibility("o15", OPEN)
    assert answer.label == Label.OBSTACLE and answer.message.startswith("yaw +0.00")
    for object_id, removed, yaw, near in ONE_SIDED:
        obs = planner.scene.obstacles(removed)
        lane = next(g for g in candidates(planner, object_id, obs) if abs(g.yaw - yaw) < 1e-9)
        band = planner.params.stpik.clearance + planner.params.stpik.act
        hits = HandProxy(band).path_hits([lane.pre_grasp, lane.grasp], obs, planner.params.resolution,
                                         approach_skip(planner.scenario.object(object_id)))
        assert [obs.items[k].name for k in hits] == [near]  # within the band, on one side
        assert squeezed_approach(lane, obs, approach_skip(planner.scenario.object(object_id)), band,
                                 planner.params.resolution, planner.params.stpik.final_tol_pos) == ""
        answer = planner.feasibility(object_id, removed)
        assert answer.label == Label.OBSTACLE and answer.message.startswith(f"yaw {yaw:+.2f}"), answer.message
