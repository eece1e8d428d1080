"""Scenario names as users type them (relocation_common.paths.resolve_scenario): a shipped scene by its bare name
even in a sub-folder of config/scenarios, as `./run demo --scenario random5_00` and the benchmarks' --scenes."""
from pathlib import Path

import pytest

from relocation_common.paths import resolve_scenario, scenarios_dir
from relocation_common.scenario import ScenarioError, load_scenario


@pytest.mark.parametrize("name", ["random5_00", "paper_random5_07", "random5_09.yaml", "random5/random5_00",
                                  "scenario1_5"])
def test_a_shipped_scene_by_its_name(name):
    path = resolve_scenario(name)
    assert path.is_file() and path.is_relative_to(scenarios_dir())
    assert path.stem == Path(name).stem
    assert load_scenario(path).target_id


def test_an_unknown_name_is_left_for_the_loader_to_name():
    assert resolve_scenario("no_such_scene") == Path("no_such_scene")
    with pytest.raises(ScenarioError, match="no_such_scene"):
        load_scenario(resolve_scenario("no_such_scene"))
