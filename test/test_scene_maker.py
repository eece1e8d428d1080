"""The scene maker (`python -m relocation_app.evaluation.scenes KIND`, also `./run evaluate scenes KIND`) writes the
shipped scenes again byte for byte from their seeds and committed feasibility tables (no new planner call): a Table 4
random case at the paper's size through the command's own draw (lane screen, tree, weights, perception's view, the
optimum planned again) and a random scene of this project's geometry; and both entry points run the same command."""
from __future__ import annotations

import re
import shutil

import pytest
import yaml

from relocation_app.evaluation.__main__ import main as evaluate_main
from relocation_app.evaluation.feasibility_cache import cache_path, planner_params
from relocation_app.evaluation.scenes import cli, generated, layout, paper_random
from relocation_common.paths import data_dir, scenarios_dir
from relocation_common.scenario import load_scenario


def _with_table(path, tmp_path):
    """A feasibility directory in tmp_path holding the committed table of the scene at `path` (the maker saves
    into it)."""
    table = cache_path(load_scenario(path), planner_params(), data_dir() / "feasibility")
    out = tmp_path / "feasibility"
    out.mkdir(exist_ok=True)
    shutil.copy(table, out / table.name)
    return out


def _seed(path, pattern: str) -> int:
    return int(re.search(pattern, yaml.safe_load(path.read_text())["description"]).group(1))


def test_the_paper_random_command_writes_case_1_again(tmp_path):
    shipped = scenarios_dir() / paper_random.DIR / f"{paper_random.name(1)}.yaml"
    feas = _with_table(shipped, tmp_path)
    seed = _seed(shipped, r"layout seed (\d+)")
    written = paper_random.make(planner_params(), feas, tmp_path / "scenarios", [1], seed - 1, 3.0, work=feas)
    assert written == 1
    assert (tmp_path / "scenarios" / paper_random.DIR / shipped.name).read_bytes() == shipped.read_bytes()


def test_a_generated_random_scene_is_written_again(tmp_path):
    shipped = scenarios_dir() / "random5" / "random5_00.yaml"
    case = generated.random_case(0, _seed(shipped, r"lattice seed (\d+)"), planner_params(),
                                 _with_table(shipped, tmp_path))
    assert case is not None
    out = layout.write_scene(case[0], tmp_path / shipped.name, generated.HEADER)
    assert out.read_bytes() == shipped.read_bytes()


def test_run_evaluate_scenes_is_the_scene_maker(tmp_path, capsys):
    args = ["jitter", "scenario1_5", "--seeds", "0-1", "--out"]
    assert evaluate_main(["scenes", *args, str(tmp_path / "a")]) == 0
    assert cli.main([*args, str(tmp_path / "b")]) == 0
    names = sorted(p.name for p in (tmp_path / "a").iterdir())
    assert names == ["scenario1_5_j12_s0.yaml", "scenario1_5_j12_s1.yaml"]
    assert all((tmp_path / "a" / n).read_bytes() == (tmp_path / "b" / n).read_bytes() for n in names)
    assert layout.made_by("jitter") in (tmp_path / "a" / names[0]).read_text().splitlines()[0]
    with pytest.raises(SystemExit) as e:
        evaluate_main(["scenes"])  # the kind is required
    assert e.value.code == 2 and "KIND" in capsys.readouterr().err
