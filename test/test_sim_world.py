"""The simulator builds the whole world of a scenario (jaco2_sim_driver, no ROS): listed and unlisted objects, boxes,
bottles lying from the start, where the file puts them; its ground truth carries every one (the unlisted ones with
the weight perception would estimate); the disturbances work on every shape."""
import math
from dataclasses import replace

import numpy as np
import pytest

import jaco2_sim_driver  # noqa: F401  (MUJOCO_GL=egl before mujoco)
from jaco2_sim_driver import disturbance as dist
from jaco2_sim_driver import frames
from jaco2_sim_driver.camera import visible_pixels
from jaco2_sim_driver.messages import ground_truth, objects_msg, time_msg
from jaco2_sim_driver.sim import Jaco2Sim
from relocation_common.ros_conversions import msg_to_objects
from relocation_common.scenario import load_scenario
from relocation_common.shelf_object import estimated_weight, unlisted_density

WORLD = ("shapes_box_10", "lying_start_8", "paper_experiment_10_unlisted", "crowd_20", "crowd_30", "same_colour_10",
         "hidden_unlisted_10")
SETTLE = 1500  # ms of physics before the poses are compared
TOL = 0.002  # m: a settled object from where the file puts it
YAW_TOL = 0.01  # rad


def _turn(a, b, period):
    return abs(math.remainder(a - b, period))


def _settled(name):
    sc = load_scenario(f"world/{name}")
    sim = Jaco2Sim(sc, watchdog_timeout=0.05)
    sim.step(SETTLE)
    return sc, sim, {p.id: ground_truth(sc, p, unlisted_density()) for p in sim.object_poses()}


@pytest.mark.parametrize("name", WORLD)
def test_every_object_stands_or_lies_where_the_file_puts_it(name):
    sc, sim, truth = _settled(name)
    assert list(truth) == [o.id for o in sc.world]  # listed, then unlisted
    for o in sc.world:
        g = truth[o.id]
        assert math.hypot(g.x - o.x, g.y - o.y) < TOL and abs(g.support_z - o.support_z) < TOL, (o.id, g)
        assert (g.shape, g.lying) == (o.shape, o.lying), (o.id, g)  # a lying bottle stays lying
        if o.shape == "box":
            assert g.size == pytest.approx(o.size) and _turn(g.yaw, o.yaw, math.pi) < YAW_TOL, (o.id, g.yaw, o.yaw)
        elif o.lying:
            assert _turn(g.yaw, o.yaw, math.pi) < YAW_TOL and abs(g.axis_tilt - math.pi / 2) < YAW_TOL, (o.id, g)
        else:
            assert g.axis_tilt < YAW_TOL, (o.id, g)


def test_each_shape_is_its_geom():
    sc = load_scenario("world/shapes_box_10")
    sim = Jaco2Sim(sc, watchdog_timeout=0.05)
    for o in sc.world:
        g = sim.model.geom(f"{o.id}_geom")
        if o.shape == "box":
            assert g.type[0] == 6 and np.allclose(g.size, np.array(o.size) / 2)  # mjGEOM_BOX: half sizes
        else:
            assert g.type[0] == 5 and np.allclose(g.size[:2], (o.radius, o.height / 2))  # mjGEOM_CYLINDER
        assert sim.model.body(o.id).mass[0] == pytest.approx(o.weight)
        assert np.allclose(sim.model.geom_rgba[g.id][:3], o.rgb)


def test_ground_truth_carries_unlisted_objects_with_listed_false_and_an_estimated_weight():
    sc, sim, _ = _settled("paper_experiment_10_unlisted")
    msg = objects_msg(sc, sim.object_poses(), time_msg(sim.time))
    objects = msg_to_objects(msg, listed_ids=sc.ids)
    assert [o.id for o in objects] == [*sc.ids, "x1"]
    x1 = objects[-1]
    weight, note = estimated_weight(sc.world_object("x1"), unlisted_density())
    assert not x1.listed and x1.weight == pytest.approx(weight) and x1.weight_note == note and "kg/m3" in note
    assert all(o.listed and o.weight_note == "" for o in objects[:-1])
    assert [o.weight for o in objects[:-1]] == [o.weight for o in sc.objects]  # the listed ones keep the file's
    assert "bottle_x1" in {child for _, child, _ in frames.bottle_transforms(sim.object_poses())}


def test_an_unlisted_object_weighed_in_the_file_is_published_with_perceptions_estimate():
    sc = load_scenario("world/paper_experiment_10_unlisted")
    heavy = replace(sc, unlisted=(replace(sc.unlisted[0], weight=0.9, weight_note=""),))
    sim = Jaco2Sim(heavy, watchdog_timeout=0.05)
    assert sim.model.body("x1").mass[0] == pytest.approx(0.9)  # the simulation's mass: the file's
    x1 = msg_to_objects(objects_msg(heavy, sim.object_poses(), time_msg(0.0)))[-1]
    assert x1.weight == pytest.approx(estimated_weight(heavy.unlisted[0], unlisted_density())[0]) and x1.weight_note


def test_the_hidden_bottle_shows_no_pixel_to_the_camera_at_home():
    sc = load_scenario("world/hidden_unlisted_10")
    pixels = visible_pixels(sc)
    assert [pixels[o.id] for o in sc.unlisted] == [0] and min(pixels[o.id] for o in sc.objects) >= 250, pixels


# ------------------------------------------------------------------------------------------------ disturbances
@pytest.fixture(scope="module")
def boxes():
    sim = Jaco2Sim(load_scenario("world/shapes_box_10"), watchdog_timeout=0.05)
    return sim


@pytest.fixture
def fresh(boxes):
    boxes.reset()
    dist.restore_all_contacts(boxes)
    boxes.step(200)
    return boxes


def _truth(sim, oid):
    return next(ground_truth(sim.scenario, p, unlisted_density()) for p in sim.object_poses() if p.id == oid)


def _roomy(sim, dx, dy, which):
    """An object (`which(o)`) with room for a push by (dx, dy)."""
    for o in sim.scenario.world:
        now = dist.current(sim, o.id)
        if which(o) and dist._room(sim, replace(now, x=now.x + dx, y=now.y + dy)) is None:
            return o
    raise AssertionError("no object with room")


def test_a_nudged_box_slides_by_the_amount_and_keeps_its_yaw(fresh):
    b = _roomy(fresh, 0.0, -0.015, lambda o: o.shape == "box")
    done = dist.nudge(fresh, b.id, 0.0, -0.015)
    assert done.detail["applied"] == pytest.approx([0.0, -0.015], abs=1e-4)
    fresh.step(1000)
    g = _truth(fresh, b.id)
    assert (g.x, g.y, g.support_z) == pytest.approx((b.x, b.y - 0.015, b.support_z), abs=TOL)
    assert _turn(g.yaw, b.yaw, math.pi) < YAW_TOL


def test_a_tipped_box_lies_on_a_side_face(fresh):
    for b in (o for o in fresh.scenario.world if o.shape == "box"):
        try:
            done = dist.tip(fresh, b.id, direction=math.pi)
        except dist.DisturbanceError:
            continue
        fresh.step(1500)
        g = _truth(fresh, b.id)
        assert g.size[2] < b.size[2] and sorted(g.size) == pytest.approx(sorted(b.size)), g.size  # on a side
        assert g.support_z == pytest.approx(b.support_z, abs=TOL) and done.kind == "tip"
        return
    raise AssertionError("no box with room to tip")


def test_a_lying_bottle_can_be_nudged_and_stood_up():
    sc = load_scenario("world/lying_start_8")
    sim = Jaco2Sim(sc, watchdog_timeout=0.05)
    sim.step(200)
    lying = next(o for o in sc.objects if o.lying)
    push = next((dx, dy) for dx, dy in ((0.0, 0.01), (0.0, -0.01), (0.01, 0.0), (-0.01, 0.0))
                if dist._room(sim, replace(dist.current(sim, lying.id), x=lying.x + dx, y=lying.y + dy)) is None)
    assert dist.nudge(sim, lying.id, *push).detail["applied"] == pytest.approx(list(push), abs=1e-4)
    sim.step(1000)
    g = _truth(sim, lying.id)
    assert g.lying and (g.x, g.y) == pytest.approx((lying.x + push[0], lying.y + push[1]), abs=TOL)
    assert lying.id not in dist.on_top_shelf(sim)  # lying: no planned disturbance picks it
    done = dist._move_somewhere(sim, lying.id, (0.0, 0.0))  # stood up at the free spot nearest the front right
    sim.step(1000)
    assert not _truth(sim, lying.id).lying and done.kind == "move"
    assert dist.on_top_shelf(sim).count(lying.id) == 1
