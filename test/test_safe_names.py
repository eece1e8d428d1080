"""Scenario names are checked like ids (relocation_common.scenario.NAME_PATTERN), naming the file and the field; the
MJCF is built with an XML library, so that no name is ever markup (jaco2_sim_driver.scene.scene_xml)."""
import dataclasses
import xml.etree.ElementTree as ET

import pytest
import yaml

from relocation_common.paths import scenarios_dir
from relocation_common.scenario import ScenarioError, load_scenario, parse_scenario

SOURCE = scenarios_dir() / "blocking_5.yaml"
HOSTILE = "x\"<&'y"


def _data(**change):
    data = yaml.safe_load(SOURCE.read_text())
    data.update(change)
    return data


@pytest.mark.parametrize("name", [HOSTILE, "../evil", ".hidden", "", "a" * 65, 7, "sp ace"])
def test_a_bad_scenario_name_is_refused_naming_the_file_and_field(name):
    """Old code: accepted by every node but the driver, whose MJCF failed ('XML parse error 6 ... Line number=1',
    naming neither file nor field)."""
    with pytest.raises(ScenarioError) as e:
        parse_scenario(_data(name=name), str(SOURCE))
    assert str(e.value).startswith(f"{SOURCE}: name: must be"), e.value


def test_a_name_from_the_file_name_is_checked_too(tmp_path):
    data = _data()
    data.pop("name")
    bad = tmp_path / "scene<1>.yaml"
    bad.write_text(yaml.safe_dump(data))
    with pytest.raises(ScenarioError, match=r"name \(from the file name 'scene<1>.yaml': give a `name:`\)"):
        load_scenario(bad)
    good = tmp_path / "scene-1.v2.yaml"
    good.write_text(yaml.safe_dump(data))
    assert load_scenario(good).name == "scene-1.v2"


def test_the_mjcf_escapes_whatever_a_scenario_holds():
    """A Scenario made in code skips the loader's checks: its name still cannot break (or inject into) the MJCF."""
    import mujoco

    from jaco2_sim_driver.scene import build_model, scene_xml

    sc = dataclasses.replace(load_scenario(SOURCE), name=HOSTILE + '"/><worldbody><geom name="injected')
    root = ET.fromstring(scene_xml(sc))
    assert root.get("model") == f"jaco2_shelf_{sc.name}"
    assert not any(g.get("name") == "injected" for g in root.iter("geom"))
    model = build_model(sc)
    assert mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, model.nbody - 1) == sc.objects[-1].id
