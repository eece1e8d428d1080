"""Reuse across answers is safe (relocation_common.feasibility, "Reuse"; near_objects in
stpik_motion_planner/planning/context.py), checked against the project's MuJoCo model by the independent checker
(test/motion_checker.py), nothing of the planner's collision model used:

- every bottle the replayed pick comes near in MuJoCo (closer than reuse_distance less the models' difference) is in
  the answer's near set;
- a pick planned with every bottle far from it removed, replayed with all of them back (the reuse rule holds: no near
  bottle removed then), touches nothing but its bottle;
- control: the same rule without the near set would reuse the target's pick, planned with its blockers removed, in a
  scene where one blocker still stands: MuJoCo sees the contact.
"""
from __future__ import annotations

import mujoco
import numpy as np
from motion_checker import MotionChecker, Report

from relocation_common.feasibility import Label, reuses
from relocation_common.scenario import load_scenario
from stpik_motion_planner.planning.params import PlannerParams
from stpik_motion_planner.planning.planner import MotionPlanner

MODELS = 0.015  # m: the simulator's finger bodies and the planner's capsules differ by up to about this


def planner(scene: str) -> MotionPlanner:
    return MotionPlanner(load_scenario(scene), PlannerParams.load())


def replay(scenario, answer, object_id, removed) -> tuple[Report, dict[str, float]]:
    """The pick replayed with `removed` on the bottom shelf: the checker's report and each other bottle's least
    distance to the arm (MuJoCo's signed distance, up to reuse_distance)."""
    c = MotionChecker(scenario)
    for k, oid in enumerate(sorted(removed)):
        adr = c._free[oid]
        x, y = scenario.slot(k)
        c.data.qpos[adr:adr + 3] = (x, y, scenario.shelf.bottom_z)
    mujoco.mj_kinematics(c.model, c.data)
    rep = c.check(answer.trajectory, f"{object_id}|{','.join(sorted(removed))}", picking=object_id,
                  approach_from=dict(answer.trajectory.phases)["approach"])
    reach = PlannerParams.load().reuse_distance
    least = {o: np.inf for o in c.bottle_geom if o != object_id}
    fromto = np.zeros(6)
    for q in answer.trajectory.positions[::2]:
        c.set_q(q)
        for o in least:
            for a in c.arm:
                d = mujoco.mj_geomDistance(c.model, c.data, a, c.bottle_geom[o], reach, fromto)
                least[o] = min(least[o], d)
    return rep, least


def test_a_pick_planned_without_the_far_bottles_touches_nothing_with_them_back():
    """scenario3_15, the largest shipped scene: every bottle asked with nothing removed."""
    mp = planner("scenario3_15")
    sc, checked = mp.scenario, 0
    for oid in sc.ids:
        first = mp.feasibility(oid, frozenset())
        if first.label == Label.UNFEASIBLE:
            continue
        far = frozenset(sc.ids) - first.near - {oid}
        answer = mp.feasibility(oid, far)  # the far bottles removed: planned without them
        assert answer.label != Label.UNFEASIBLE and reuses(answer, far, frozenset()), (oid, answer.message)
        rep, least = replay(sc, answer, oid, frozenset())  # all of them back on the shelf
        assert rep.contacts == [], "\n".join(map(str, rep.contacts))
        close = {o for o, d in least.items() if d < mp.params.reuse_distance - MODELS}
        assert close <= answer.near, (oid, close - answer.near)
        checked += 1
    assert checked >= 4


def test_without_its_near_set_the_rule_would_reuse_a_pick_into_a_contact():
    """paper_experiment_10's T is feasible once o2 and o6 are removed (the demo's optimum); its pick planned so,
    replayed with o2 back: the reuse rule refuses it (o2 is near), and MuJoCo shows why."""
    mp = planner("paper_experiment_10")
    removed = frozenset({"o2", "o6"})
    answer = mp.feasibility("T", removed)
    assert answer.label == Label.TARGET and {"o2", "o6"} <= answer.near
    assert not reuses(answer, removed, frozenset({"o6"}))
    rep, _ = replay(mp.scenario, answer, "T", frozenset({"o6"}))
    assert rep.contacts and any("o2" in (c.geom1 + c.geom2) for c in rep.contacts), rep.summary()
