"""STPIK checks reused across questions (stpik_motion_planner/planning/stpik.py, TrackMemo) give the answers of
checks run afresh: the same labels, attempts, messages, near sets and trajectories, bit for bit.

The questions are fixed before any answer: every object of scenario3_15 with removed sets drawn by a seeded
generator, several per object (the reuse happens between questions about one object), and each object again with its
nearest neighbours removed and not (obstacles beside the path: where a reuse that ignored them would be wrong).
"""
from __future__ import annotations

import dataclasses
import random

import numpy as np
import pytest

from relocation_common import robot_description as rd
from relocation_common.scenario import load_scenario
from stpik_motion_planner.planning.params import PlannerParams
from stpik_motion_planner.planning.pick import candidates, front_of_shelf
from stpik_motion_planner.planning.planner import MotionPlanner
from stpik_motion_planner.planning.stpik import TrackMemo, same_near

SCENE = "scenario3_15"


def _questions(sc) -> list[tuple[str, frozenset[str]]]:
    rng = random.Random(7)
    out = []
    for oid in sc.ids:
        others = [i for i in sc.obstacle_ids if i != oid]
        o = sc.object(oid)
        near = sorted(others, key=lambda i: (sc.object(i).x - o.x) ** 2 + (sc.object(i).y - o.y) ** 2)[:3]
        sets = [frozenset(near), frozenset(near[:2]), frozenset(near[:1]), frozenset()]  # the neighbours come back
        sets += [frozenset(rng.sample(others, rng.randint(1, 4))) for _ in range(3)]
        out += [(oid, s) for s in sets]
    return out


def _answer(a) -> tuple:
    t = a.trajectory
    traj = None if t is None else (t.times.tobytes(), t.positions.tobytes(), t.velocities.tobytes(), repr(t.phases))
    return (int(a.label), a.attempts, a.message, sorted(a.near or ()),
            [(sorted(b.objects), b.certain, b.lane) for b in a.blockers], traj)


class _Keeping(dict):
    """A cache that keeps nothing."""

    def __setitem__(self, key, value) -> None:
        pass


@pytest.fixture(scope="module")
def planners():
    sc = load_scenario(SCENE)
    params = dataclasses.replace(PlannerParams.load(), certify_relocation=False)
    reusing = MotionPlanner(sc, params)
    fresh = MotionPlanner(sc, params)
    fresh.stpik.memo = None  # nothing kept: every check run, every near set computed
    fresh.near_cache = _Keeping()
    return sc, reusing, fresh


def test_reused_checks_give_the_fresh_answers(planners):
    sc, reusing, fresh = planners
    qs = _questions(sc)
    got = [_answer(reusing.feasibility(o, r)) for o, r in qs]
    memo = reusing.stpik.memo
    assert memo.hits >= 10, f"the question set exercises reuse: {memo.hits} hits, {memo.misses} misses"
    want = [_answer(fresh.feasibility(o, r)) for o, r in qs]
    bad = [(qs[k], g[:3], w[:3]) for k, (g, w) in enumerate(zip(got, want)) if g != w]
    assert not bad, f"{len(bad)} of {len(qs)} answers differ from checks run afresh, first: {bad[0]}"


def test_checks_whose_neighbour_matters(planners):
    """The direct path to each lane of each object, checked with one of the object's three nearest bottles removed,
    then with it back: by a Stpik with a memo and by one without. The bottle changes the fresh check in some of
    them (the case a reuse must refuse); the memo's results are the fresh ones in all of them."""
    sc, reusing, fresh = planners
    memo, differ, n = TrackMemo(), 0, 0
    stpik, kept = reusing.stpik, reusing.stpik.memo
    stpik.memo = memo
    try:
        for oid in sc.ids:
            o = sc.object(oid)
            others = sorted((i for i in sc.ids if i != oid), key=lambda i: (sc.object(i).x - o.x) ** 2 +
                            (sc.object(i).y - o.y) ** 2)
            for nb in others[:3]:
                without, full = reusing.scene.obstacles(frozenset([nb])), reusing.scene.obstacles(frozenset())
                for g in candidates(reusing, oid, without)[:2]:
                    path = [reusing.home, front_of_shelf(reusing, g.pre_grasp), np.asarray(g.pre_grasp)]
                    for obs in (without, full):
                        got, want = (s.track(rd.Q_HOME, path, obs, 1e18) for s in (stpik, fresh.stpik))
                        assert (got.ok, got.reason, got.q.tobytes(), got.qdot.tobytes(), got.min_clearance) == \
                            (want.ok, want.reason, want.q.tobytes(), want.qdot.tobytes(), want.min_clearance), \
                            f"{oid} lane {g.yaw:+.2f} with {nb} {'back' if obs is full else 'removed'}"
                        n += 1
                    a, b = (fresh.stpik.track(rd.Q_HOME, path, obs, 1e18) for obs in (without, full))
                    differ += a.q.tobytes() != b.q.tobytes()
    finally:
        stpik.memo = kept
    assert differ, f"no neighbour changed any of the {n} checks: the test shows nothing"
    assert memo.hits, "some check was reused"


def test_an_obstacle_near_the_path_is_not_ignored(planners):
    """A check run with the bottle nearest the object removed is not reused once that bottle stands there (it comes
    near the arm at some step of a check, so same_near refuses that one), and is reused for the farthest bottle
    (near no step)."""
    sc, reusing, _ = planners
    memo = TrackMemo()
    reusing.stpik.memo, kept = memo, reusing.stpik.memo
    try:
        for oid in sc.ids:  # the first object whose pick runs an STPIK check
            o = sc.object(oid)
            others = sorted((i for i in sc.ids if i != oid), key=lambda i: (sc.object(i).x - o.x) ** 2 +
                            (sc.object(i).y - o.y) ** 2)
            nearest, farthest = others[0], others[-1]
            reusing.feasibility(oid, frozenset([nearest, farthest]))
            checks = [c for cs in memo.checks.values() for c in cs]
            if checks:
                break
        else:
            pytest.fail(f"no pick of {SCENE} runs an STPIK check")
        full = reusing.scene.obstacles(frozenset())
        by_id = {o.object_id: o for o in full.items}
        assert any(not same_near(c, full.items) for c in checks), f"{nearest} comes near a check of {oid}"
        only_far = [o for o in full.items if o is not by_id[nearest]]
        assert all(same_near(c, only_far) for c in checks), f"{farthest} comes near no check of {oid}"
    finally:
        reusing.stpik.memo = kept


def test_a_reused_result_is_a_copy(planners):
    """What the memo keeps is never handed out: a caller that changes its result changes no later answer."""
    sc, reusing, _ = planners
    stpik, obs = reusing.stpik, reusing.scene.obstacles(frozenset())
    path = [reusing.home, reusing.home + np.array([0.0, 0.0, 0.02, 0.0])]
    a = stpik.track(rd.Q_HOME, path, obs, 1e18)
    a.q[:] = 0.0
    hits = stpik.memo.hits
    b = stpik.track(rd.Q_HOME, path, obs, 1e18)
    assert stpik.memo.hits == hits + 1
    assert b.ok and np.any(b.q != 0.0)


def test_the_seed_follows_a_changed_parameter_and_scene(planners):
    """question_rng keeps the scene-and-parameters part of its seed (PlanningContext.seed_scene): a parameter
    changed in place, or another scene, gives the seed a planner built with them gives."""
    sc, reusing, _ = planners
    def draw(mp: MotionPlanner) -> int:
        rng = mp.question_rng("pick", sc.target_id, frozenset())
        assert rng is not None
        return int(rng.integers(1 << 62))

    before = draw(reusing)
    reusing.params.rrt_max_checks += 1
    try:
        changed = draw(reusing)
        assert changed != before
        assert changed == draw(MotionPlanner(sc, dataclasses.replace(reusing.params)))
    finally:
        reusing.params.rrt_max_checks -= 1
    assert draw(reusing) == before
    moved = dataclasses.replace(sc, objects=tuple(dataclasses.replace(o, x=o.x + 0.001) if o.id == sc.target_id
                                                  else o for o in sc.objects), _by_id={})
    fresh = MotionPlanner(moved, dataclasses.replace(reusing.params))
    reusing.set_scenario(moved)
    try:
        assert draw(reusing) == draw(fresh) != before
    finally:
        reusing.set_scenario(sc)
