"""The one scenario loader: valid files load, every kind of bad input gets a one-line ScenarioError."""
import copy
import math

import pytest
import yaml

from relocation_common.paths import default_scenario, scenarios_dir
from relocation_common.scenario import ScenarioError, UnknownObjectError, load_scenario, parse_scenario

BASE = yaml.safe_load(default_scenario().read_text())


def test_default_scenario_is_the_papers_experiment():
    s = load_scenario(default_scenario())
    assert len(s.obstacle_ids) == 10 and s.target_id == "T"
    assert sorted(s.weights.values()) == sorted([0.15, 0.13, 0.23, 0.44, 0.65, 0.78, 0.13, 0.34, 0.56, 0.89])
    assert s.object("T").is_target and s.object("T").label == "green"
    assert len(set(o.label for o in s.objects)) == len(s.objects)
    assert len(s.slots) >= len(s.objects)
    for x, y in s.slots:  # slots lie on the bottom shelf
        assert s.shelf.x_front < x < s.shelf.x_back and s.shelf.y_min < y < s.shelf.y_max


def test_all_shipped_scenarios_load():
    for path in sorted(scenarios_dir().glob("*.yaml")):
        s = load_scenario(path)
        assert s.target_id in s.ids


def test_unknown_object_id_names_the_known_ones():
    s = load_scenario(default_scenario())
    with pytest.raises(UnknownObjectError, match="unknown object id 'nope'.*o1"):
        s.object("nope")
    with pytest.raises(UnknownObjectError):
        s.check_ids(["o1", "ghost"])


def _bad(mutate):
    d = copy.deepcopy(BASE)
    mutate(d)
    with pytest.raises(ScenarioError) as e:
        parse_scenario(d, "x.yaml")
    msg = str(e.value)
    assert msg.startswith("x.yaml: ") and "\n" not in msg
    return msg


@pytest.mark.parametrize("mutate, fragment", [
    (lambda d: d["objects"][1].update(id="o1"), "duplicate id 'o1'"),
    (lambda d: d["objects"][0].update(weight=1.5), "weight must be in (0, 1]"),
    (lambda d: d["objects"][0].update(weight=0), "weight must be in (0, 1]"),
    (lambda d: d["objects"][0].update(weight=math.nan), "finite number"),
    (lambda d: d["objects"][0].update(xy=[0.69, math.inf]), "finite number"),
    (lambda d: d.pop("target"), "target: missing"),
    (lambda d: d.update(target="ghost"), "'ghost' is not among the objects"),
    (lambda d: d["objects"][0].update(xy=[2.0, 0.0]), "not on the top shelf"),
    (lambda d: d["objects"][0].update(xy=[0.69, -0.10]), "overlap"),
    (lambda d: d["objects"][0].update(id=""), "id must be a letter"),
    (lambda d: d.update(objects=[]), "non-empty list"),
    (lambda d: d.pop("marker"), "marker: missing"),
    (lambda d: d["shelf"].update(ceiling_z=-0.5), "bottom_z < top_z < ceiling_z"),
    (lambda d: d.update(blocking={"T": ["ghost"]}), "blocking[T]"),
    (lambda d: d["objects"][0].update(color="chartreuse"), "unknown color"),
])
def test_bad_scenarios_get_one_clear_line(mutate, fragment):
    assert fragment in _bad(mutate)


def test_malformed_yaml_and_missing_file(tmp_path):
    p = tmp_path / "broken.yaml"
    p.write_text("name: x\nobjects: [\n  - {id: a\n")
    with pytest.raises(ScenarioError, match="malformed YAML at line"):
        load_scenario(p)
    with pytest.raises(ScenarioError, match="cannot read scenario file"):
        load_scenario(tmp_path / "absent.yaml")
    p.write_text("- just\n- a list\n")
    with pytest.raises(ScenarioError, match="must be a YAML mapping"):
        load_scenario(p)


def test_with_objects_keeps_the_shelf_and_validates():
    s = load_scenario(default_scenario())
    fewer = s.with_objects([o for o in s.objects if o.id != "o1"])
    assert "o1" not in fewer.ids and fewer.shelf == s.shelf and fewer.slots == s.slots
    with pytest.raises(ScenarioError, match="exactly one target"):
        s.with_objects([o for o in s.objects if not o.is_target])


def test_scene_messages_round_trip_and_reject_nan():
    from relocation_common.ros_conversions import msg_to_objects, objects_to_msg
    s = load_scenario(default_scenario())
    msg = objects_to_msg(s.objects)
    assert msg_to_objects(msg) == s.objects
    msg.objects[2].pose.position.x = math.nan
    with pytest.raises(ScenarioError, match="non-finite"):
        msg_to_objects(msg)
    msg = objects_to_msg(s.objects)
    msg.objects[1].id = msg.objects[0].id
    with pytest.raises(ScenarioError, match="duplicate id"):
        msg_to_objects(msg)
