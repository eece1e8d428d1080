"""`scenes jitter` (docs/benchmarks.md, "Perturbed layouts"): seeded, within the amplitude, apart, on the shelf."""
from __future__ import annotations

import math

import pytest
import yaml

from relocation_app.evaluation.scenes.cli import main, seed_range
from relocation_app.evaluation.scenes.jitter import jitter_scene
from relocation_common.paths import resolve_scenario
from relocation_common.scenario import load_scenario, parse_scenario

SCENES = ("paper_experiment_10", "scenario3_15", "paper2_10")


@pytest.mark.parametrize("name", SCENES)
@pytest.mark.parametrize("amp", (0.012, 0.020))
def test_every_bottle_moves_within_the_amplitude_apart_and_on_the_shelf(name, amp):
    data = yaml.safe_load(resolve_scenario(name).read_text())
    base = load_scenario(resolve_scenario(name))
    for seed in range(3):
        d = jitter_scene(data, amp, seed)
        assert d == jitter_scene(data, amp, seed)  # a function of (scene, amplitude, seed)
        sc = parse_scenario(d, d["name"])  # on the shelf, not overlapping (the scenario's own checks)
        assert sc.name == f"{name}_j{round(amp * 1000)}_s{seed}"
        moves = [math.hypot(a.x - b.x, a.y - b.y) for a, b in zip(base.objects, sc.objects)]
        assert max(moves) <= amp + 1e-4 and min(moves) >= 0.0
        objs = sc.objects
        for i, a in enumerate(objs):
            for b in objs[i + 1:]:
                a0, b0 = base.object(a.id), base.object(b.id)
                before = math.hypot(a0.x - b0.x, a0.y - b0.y)
                gap = min(0.005, before - a.radius - b.radius)
                assert math.hypot(a.x - b.x, a.y - b.y) >= a.radius + b.radius + gap - 2e-4
    assert jitter_scene(data, amp, 0)["objects"] != jitter_scene(data, amp, 1)["objects"]


def test_the_subcommand_writes_one_file_per_seed_and_refuses_a_bad_amplitude(tmp_path, capsys):
    assert main(["jitter", "scenario1_5", "--seeds", "0-2", "--out", str(tmp_path)]) == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == [f"scenario1_5_j12_s{k}.yaml" for k in range(3)]
    assert main(["jitter", "scenario1_5", "--amplitude", "-1", "--out", str(tmp_path)]) == 2
    assert "amplitude" in capsys.readouterr().out
    assert seed_range("0-2,7") == [0, 1, 2, 7]
