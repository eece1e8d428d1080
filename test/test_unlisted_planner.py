"""Objects the scenario does not list, in the motion planner (stpik_motion_planner.service.update_scene,
model.scene_update, relocation_common.scene_check) and in its motions, replayed in MuJoCo by the independent checker
(test/motion_checker.py, whose world is the simulator's: the scenario's `unlisted:` objects too).

The scene comes as the simulator's ground truth publishes it (/sim/objects: jaco2_sim_driver.messages.objects_msg over
Jaco2Sim's object poses, read back by ros_conversions.msg_to_objects as the node does): the unlisted bottle x1 of
paper_experiment_10_unlisted (`listed: false`, its weight estimated). Before, scene_check refused a scene with an id
the scenario does not list and the planner dropped the whole message: it planned as if x1 were not there, and the
demo sequence's pick of T drove the fingers 34 mm into it.
"""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import yaml
from motion_checker import MotionChecker, Report, replay_relocation

from jaco2_sim_driver.messages import objects_msg, time_msg
from jaco2_sim_driver.sim import Jaco2Sim
from qtree_task_planner.problem import RelocationProblem
from qtree_task_planner.search import astar
from relocation_common.feasibility import Label
from relocation_common.ros_conversions import msg_to_objects
from relocation_common.scenario import Scenario, ScenarioError, load_scenario, parse_scenario
from relocation_common.scene_check import check_scene
from stpik_motion_planner.execution.relocation import plan_relocation
from stpik_motion_planner.planning.params import PlannerParams, node_parameters
from stpik_motion_planner.service import MotionPlannerService

PATH = "config/scenarios/world/paper_experiment_10_unlisted.yaml"
SC = load_scenario(PATH)
HIDDEN = load_scenario("config/scenarios/world/hidden_unlisted_10.yaml")  # its unlisted bottle is x1 too
# wall-clock safety nets of 300 s (answers must not depend on machine load); the work budgets are the planner's
PARAMS = dataclasses.replace(PlannerParams.load(), timeout=300.0, carry_timeout=300.0)
VARIANT_SEEDS = (0, 1, 2, 3)  # fixed before any result: x1 drawn on the front part of the top shelf


def ground_truth(sc: Scenario):
    """The scene /sim/objects publishes at the start, as the motion planner node reads it."""
    return msg_to_objects(objects_msg(sc, Jaco2Sim(sc).object_poses(), time_msg(0.0)))


def service(sc: Scenario, told: bool) -> MotionPlannerService:
    """The motion planner on `sc`, told the ground-truth scene (x1 too) or not (the scenario file only)."""
    s = MotionPlannerService(sc, PARAMS)
    if told:
        assert "x1" in s.update_scene(ground_truth(sc), "/sim/objects")
    return s


def test_a_scene_with_an_unlisted_object_is_merged_not_dropped():
    s = service(SC, told=True)
    x1 = s.planner.scenario.object("x1")
    assert not x1.listed and x1.weight_note.endswith("kg") and 0 < x1.weight <= 1
    assert "x1" in s.planner.scene.bottles  # an obstacle of the collision scene
    lanes, answer = s.feasibility("T", ["o2", "o6"], all_lanes=True)
    assert answer is not None and answer.label == Label.UNFEASIBLE
    assert answer.blockers and all(b.certain and "x1" in b.objects for b in answer.blockers), answer.blockers
    assert lanes["T"] and all("x1" in b.objects for b in lanes["T"])  # every lane of T passes x1
    assert lanes["x1"]  # a standing bottle the hand takes: relocatable (behind T or o8 here)
    s.check_goal("x1", [])  # a goal may name it; and it may be in a removed set
    with pytest.raises(ValueError, match="standing on the top shelf"):
        s.check_goal("T", ["x1"])


def test_scene_check_tells_unlisted_objects_from_unknown_listed_ids():
    objects = [(o.id, o.x, o.y, SC.shelf.top_z) for o in SC.world]
    check_scene(SC, objects, unlisted={"x1"})
    with pytest.raises(ScenarioError, match="'x1' is not in scenario .* must be marked listed: false"):
        check_scene(SC, objects)  # x1 said to be listed
    with pytest.raises(ScenarioError, match="'o3' is marked unlisted, but scenario"):
        check_scene(SC, objects, unlisted={"x1", "o3"})


def test_a_listed_bottle_not_seen_keeps_its_pose_and_an_unlisted_one_renamed_is_no_phantom():
    s = service(SC, told=True)
    truth = {o.id: o for o in ground_truth(SC)}
    renamed = dataclasses.replace(truth["x1"], id="u1")  # perception named it anew
    changed = s.update_scene([o for i, o in truth.items() if i not in ("x1", "o3")] + [renamed])
    assert changed == ["u1", "x1"]
    assert "x1" not in s.planner.scene.bottles and "u1" in s.planner.scene.bottles
    assert s.planner.scenario.object("o3") == SC.object("o3")  # listed, unseen: kept where it was
    moved = dataclasses.replace(renamed, id="u2", x=renamed.x - 0.2)  # elsewhere: u1 is kept (hidden, maybe)
    s.update_scene([*truth.values(), moved][:-2] + [moved])
    assert {"u1", "u2"} <= set(s.planner.scene.bottles)


def _variant(seed: int) -> Scenario:
    """paper_experiment_10_unlisted with x1 drawn (seeded) on the front part of the top shelf, clear of the others."""
    raw = yaml.safe_load(open(PATH))
    rng = np.random.default_rng(seed)
    while True:
        xy = [round(float(rng.uniform(0.66, 0.90)), 3), round(float(rng.uniform(-0.2, 0.2)), 3)]
        try:
            return parse_scenario(dict(raw, unlisted=[dict(raw["unlisted"][0], xy=xy)]))
        except ScenarioError:  # overlaps a listed bottle: drawn again
            continue


def _replay(sc: Scenario, told: bool) -> tuple[tuple[str, ...] | None, Report]:
    """The exact optimum (blocker A*) of the planner told or not of x1, every relocation of it planned and replayed
    in the simulator's world."""
    planner = service(sc, told).planner
    r = astar.solve(RelocationProblem.from_scenario(planner.scenario), planner)
    checker, done, rep = MotionChecker(sc), [], Report()
    for oid in r.sequence or ():
        plan = plan_relocation(planner, oid, done)
        rep.merge(replay_relocation(checker, plan.pick, [plan.carry, plan.retreat], plan.home, oid))
        done.append(oid)
    return r.sequence, rep


def _never_touched(scenes: list[Scenario]) -> list[bool]:
    """Each scene replayed told of x1 (no contact at all) and not told: whether that planner touched x1."""
    touched, found = [], 0
    for sc in scenes:
        seq, rep = _replay(sc, told=True)
        print(f"x1 at ({sc.unlisted[0].x}, {sc.unlisted[0].y}): told {seq}: {rep.summary()}")
        assert rep.contacts == [], "\n".join(map(str, rep.contacts))
        found += seq is not None
        old_seq, old = _replay(sc, told=False)
        hits = [c for c in old.contacts if "x1_geom" in (c.geom1, c.geom2)]
        print(f"  not told {old_seq}: {len(hits)} contacts with x1, deepest "
              f"{max((-c.distance for c in hits), default=0) * 1000:.1f} mm")
        touched.append(bool(hits))
    print(f"told of x1: {found} of {len(touched)} scenes retrieved, 0 contacts; not told: {sum(touched)} touch x1")
    return touched


@pytest.mark.slow
def test_planned_motions_never_touch_the_unlisted_bottle():
    """The two shipped scenes with an unlisted bottle and a seeded variant of x1's place in the first (the other
    variants: -m extended): the planner told of x1 plans nothing that touches it (nor anything else); the planner
    of the scenario file alone drives into it in both shipped scenes (34 mm in paper_experiment_10_unlisted, 2.6 mm
    in hidden_unlisted_10)."""
    touched = _never_touched([SC, HIDDEN, _variant(VARIANT_SEEDS[0])])
    assert touched[0] and touched[1], "the scenario file's planner touches x1 in both shipped scenes"


@pytest.mark.extended
def test_planned_motions_never_touch_the_unlisted_bottle_in_the_other_variants():
    _never_touched([_variant(s) for s in VARIANT_SEEDS[1:]])


def test_an_unlisted_object_perception_no_longer_publishes_leaves_the_scene_after_phantom_scenes_in_view():
    """Perception published u1 (in the front row, nothing between it and the shelf's front) and x1 (behind o2 and o6),
    then neither, nor the listed o3. After phantom_scenes scenes in a row (config/motion_planner.yaml) u1 is gone from
    the planner's scene, not before; a scene received again (same stamp) counts once; x1, hidden, and o3, listed,
    keep their last poses; one this node placed on the bottom shelf is kept. Before, u1 stayed forever: a phantom
    published once stayed in the planner's scene, an obstacle no relocation removes."""
    n = node_parameters()["phantom_scenes"]
    truth = {o.id: o for o in ground_truth(SC)}
    u1 = dataclasses.replace(truth["x1"], id="u1", x=0.67, y=0.14)  # between o3 and o4, in front
    later = [o for i, o in truth.items() if i not in ("x1", "o3")]
    for placed in (False, True):
        s = service(SC, told=False)
        assert {"u1", "x1"} <= set(s.update_scene([*truth.values(), u1], stamp=(1, 0)))
        if placed:
            s.relocated["u1"] = 0
        for k in range(n - 1):
            s.update_scene(later, stamp=(2 + k, 0))
            s.update_scene(later, stamp=(2 + k, 0))  # republished: the same scene again
        assert "u1" in s.planner.scene.bottles
        changed = s.update_scene(later, stamp=(n + 1, 0))
        assert ("u1" in changed) is not placed and ("u1" in s.planner.scene.bottles) is placed, changed
        assert "x1" in s.planner.scene.bottles and s.planner.scenario.object("o3") == SC.object("o3")
    s = service(SC, told=False)
    s.update_scene([*truth.values(), u1], stamp=(1, 0))
    s.update_scene(later, stamp=(2, 0))
    s.update_scene([*later, u1], stamp=(3, 0))  # seen again: its count starts over
    for k in range(n - 1):
        s.update_scene(later, stamp=(4 + k, 0))
    assert "u1" in s.planner.scene.bottles
