"""Disturbances of the simulated shelf on the real MuJoCo simulator core (jaco2_sim_driver.disturbance)."""
import math

import numpy as np
import pytest

import jaco2_sim_driver  # noqa: F401  (MUJOCO_GL=egl before mujoco)
from jaco2_sim_driver import disturbance as dist
from jaco2_sim_driver.sim import Jaco2Sim
from relocation_app.final_state import HOME_TOL
from relocation_common.paths import default_scenario
from relocation_common.scenario import load_scenario

SCENARIO = load_scenario(default_scenario())
TOP = SCENARIO.shelf.top_z


@pytest.fixture(scope="module")
def sim():
    return Jaco2Sim(SCENARIO)


@pytest.fixture
def fresh(sim):
    sim.reset()
    dist.restore_all_contacts(sim)
    sim.step(200)
    return sim


def _pos(sim, oid) -> np.ndarray:
    return np.asarray({p.id: p.position for p in sim.object_poses()}[oid])


def _free_bottle(sim) -> str:
    """A bottle with 2 cm of room towards -y (nothing within 2 radii + 2 cm on that side)."""
    for b in SCENARIO.objects:
        if all(o.id == b.id or math.hypot(o.x - b.x, o.y - (b.y - 0.02)) > b.radius + o.radius + 0.01
               for o in SCENARIO.objects) and b.y - 0.02 - b.radius > SCENARIO.shelf.y_min + 0.01:
            return b.id
    raise AssertionError("no bottle with room in the default scene")


def test_a_nudged_bottle_moves_by_the_amount_and_stays(fresh):
    oid = _free_bottle(fresh)
    p0 = _pos(fresh, oid)
    done = dist.nudge(fresh, oid, 0.0, -0.02)
    assert done.detail["applied"] == pytest.approx([0.0, -0.02], abs=1e-4)
    fresh.step(1000)
    assert np.allclose(_pos(fresh, oid) - p0, (0.0, -0.02, 0.0), atol=2e-3), _pos(fresh, oid) - p0
    assert dist.tilt(fresh, oid) < math.radians(2)
    for o in SCENARIO.objects:  # nothing else moved
        if o.id != oid:
            assert np.allclose(_pos(fresh, o.id), (o.x, o.y, TOP), atol=2e-3), o.id


def test_a_nudge_into_a_neighbour_stops_short_of_it(fresh):
    a, b = SCENARIO.objects[0], min(SCENARIO.objects[1:], key=lambda o: math.hypot(o.x - SCENARIO.objects[0].x,
                                                                                     o.y - SCENARIO.objects[0].y))
    d = np.array([b.x - a.x, b.y - a.y])
    done = dist.nudge(fresh, a.id, *(d * 1.5))  # would pass through b
    moved = np.asarray(done.detail["applied"])
    gap = np.linalg.norm(np.array([a.x, a.y]) + moved - (b.x, b.y)) - a.radius - b.radius
    assert 0 <= gap < dist.MARGIN + 2 * dist.PUSH_STEP, gap
    fresh.step(500)
    assert np.allclose(_pos(fresh, b.id), (b.x, b.y, TOP), atol=2e-3)


def test_a_tipped_bottle_lies_on_the_board(fresh):
    oid = _free_bottle(fresh)
    done = dist.tip(fresh, oid, direction=-math.pi / 2)
    fresh.step(1500)
    assert dist.tilt(fresh, oid) > math.radians(80), math.degrees(dist.tilt(fresh, oid))
    r = SCENARIO.object(oid).radius
    assert _pos(fresh, oid)[2] == pytest.approx(TOP + r, abs=5e-3)  # on the top board, on its side
    assert done.kind == "tip" and "direction" in done.detail


def test_move_to_puts_a_bottle_upright_where_asked_and_refuses_an_overlap(fresh):
    a, b = SCENARIO.objects[0], SCENARIO.objects[1]
    with pytest.raises(dist.DisturbanceError, match=f"overlap {b.id}"):
        dist.move_to(fresh, a.id, b.x, b.y)
    sh = SCENARIO.shelf
    spot = dist._move_somewhere(fresh, a.id, (0.0, 0.0))  # the free spot nearest the front right corner
    fresh.step(500)
    assert np.allclose(_pos(fresh, a.id), spot.detail["to"], atol=2e-3)
    assert _pos(fresh, a.id)[0] < sh.x_front + 0.1


def _hold(sim) -> str:
    """A bottle put between the open fingers at home (axis along the finger spread) and grasped."""
    oid = SCENARIO.objects[0].id
    h = SCENARIO.object(oid).height
    t = sim.ee_pose()
    spread = t[:3, 1]
    if spread[2] < 0:
        spread = -spread
    base = t[:3, 3] - 0.5 * h * spread
    z = spread
    k = np.cross([0.0, 0.0, 1.0], z)
    angle = math.acos(float(np.clip(z[2], -1, 1)))
    n = np.linalg.norm(k)
    quat = (1.0, 0.0, 0.0, 0.0) if n < 1e-9 else (math.cos(angle / 2), *(math.sin(angle / 2) * k / n))
    dist._set_pose(sim, oid, base, quat)
    assert sim.gripper_close() == oid
    sim.step(300)
    return oid


def test_a_held_bottle_stays_in_the_hand_without_a_drop(fresh):
    oid = _hold(fresh)
    fresh.step(1000)
    assert fresh.grasped == oid
    assert np.linalg.norm(_pos(fresh, oid) - fresh.ee_pose()[:3, 3]) < 0.15


def test_a_dropped_bottle_falls_out_of_the_hand(fresh):
    oid = _hold(fresh)
    z0 = _pos(fresh, oid)[2]
    done = dist.drop_grasped(fresh)
    assert done is not None and done.object_id == oid and fresh.grasped is None
    fresh.step(1500)
    assert _pos(fresh, oid)[2] < z0 - 0.2  # fell (to the floor or a board below the hand)
    assert dist.clear_of_hand(fresh, oid)
    assert dist.drop_grasped(fresh) is None  # nothing left to drop


def test_carry_dropper_drops_on_the_planned_carry_and_gives_contacts_back(fresh):
    dropper = dist.CarryDropper(carries={0}, seed=3, delay_range=(0.1, 0.2))
    oid = _hold(fresh)
    drops = []
    for _ in range(200):  # 2 s at the driver's 10 ms batches
        done = dropper.update(fresh)
        if done is not None:
            drops.append(done)
        fresh.step(10)
    assert [d.object_id for d in drops] == [oid] and drops[0].detail["carry"] == 0
    assert fresh.grasped is None and dropper._slipping is None
    g = fresh.model.geom(f"{oid}_geom").id
    assert (fresh.model.geom_contype[g], fresh.model.geom_conaffinity[g]) == (1, 3)


def test_carry_dropper_with_probability_zero_never_drops(fresh):
    dropper = dist.CarryDropper(probability=0.0)
    _hold(fresh)
    for _ in range(100):
        assert dropper.update(fresh) is None
        fresh.step(10)
    assert fresh.grasped is not None and dropper.carry == 0


def test_seeded_plans_are_reproducible_and_serialise():
    a = dist.DisturbancePlan.draw(3, seed=7, relocations=5)
    assert a == dist.DisturbancePlan.draw(3, seed=7, relocations=5)
    assert a != dist.DisturbancePlan.draw(3, seed=8, relocations=5)
    assert len(a.disturbances) == 3
    for d in a.disturbances:
        assert d.kind in dist.KINDS
        assert (d.moment == "during") == (d.kind == "drop")
        assert 0 <= d.relocation < (5 if d.kind == "drop" else 4)
    rows = a.to_list()
    assert [r["when"] for r in rows] == [d.when for d in a.disturbances]
    assert sum(len(a.at(d.moment, d.relocation)) for d in set(a.disturbances)) >= 3
    import json
    json.dumps(rows)
    with pytest.raises(ValueError, match="kinds"):
        dist.DisturbancePlan.draw(1, 0, 3, kinds=("explode",))
    assert {d.kind for d in dist.DisturbancePlan.draw(4, 0, 1).disturbances} == {"drop"}
    with pytest.raises(ValueError, match="only a drop"):
        dist.DisturbancePlan.draw(1, 0, 1, kinds=("nudge",))


def test_applying_a_plan_records_what_was_done(fresh):
    plan = dist.DisturbancePlan.draw(4, seed=1, relocations=3, kinds=("nudge", "tip", "move"))
    records = [dist.apply(fresh, d) for d in plan.disturbances]
    for r, d in zip(records, plan.disturbances):
        assert r["kind"] == d.kind and r["when"] == d.when
        assert "object" in r or "skipped" in r
    drop = dist.apply(fresh, dist.Disturbance("drop", "during", 0))
    assert drop["skipped"] == "nothing in the hand"


def test_plan_json_round_trip_and_bad_json():
    plan = dist.DisturbancePlan.draw(5, seed=11, relocations=4)
    assert dist.DisturbancePlan.from_json(plan.to_json()) == plan
    with pytest.raises(ValueError, match="not a disturbance plan"):
        dist.DisturbancePlan.from_json('{"seed": 1}')
    with pytest.raises(ValueError, match="bad entry"):
        dist.DisturbancePlan.from_json('{"seed": 1, "disturbances": [{"kind": "explode", "moment": "after", '
                                       '"relocation": 0}]}')


def _release(sim, steps: int = 300) -> None:
    sim.gripper_open()
    sim.step(steps)


def test_schedule_applies_each_disturbance_at_its_moment(fresh):
    """After relocation 1 (the first release, arm at home): a nudge; during carry 2 (after the second grasp): a
    drop; a drop planned for carry 1 whose carry passed without it being due is recorded as skipped."""
    plan = dist.DisturbancePlan(0, (dist.Disturbance("nudge", "after", 0, choice=0.99, amount=0.01),
                                    dist.Disturbance("drop", "during", 1),
                                    dist.Disturbance("drop", "during", 0)))
    schedule = dist.DisturbanceSchedule(plan, HOME_TOL, drop_delay=10.0)  # the drop of carry 1 never gets due
    assert schedule.update(fresh) == []
    _hold(fresh)  # carry 1
    assert schedule.update(fresh) == []
    _release(fresh)
    done = schedule.update(fresh)  # relocation 1 ended, the arm is at home: the nudge; carry 1's drop missed
    assert [(r["kind"], r["when"]) for r in done] == [("nudge", "after relocation 1"), ("drop", "during carry 1")]
    assert "object" in done[0] and done[1]["skipped"] == "its moment has passed"
    schedule.drop_delay = 0.2
    oid = _hold(fresh)  # carry 2
    assert schedule.update(fresh) == [] and schedule.carries == 2
    fresh.step(250)
    done = schedule.update(fresh)
    assert [(r["kind"], r["when"], r["object"]) for r in done] == [("drop", "during carry 2", oid)]
    assert fresh.grasped is None and schedule.pending == [] and len(schedule.records) == 3
    for _ in range(150):
        fresh.step(10)
        schedule.update(fresh)
    assert schedule._slipping is None  # contacts with the hand given back once clear


def test_transform_commands_nudge_tip_move_drop_and_refuse_bad_ones(fresh):
    oid = _free_bottle(fresh)
    p0 = _pos(fresh, oid)
    r = dist.command(fresh, oid, True, (0.0, -0.015, 0.0))
    assert r["kind"] == "nudge" and r["applied"] == pytest.approx([0.0, -0.015], abs=1e-4)
    s = math.sin(math.pi / 4)
    r = dist.command(fresh, oid, True, (0, 0, 0), (s, 0.0, 0.0, s))  # 90 deg about x: the axis turns to -y
    assert r["kind"] == "tip"  # towards -y, or the next direction with room for it to lie (30 degrees apart)
    k = (r["direction"] - 3 * math.pi / 2) / (2 * math.pi / dist.TIP_DIRECTIONS)
    assert abs(k - round(k)) < 1e-3, r
    fresh.step(1000)
    assert dist.tilt(fresh, oid) > math.radians(80)
    r = dist.command(fresh, oid, False, (p0[0], p0[1], TOP))
    assert r["kind"] == "move"
    fresh.step(500)
    assert np.allclose(_pos(fresh, oid), p0, atol=3e-3) and dist.tilt(fresh, oid) < math.radians(2)
    assert dist.command(fresh, "nope", True, (0.01, 0, 0))["skipped"].startswith("unknown object id 'nope'")
    assert dist.command(fresh, oid, True, (math.nan, 0, 0))["skipped"] == "the transform has NaN or Inf"
    assert dist.command(fresh, dist.GRASPED, True, (0, 0, 0))["skipped"] == "nothing in the hand to drop"
    held = _hold(fresh)
    assert dist.command(fresh, dist.GRASPED, True, (0, 0, 0))["object"] == held and fresh.grasped is None
