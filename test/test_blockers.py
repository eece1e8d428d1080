"""The motion planner's lane blockers (stpik_motion_planner.model.blockers) and the blocker A* on the real planner:
the blockers are the grasp/approach screen exactly, and the A* proves the same optimum as uniform-cost search in
far fewer planner calls (docs/motion_planner.md, "Blockers")."""
import json
import random
import subprocess
import sys

import pytest

from qtree_task_planner.oracles import CachedOracle
from qtree_task_planner.search import astar, exact
from relocation_common.feasibility import Label
from relocation_common.paths import scenarios_dir
from relocation_common.scenario import load_scenario
from stpik_motion_planner.model import blockers
from stpik_motion_planner.planning.params import PlannerParams
from stpik_motion_planner.planning.pick import candidates
from stpik_motion_planner.planning.planner import MotionPlanner


@pytest.fixture(scope="module")
def planners():
    out = {}

    def get(name):
        if name not in out:
            out[name] = MotionPlanner(load_scenario(scenarios_dir() / f"{name}.yaml"), PlannerParams.load())
        return out[name]
    return get


@pytest.mark.parametrize("name", ["scenario3_15", "paper_experiment_10"])
def test_lane_blockers_are_the_screen(planners, name):
    """A lane passes pick.candidates with `removed` gone exactly when its blockers are all removed."""
    mp = planners(name)
    ids = [b.id for b in mp.scenario.objects]
    rnd = random.Random(5)
    checked = 0
    for _ in range(60):
        removed = frozenset(rnd.sample(ids, rnd.randint(0, len(ids) // 2)))
        lanes = blockers.lane_blockers(mp, removed)
        assert set(lanes) == set(ids) - removed
        for o in lanes:
            screen = {round(g.yaw, 6) for g in candidates(mp, o, mp.scene.obstacles(removed))}
            clear = {round(g.yaw, 6) for g, bl in blockers.static_lanes(mp, o) if bl <= removed}
            assert screen == clear, (o, sorted(removed))
            assert all(b.certain and not b.objects & removed for b in lanes[o])
            checked += 1
    assert checked > 300


def test_scenario3_15_target_lanes(planners):
    lanes = blockers.lane_blockers(planners("scenario3_15"))
    target = {b.lane: b.objects for b in lanes["T"]}
    # a lane per approach yaw of both tiers (5 up to 0.5 rad, then 9 up to 0.8; config/motion_planner.yaml) that
    # boards and reach leave open: -0.50, -0.60 and +-0.80 have none; +0.60 is the one without o4 and o10
    assert target == {"yaw +0.00": {"o4", "o9", "o10"}, "yaw +0.25": {"o3", "o4", "o9", "o10"},
                      "yaw -0.25": {"o4", "o9", "o10"}, "yaw +0.50": {"o3", "o9", "o10", "o14"},
                      "yaw +0.20": {"o3", "o4", "o9", "o10"}, "yaw -0.20": {"o4", "o9", "o10"},
                      "yaw +0.40": {"o3", "o4", "o9", "o10"}, "yaw -0.40": {"o4", "o5", "o9", "o10"},
                      "yaw +0.60": {"o3", "o8", "o9", "o14"}}
    assert lanes["o6"] == ()  # no lane any removal clears
    # front row: free but for the widest yaw, where o2 stands in the hand's way
    assert {b.lane for b in lanes["o1"] if b.objects} == {"yaw -0.80"}


@pytest.mark.parametrize("name", ["scenario1_5", "paper_experiment_10", "scenario2_10"])
def test_astar_on_the_real_planner_matches_uniform_cost(planners, name):
    mp = planners(name)
    a, u = CachedOracle(mp), CachedOracle(mp)
    ra, ru = astar.solve(mp.scenario, a), exact.solve(mp.scenario, u)
    assert ra.found and ra.total_weight == pytest.approx(ru.total_weight)
    assert ra.oracle_calls == a.calls < u.calls


def test_scenario3_15_optimum_in_at_most_50_calls(planners):
    mp = planners("scenario3_15")
    cache = CachedOracle(mp)
    r = astar.solve(mp.scenario, cache)
    # o3 o9 o8 o14 T through the second tier's lane +0.60 (o3 o4 o9 o10 T, 2.12, with the first tier alone)
    assert r.sequence is not None and set(r.sequence) == {"o3", "o8", "o9", "o14", "T"}
    assert r.total_weight == pytest.approx(1.31) and cache.calls <= 50


def test_unfeasible_answers_name_their_blockers(planners):
    mp = planners("paper_experiment_10")
    a = mp.feasibility("T", frozenset())
    assert a.label == Label.UNFEASIBLE and a.blockers and all(b.certain for b in a.blockers)
    assert a.blockers == mp.lane_blockers(frozenset())["T"]
    assert mp.feasibility("o1", frozenset()).blockers == ()  # feasible: nothing to name
    removed = frozenset({"o2"})
    assert mp.lane_blockers(removed)["T"] == mp.feasibility("T", removed).blockers


def test_an_stpik_failure_is_uncertain(planners, monkeypatch):
    """A lane the screen passes but the STPIK check rejects: an uncertain set (the bottles near it)."""
    mp = planners("paper_experiment_10")
    monkeypatch.setattr(mp, "track", lambda *a, **k: type("R", (), {"ok": False, "reason": "test"})())
    a = mp.feasibility("o1", frozenset())
    # every lane the screen passes is uncertain; the one it does not (yaw -0.80, o2 in the way) stays certain
    assert a.label == Label.UNFEASIBLE and any(not b.certain for b in a.blockers)
    assert all(b.objects for b in a.blockers if b.certain)
    assert all("o1" not in b.objects for b in a.blockers)


def test_cli_solves_on_the_planner_by_default():
    p = subprocess.run([sys.executable, "-m", "relocation_app.cli", "solve", "--scenario", "scenario1_5"],
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    r = json.loads(p.stdout)
    assert r["oracle"] == "planner" and r["solver"] == "astar" and r["found"] and r["planner_calls"] >= 1
    assert "real oracle calls" in p.stderr.splitlines()[-1]
