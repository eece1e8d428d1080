"""The closed loop's checks against the real MuJoCo simulator core: the default tolerances hold the settled
physics (no difference where nothing happened) and catch each disturbance of jaco2_sim_driver.disturbance."""
from dataclasses import replace

import pytest

import jaco2_sim_driver  # noqa: F401  (MUJOCO_GL=egl before mujoco)
from jaco2_sim_driver import disturbance as dist
from jaco2_sim_driver.sim import Jaco2Sim
from qtree_task_planner.executive.closed_loop import SeenObject, remaining_problem, verify_relocation
from relocation_common.paths import default_scenario
from relocation_common.scenario import load_scenario
from relocation_common.shelf_object import tilt_of_quaternion

SCENARIO = load_scenario(default_scenario())
SH = SCENARIO.shelf


def perceive(sim) -> dict[str, SeenObject]:
    """Ground truth as the closed loop's scene (as /sim/objects would give it)."""
    out = {}
    for p in sim.object_poses():
        b = SCENARIO.object(p.id)
        out[p.id] = SeenObject(p.id, *p.position, weight=b.weight, is_target=b.is_target,
                               tilt=tilt_of_quaternion(*p.quat_wxyz), radius=b.radius, height=b.height)
    return out


@pytest.fixture(scope="module")
def sim():
    s = Jaco2Sim(SCENARIO)
    s.step(1000)
    return s


def test_settled_scene_is_the_scenario(sim):
    rp = remaining_problem(SCENARIO, perceive(sim), ())
    assert rp.problem is not None and set(rp.problem.ids) == set(SCENARIO.ids)
    assert rp.moved == {} and rp.gone == frozenset() and rp.tipped == ()
    assert rp.free_slots == tuple(range(len(SCENARIO.slots)))


def test_checks_on_the_simulator_see_what_happened_and_only_that(sim):
    sim.reset()
    sim.step(500)
    before = perceive(sim)
    moved = SCENARIO.obstacle_ids[0]
    x, y = SCENARIO.slots[0]
    dist.move_to(sim, moved, x, y, SH.bottom_z)  # relocated as planned (the arm's part is not under test here)
    sim.step(800)
    after = perceive(sim)
    assert verify_relocation(moved, (x, y, SH.bottom_z), before, after).ok
    rp = remaining_problem(SCENARIO, after, [moved])
    assert rp.gone == {moved} and rp.free_slots == tuple(range(1, len(SCENARIO.slots)))
    # a neighbour nudged by 3 cm, another tipped: exactly these two differences
    others = [o for o in SCENARIO.obstacle_ids if o != moved]
    nudged = next(o for o in others if _room_for_push(sim, o, 0.03))
    assert dist.nudge(sim, nudged, 0.0, 0.03).detail["applied"] == pytest.approx([0.0, 0.03], abs=1e-4)
    tipped = next(o for o in others if o != nudged and _tips(sim, o))
    sim.step(1500)
    check = verify_relocation(moved, (x, y, SH.bottom_z), after, perceive(sim))
    assert {(d.kind, d.object_id) for d in check.differences} == {("moved", nudged), ("tipped", tipped)}, \
        check.differences
    rp = remaining_problem(SCENARIO, perceive(sim), [moved])
    assert set(rp.moved) == {nudged, tipped} and rp.tipped == (tipped,) and tipped in rp.problem.obstacles


def _room_for_push(sim, oid, dy) -> bool:
    now = dist.current(sim, oid)
    return dist._room(sim, replace(now, y=now.y + dy)) is None


def _tips(sim, oid) -> bool:
    try:
        dist.tip(sim, oid)
        return True
    except dist.DisturbanceError:
        return False
