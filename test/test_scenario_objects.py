"""The scenario's objects as they are on a shelf: shapes (boxes, lying cylinders), colours by name or RGB (repeating,
no cap), fewer objects listed than the shelf holds, `unlisted:` objects for the simulator only; every new key
loads, every error is one line; footprints overlap as the shapes do."""
import copy
import math

import pytest
import yaml

from relocation_common.paths import default_scenario, scenarios_dir
from relocation_common.scenario import PALETTE, ScenarioError, UnknownObjectError, load_scenario, parse_scenario
from relocation_common.shelf_object import Footprint, ShelfObject, unlisted_density

BASE = yaml.safe_load(default_scenario().read_text())
TOP = BASE["shelf"]["top_z"]


def _load(mutate):
    d = copy.deepcopy(BASE)
    mutate(d)
    return parse_scenario(d, "x.yaml")


def _bad(mutate):
    with pytest.raises(ScenarioError) as e:
        _load(mutate)
    msg = str(e.value)
    assert msg.startswith("x.yaml: ") and "\n" not in msg, msg
    return msg


def _add(entry, section="objects"):
    def mutate(d):
        d.setdefault(section, [])
        d[section].insert(0, entry)
    return mutate


def test_every_shipped_scene_loads_those_of_world_too():
    paths = sorted(scenarios_dir().rglob("*.yaml"))
    assert len([p for p in paths if p.parent.name == "world"]) == 7
    for path in paths:
        s = load_scenario(path)
        assert s.target_id in s.ids and all(o.listed for o in s.objects) and not any(o.listed for o in s.unlisted)


def test_the_target_alone_may_be_listed():
    s = _load(lambda d: d.update(objects=[{"id": "T", "xy": [0.92, 0.0]}]))
    assert s.ids == ("T",) and s.obstacle_ids == () and s.object("T").label == "green"


def test_a_box_with_its_size_and_yaw():
    s = _load(_add({"id": "b1", "weight": 0.3, "xy": [0.74, -0.32], "shape": "box", "size": [0.05, 0.08, 0.12],
                    "yaw": 0.4}))
    b = s.object("b1")
    assert (b.shape, b.size, b.radius, b.height, b.yaw, b.lying) == ("box", (0.05, 0.08, 0.12), 0.0, 0.12, 0.4, False)
    assert b.support_z == TOP and b.top_z == pytest.approx(TOP + 0.12) and b.volume == pytest.approx(0.00048)
    assert len(b.footprint().corners) == 4 and b.centre()[2] == pytest.approx(TOP + 0.06)


def test_a_lying_cylinder_with_the_yaw_of_its_axis():
    s = _load(_add({"id": "l1", "weight": 0.3, "xy": [0.80, -0.31], "lying": True, "yaw": 3.0}))
    o = s.object("l1")
    assert o.lying and o.shape == "cylinder" and o.yaw == pytest.approx(3.0 - math.pi)  # an axis: modulo pi
    assert o.top_z == pytest.approx(TOP + 2 * o.radius) and o.centre()[2] == pytest.approx(TOP + o.radius)
    corners = o.footprint().corners
    side = sorted(math.dist(corners[0], c) for c in corners[1:])
    assert side[:2] == pytest.approx([2 * o.radius, o.height])  # the rectangle it covers on the board


def test_colours_by_name_or_rgb_may_repeat_and_cycle_without_a_cap():
    s = _load(lambda d: (d["objects"][0].update(color="red"), d["objects"][1].update(color="red"),
                         d["objects"][2].update(color=[0.85, 0.10, 0.10]),
                         d["objects"][3].update(color=[0.3, 0.3, 0.3])))
    assert [s.objects[k].label for k in range(4)] == ["red", "red", "red", ""]
    assert s.objects[3].rgb == (0.3, 0.3, 0.3)
    crowd = load_scenario("world/crowd_30")
    labels = [o.label for o in crowd.objects if not o.is_target]
    assert len(labels) == 29 and labels[:16] == list(PALETTE) and labels[16:29] == list(PALETTE)[:13]


def test_unlisted_objects_are_in_the_simulators_world_only():
    s = _load(lambda d: d.update(unlisted=[{"id": "x1", "xy": [0.86, 0.06], "radius": 0.025},
                                           {"id": "x2", "weight": 0.4, "xy": [0.74, 0.31], "shape": "box",
                                            "size": [0.05, 0.05, 0.1]}]))
    assert "x1" not in s.ids and [o.id for o in s.unlisted] == ["x1", "x2"] and s.world == s.objects + s.unlisted
    x1, x2 = s.unlisted
    assert not x1.listed and x1.weight == pytest.approx(math.pi * 0.025 ** 2 * 0.16 * unlisted_density())
    assert "L x" in x1.weight_note and "kg/m3" in x1.weight_note  # how its weight was estimated
    assert x2.weight == 0.4 and x2.weight_note == ""  # weighed in the file: the simulator's mass
    assert s.world_object("x2") is x2
    with pytest.raises(UnknownObjectError, match="x1"):
        s.object("x1")  # the planners' view: listed ones only


def test_auto_slots_say_when_they_are_fewer_than_the_objects():
    crowd = load_scenario("world/crowd_30")
    assert crowd.auto_slots and len(crowd.slots) == 12
    assert "12 slots" in crowd.slot_note and "30 objects" in crowd.slot_note
    assert load_scenario(default_scenario()).slot_note == ""


@pytest.mark.parametrize("mutate, fragment", [
    (_add({"id": "s1", "weight": 0.3, "xy": [0.74, 0.31], "shape": "sphere"}), "shape must be one of cylinder, box"),
    (_add({"id": "b1", "weight": 0.3, "xy": [0.74, 0.31], "shape": "box"}), "missing required key 'size'"),
    (_add({"id": "b1", "weight": 0.3, "xy": [0.74, 0.31], "shape": "box", "size": [0.05, 0.0, 0.1]}),
     "size must be three positive numbers"),
    (_add({"id": "b1", "weight": 0.3, "xy": [0.74, 0.31], "shape": "box", "size": [0.05, 0.05, 0.1], "radius": 0.03}),
     "a box has `size"),
    (_add({"id": "b1", "weight": 0.3, "xy": [0.74, 0.31], "shape": "box", "size": [0.05, 0.05, 0.1], "lying": True}),
     "a box has `size"),
    (_add({"id": "c1", "weight": 0.3, "xy": [0.74, 0.31], "size": [0.05, 0.05, 0.1]}), "not size"),
    (_add({"id": "c1", "weight": 0.3, "xy": [0.74, 0.31], "yaw": 0.3}), "a standing cylinder has none"),
    (_add({"id": "c1", "weight": 0.3, "xy": [0.74, 0.31], "lying": "yes"}), "lying must be true or false"),
    (_add({"id": "c1", "weight": 0.3, "xy": [0.74, 0.31], "color": [1.0, 2.0, 0.0]}), "must be in [0, 1]"),
    (_add({"id": "c1", "weight": 0.3, "xy": [0.74, 0.31], "color": [1.0, 0.0]}), "color must be a list of 3"),
    (_add({"id": "c1", "weight": 0.3, "xy": [0.74, 0.31], "colour": "red"}), "unknown key(s) colour"),
    (lambda d: d.update(unlisteds=[]), "unknown key(s) unlisteds"),
    (lambda d: d.update(unlisted={"id": "x1"}), "unlisted: must be a list"),
    (_add({"id": "c1", "xy": [0.74, 0.31]}), "missing required key 'weight'"),  # a listed obstacle is weighed
    (lambda d: d.update(unlisted=[next(o for o in d["objects"] if o["id"] == "T")]), "the target must be listed"),
    (_add({"id": "o1", "xy": [0.74, 0.31]}, "unlisted"), "duplicate id 'o1'"),
    (_add({"id": "x1", "xy": [0.70, -0.19]}, "unlisted"), "objects 'o1' and 'x1' overlap"),
    # a box whose end reaches o1 (at 0.69, -0.21, radius 0.033): its long side along x from 0.713
    (_add({"id": "b1", "weight": 0.3, "xy": [0.763, -0.21], "shape": "box", "size": [0.10, 0.02, 0.1]}),
     "objects 'b1' and 'o1' overlap"),
    # a lying bottle whose axis runs along x towards the back panel: its end leaves the shelf, its centre does not
    (_add({"id": "l1", "weight": 0.3, "xy": [0.92, 0.30], "radius": 0.02, "lying": True, "yaw": 0.0}),
     "is not on the top shelf"),
    (_add({"id": "b1", "weight": 0.3, "xy": [0.74, 0.31], "shape": "box", "size": [0.05, 0.05, 0.27]}),
     "does not fit under the ceiling"),
])
def test_bad_objects_get_one_clear_line(mutate, fragment):
    assert fragment in _bad(mutate)


def test_the_target_must_be_listed():
    def mutate(d):
        t = next(o for o in d["objects"] if o["id"] == "T")
        d["objects"].remove(t)
        d["objects"].append({"id": "T2", "xy": [0.92, 0.0]})
        d["unlisted"] = [t]
        d["target"] = "T"
    assert "is not among the objects" in _bad(mutate)


def test_shapes_turned_so_they_fit_load():
    """The two refused entries above, turned a quarter: the box's long side along y clears o1, the lying bottle
    along y stays on the shelf (the checks read the yaw)."""
    s = _load(_add({"id": "b1", "weight": 0.3, "xy": [0.763, -0.21], "shape": "box", "size": [0.10, 0.02, 0.1],
                    "yaw": math.pi / 2}))
    assert s.object("b1").yaw == pytest.approx(math.pi / 2)
    s = _load(_add({"id": "l1", "weight": 0.3, "xy": [0.92, 0.30], "radius": 0.02, "lying": True,
                    "yaw": math.pi / 2}))
    assert s.object("l1").lying


# ------------------------------------------------------------------------------------------------ footprints
def _box(x, y, sx, sy, yaw):
    return ShelfObject("b", "", (0.5, 0.5, 0.5), 0.5, x, y, 0.0, 0.1, shape="box", size=(sx, sy, 0.1),
                       yaw=yaw).footprint()


def circle(x, y, r):
    return Footprint((x, y), r, ())


def test_footprints_overlap_as_the_shapes_do():
    assert not circle(0, 0, 0.01).overlaps(circle(0.02, 0, 0.01))  # touching is not overlapping
    assert circle(0, 0, 0.01).overlaps(circle(0.0199, 0, 0.01))
    diamond = _box(0, 0, 0.1, 0.1, math.pi / 4)  # its corner at x = 0.0707
    assert diamond.overlaps(circle(0.075, 0, 0.01)) and not diamond.overlaps(circle(0.085, 0, 0.01))
    square = _box(0, 0, 0.1, 0.1, 0.0)  # its side at x = 0.05: the same circles miss it
    assert not square.overlaps(circle(0.075, 0, 0.01))
    assert _box(0, 0, 0.2, 0.02, 0).overlaps(_box(0, 0, 0.02, 0.2, 0))  # a plus sign: no corner inside the other
    assert not _box(0, 0, 0.2, 0.02, 0).overlaps(_box(0, 0.03, 0.2, 0.02, 0.0))
    assert _box(0, 0, 0.2, 0.02, 0).overlaps(_box(0, 0.03, 0.2, 0.02, 0.2))  # turned, it reaches across
