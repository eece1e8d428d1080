"""ShelfObject <-> ObjectState (relocation_common.ros_conversions): every shape survives the round trip object ->
message -> object; the message carries the primitive as moveit_msgs/CollisionObject does (shape_msgs/SolidPrimitive
at its centre, full orientation); a measured pose comes back as the model has it (shelf_object.at_pose); a bad
message gets one clear line."""
import math
from dataclasses import replace

import numpy as np
import pytest
from shape_msgs.msg import SolidPrimitive

from relocation_common.geometry import rpy_matrix, xyzw_matrix
from relocation_common.paths import scenarios_dir
from relocation_common.ros_conversions import msg_to_objects, object_to_msg, objects_to_msg
from relocation_common.scenario import ScenarioError, ShelfObject, load_scenario
from relocation_common.shelf_object import at_pose

TOP = 0.02
BOTTLE = ShelfObject("o1", "red", (0.85, 0.1, 0.1), 0.3, 0.70, -0.10, 0.033, 0.16, support_z=TOP)
TARGET = ShelfObject("T", "green", (0.1, 0.75, 0.15), 1.0, 0.92, 0.0, 0.033, 0.16, True, support_z=TOP)
SHAPES = {
    "standing": BOTTLE,
    "lying": replace(BOTTLE, lying=True, yaw=0.3),
    "lying, axis at -1.2": replace(BOTTLE, lying=True, yaw=-1.2),
    "lying, axis along y": replace(BOTTLE, lying=True, yaw=1.570796),
    "leaning 63 deg": replace(BOTTLE, lying=True, yaw=2.5, tilt=1.1),
    "standing, leaning 6 deg": replace(BOTTLE, yaw=-2.0, tilt=0.1),
    "box": ShelfObject("b1", "", (0.3, 0.4, 0.5), 0.2, 0.8, 0.2, 0.0, 0.0, shape="box", size=(0.05, 0.08, 0.12),
                       yaw=0.4, support_z=TOP),
    "box at -1.5": ShelfObject("b2", "olive", (0.5, 0.5, 0.05), 0.2, 0.8, 0.2, 0.0, 0.0, shape="box",
                               size=(0.1, 0.04, 0.2), yaw=-1.5, support_z=TOP),
    "unlisted, weight estimated": replace(BOTTLE, id="u3", listed=False, weight_note="0.55 L x 600 kg/m3 = 0.33 kg"),
    "conservative box": ShelfObject("u4", "", (0.2, 0.2, 0.2), 0.4, 0.8, 0.2, 0.0, 0.0, shape="box",
                                    size=(0.1, 0.1, 0.1), listed=False, fit_rms=0.004, conservative=True,
                                    support_z=TOP),
    "on the bottom shelf": replace(BOTTLE, support_z=-0.18),
}


@pytest.mark.parametrize("name", sorted(SHAPES))
def test_every_shape_survives_the_round_trip(name):
    o = SHAPES[name]
    back, = msg_to_objects(objects_to_msg([TARGET, o]), require_target=True)[1:]
    assert back == o


def test_numbers_of_any_precision_come_back_within_a_nanometre():
    """A measured object's numbers have all their digits: they come back within 1e-9 m / rad (the model's numbers
    from a pose are rounded there, so that a file's come back exactly)."""
    o = replace(BOTTLE, x=0.7123456789012, lying=True, yaw=math.pi / 2, support_z=TOP + 1e-10 / 3)
    back = msg_to_objects(objects_to_msg([TARGET, o]))[1]
    for k, v in o.__dict__.items():
        assert getattr(back, k) == (pytest.approx(v, abs=1e-9) if isinstance(v, float) else v), k


def test_every_object_of_every_shipped_scene_survives_the_round_trip():
    for path in sorted(scenarios_dir().rglob("*.yaml")):
        s = load_scenario(path)
        assert msg_to_objects(objects_to_msg(s.objects), listed_ids=s.ids) == s.objects, path.name
        assert msg_to_objects(objects_to_msg(s.objects + s.unlisted), listed_ids=s.ids) == s.objects + s.unlisted


def test_the_message_carries_a_solid_primitive_at_its_centre():
    m = object_to_msg(SHAPES["lying"])
    assert m.shape.type == SolidPrimitive.CYLINDER and list(m.shape.dimensions) == [0.16, 0.033]  # [height, radius]
    p, q = m.pose.position, m.pose.orientation
    assert (p.x, p.y, p.z) == pytest.approx((0.70, -0.10, TOP + 0.033))  # its centre, resting on the board
    axis = xyzw_matrix((q.x, q.y, q.z, q.w))[:, 2]
    assert abs(float(axis @ (math.cos(0.3), math.sin(0.3), 0.0))) == pytest.approx(1.0)
    m = object_to_msg(SHAPES["standing"])
    assert (m.pose.position.z, m.pose.orientation.w) == pytest.approx((TOP + 0.08, 1.0))
    b = object_to_msg(SHAPES["box"])
    assert b.shape.type == SolidPrimitive.BOX and list(b.shape.dimensions) == [0.05, 0.08, 0.12]
    assert b.pose.position.z == pytest.approx(TOP + 0.06)
    assert (b.listed, object_to_msg(SHAPES["conservative box"]).conservative) == (True, True)
    assert object_to_msg(SHAPES["unlisted, weight estimated"]).weight_note.endswith("0.33 kg")


def test_a_measured_pose_comes_back_as_the_model_has_it():
    """A box measured lying on its side (turned a quarter about its x axis): its size reordered, resting on its
    face; a bottle measured upside down: standing, its base where it rests; a bottle on its side: lying."""
    box = SHAPES["box"]
    side = at_pose(box, (0.8, 0.2, TOP + 0.04), rpy_matrix((math.pi / 2, 0.0, 0.0)))
    assert side.size == pytest.approx((0.12, 0.05, 0.08)) and side.support_z == pytest.approx(TOP)
    flipped = at_pose(BOTTLE, (0.7, -0.1, TOP + 0.08), rpy_matrix((math.pi, 0.0, 0.0)))
    assert not flipped.lying and (flipped.x, flipped.y, flipped.support_z) == pytest.approx((0.7, -0.1, TOP))
    lying = at_pose(BOTTLE, (0.7, -0.1, TOP + 0.033), rpy_matrix((0.0, math.pi / 2, 0.4)))
    assert lying.lying and lying.tilt is None and lying.yaw == pytest.approx(0.4)
    assert lying.support_z == pytest.approx(TOP)


def _msg_with(mutate, objects=(TARGET, BOTTLE)):
    msg = objects_to_msg(objects)
    mutate(msg.objects[1])
    return msg


@pytest.mark.parametrize("mutate, fragment", [
    (lambda o: setattr(o.pose.orientation, "w", 0.0), "not a unit quaternion"),
    (lambda o: setattr(o.pose.orientation, "w", 2.0), "not a unit quaternion"),
    (lambda o: setattr(o.shape, "type", SolidPrimitive.SPHERE), "must be a CYLINDER [height, radius] or a BOX"),
    (lambda o: setattr(o.shape, "dimensions", [0.16]), "must be a CYLINDER [height, radius] or a BOX"),
    (lambda o: setattr(o.shape, "dimensions", [0.16, -0.03]), "positive dimensions"),
    (lambda o: setattr(o.shape, "dimensions", [0.16, math.nan]), "non-finite"),
    (lambda o: setattr(o.color, "g", math.inf), "non-finite"),
    (lambda o: setattr(o, "id", "o 1; rm"), "is not a letter then letters"),
    (lambda o: setattr(o, "weight", 0.0), "weight must be in (0, 1]"),
    (lambda o: setattr(o, "is_target", True), "exactly one target, got 2"),
])
def test_bad_objects_in_a_message_get_one_clear_line(mutate, fragment):
    with pytest.raises(ScenarioError) as e:
        msg_to_objects(_msg_with(mutate))
    assert fragment in str(e.value) and "\n" not in str(e.value), str(e.value)


def test_listed_ids_and_the_target_are_checked():
    msg = objects_to_msg([TARGET, BOTTLE, SHAPES["unlisted, weight estimated"]])
    assert [o.listed for o in msg_to_objects(msg, listed_ids={"T", "o1"})] == [True, True, False]
    with pytest.raises(ScenarioError, match="listed, but the scenario does not list it"):
        msg_to_objects(msg, listed_ids={"T"})
    with pytest.raises(ScenarioError, match="unlisted, but the scenario lists that id"):
        msg_to_objects(msg, listed_ids={"T", "o1", "u3"})
    alone = objects_to_msg([BOTTLE])
    with pytest.raises(ScenarioError, match="exactly one target, got 0"):
        msg_to_objects(alone)
    assert msg_to_objects(alone, require_target=False) == (BOTTLE,)  # a scene after the target left it


def test_colour_comes_from_the_message_or_else_from_the_label():
    msg = objects_to_msg([TARGET, BOTTLE])
    msg.objects[1].color.a = 0.0  # not filled in: the label's palette colour
    msg.objects[1].color.r = 0.123
    assert msg_to_objects(msg)[1].rgb == (0.85, 0.1, 0.1)
    assert np.allclose(msg_to_objects(objects_to_msg([TARGET, replace(BOTTLE, rgb=(0.123, 0.456, 0.789))]))[1].rgb,
                       (0.123, 0.456, 0.789), atol=0)
