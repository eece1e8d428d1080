"""The scenes of this project's geometry (`python -m relocation_app.evaluation.scenes generated`, also
`./run evaluate scenes generated`); rerunning rewrites the same files.

- scenario1_5: lattice_scene(seed 50, 5 obstacles), the candidate closest to the paper's 10 feasible sequences
  among the lattice seeds 0-60 that passed `accept` (it has 7).
- scenario2_10: scenario3_15 without its five outermost obstacles (o1, o5, o6, o11, o15), renumbered o1..o10.
- random5/random5_XX: the first ten lattice seeds from RANDOM_SEED0 on that pass `accept` (Table 4).
`accept` is the admission rule: target blocked at the start, a unique optimal set of obstacles, at least two
feasible sequences from at least two minimal freeing sets (an alternative to learn against). Feasibility comes from
the real planner (evaluation parameters, feasibility_cache.planner_params) through the disk cache.
"""
from __future__ import annotations

import math
import random
from pathlib import Path

import yaml

from relocation_app.evaluation.scenes.layout import MAX_REACH, made_by, scene_data, write_scene
from relocation_app.evaluation.scenes.screening import fill

RANDOM_SEED0 = 1000
HEADER = (f"# Evaluation scene (docs/evaluation.md), made by {made_by('generated')}\n"
          "# on the shelf of paper_experiment_10. Format: docs/scenarios.md.")
LATTICE = {0.69: (-0.28, -0.14, 0.0, 0.14, 0.28), 0.79: (-0.33, -0.21, -0.07, 0.07, 0.21, 0.33),
           0.89: (-0.24, -0.12, 0.0, 0.12, 0.24)}  # three staggered rows (scenario3_15's layout)


def lattice_scene(seed: int, n: int, name: str, spread: float = 0.3, jitter: float = 0.01) -> dict:
    """The bottles on the staggered three-row lattice (jittered): the target in the back row, the n obstacles on
    lattice points within `spread` of it laterally (rows of a real shelf), weights uniform in [0.05, 0.95]."""
    rng = random.Random(seed)
    ty = rng.choice((-0.12, 0.0, 0.12))
    tx = 0.89
    cands = [(x, y) for x, ys in LATTICE.items() for y in ys if abs(y - ty) <= spread and (x, y) != (tx, ty)
             and math.hypot(x, y) <= MAX_REACH]
    if len(cands) < n:
        raise RuntimeError(f"seed {seed}: only {len(cands)} lattice points within {spread} m of the target")
    chosen = rng.sample(cands, n)
    pts = [(x + rng.uniform(-jitter, jitter), y + rng.uniform(-jitter, jitter)) for x, y in chosen]
    return scene_data(rng, seed, name, (tx + rng.uniform(-jitter, jitter), ty), pts)


def accept(report, min_sequences: int = 2) -> bool:
    """Admission rule for an evaluation scene (module docstring)."""
    return (not report.target_free_at_start and report.unique_optimum and len(report.minimal_sets) >= 2
            and report.n_sequences >= min_sequences)


def evaluate_scene(data: dict, params, directory, workers: int = 1):
    """(sequences.analyse report, table, its path): the scene's table filled completely with the real planner."""
    from relocation_app.evaluation.sequences import analyse
    sc, table, path, _ = fill(data, params, directory, save=True, workers=workers)
    return analyse(table, sc), table, path


def scenario2_from_3(scenarios: Path) -> dict:
    """scenario2_10's data: scenario3_15 without its five outermost obstacles, renumbered o1..o10."""
    d = yaml.safe_load((scenarios / "scenario3_15.yaml").read_text())
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


def random_case(k: int, seed: int, params, data_dir):
    """(data, sequences report) of Table 4 random scene k from lattice seed `seed` if it passes `accept` (its table
    filled in `data_dir`), else None."""
    d = lattice_scene(seed, 5, f"random5_{k:02d}", 0.3)
    rep, _, _ = evaluate_scene(d, params, data_dir)
    if not accept(rep):
        return None
    d["description"] = f"Table 4 random scene {k} (lattice seed {seed}); {rep.n_sequences} feasible sequences."
    return d, rep


def make(params, data_dir, scenarios: Path, n_random: int = 10) -> None:
    """Write scenario1_5, scenario2_10 and the `n_random` Table 4 scenes random5/ into `scenarios` (module
    docstring)."""
    d1 = lattice_scene(50, 5, "scenario1_5", 0.3)
    d1["description"] = "Five obstacles in staggered rows in front of the target (lattice seed 50)."
    write_scene(d1, scenarios / "scenario1_5.yaml", HEADER)
    write_scene(scenario2_from_3(scenarios), scenarios / "scenario2_10.yaml", HEADER)
    found, seed = 0, RANDOM_SEED0
    while found < n_random:
        case = random_case(found, seed, params, data_dir)
        if case is not None:
            write_scene(case[0], scenarios / "random5" / f"random5_{found:02d}.yaml", HEADER)
            print(f"random5_{found:02d}: seed {seed}, {case[1].n_sequences} sequences", flush=True)
            found += 1
        seed += 1
