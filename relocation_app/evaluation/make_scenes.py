"""How the evaluation scenes were made (`./run evaluate scenes`); rerunning rewrites the same files.

- scenario1_5: lattice_scene(seed 50, 5 obstacles), the candidate closest to the paper's 10 feasible sequences
  among the lattice seeds 0-60 that passed `accept` (it has 7).
- scenario2_10: scenario3_15 without its five outermost obstacles (o1, o5, o6, o11, o15), renumbered o1..o10.
- random5/random5_XX: the first ten lattice seeds from RANDOM_SEED0 on that pass `accept` (Table 4).
Feasibility comes from the real planner (evaluation parameters, see __main__.planner_params).
"""
from __future__ import annotations


from relocation_common.paths import scenarios_dir

import yaml

from .scenarios_gen import accept, evaluate_scene, lattice_scene, write_scene

SCEN = scenarios_dir()
RANDOM_SEED0 = 1000
HEADER = ("# Evaluation scene (docs/evaluation.md), made by relocation_app/evaluation/make_scenes.py on the shelf\n"
          "# of paper_experiment_10. Format: docs/scenarios.md.")


def scenario2_from_3() -> dict:
    d = yaml.safe_load((SCEN / "scenario3_15.yaml").read_text())
    drop = {"o1", "o5", "o6", "o11", "o15"}
    objs = [o for o in d["objects"] if o["id"] not in drop]
    k = 0
    for o in objs:
        if o["id"] != d["target"]:
            k += 1
            o["id"] = f"o{k}"
    d.update(name="scenario2_10", objects=objs,
             description="Ten obstacles: scenario3_15 without its five outermost obstacles; target at the back.")
    return d


def make_all(params, data_dir, n_random: int = 10) -> None:
    d1 = lattice_scene(50, 5, "scenario1_5", 0.3)
    d1["description"] = "Five obstacles in staggered rows in front of the target (lattice seed 50)."
    write_scene(d1, SCEN / "scenario1_5.yaml", HEADER)
    write_scene(scenario2_from_3(), SCEN / "scenario2_10.yaml", HEADER)
    found, seed = 0, RANDOM_SEED0
    while found < n_random:
        d = lattice_scene(seed, 5, f"random5_{found:02d}", 0.3)
        rep, _, _ = evaluate_scene(d, params, data_dir)
        if accept(rep):
            d["description"] = f"Table 4 random scene {found} (lattice seed {seed}); {rep.n_sequences} feasible sequences."
            write_scene(d, SCEN / "random5" / f"random5_{found:02d}.yaml", HEADER)
            print(f"random5_{found:02d}: seed {seed}, {rep.n_sequences} sequences", flush=True)
            found += 1
        seed += 1
