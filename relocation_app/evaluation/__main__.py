"""`./run evaluate [fill|sweep|report|scenes|all] [--runs N] [--quick] ...`: the paper's evaluation
(docs/evaluation.md).

all (default): fill the missing feasibility answers with the real planner (none when data/feasibility/ is
complete), run the missing sweep cells (the scenes of the paper's size paper1_5/paper2_10/paper3_15, scenarios
1-3 of this project's geometry, the Sect. 5.2 scene paper_experiment_10, the 10 random scenes of each set), regenerate
docs/evaluation.md (the paper's Tables 1-4 beside ours, data/paper/) and docs/figures/.
--only a,b: fill/sweep only those scenes.
scenes KIND ...: make scenes (generated, paper N, paper-random, jitter): `./run evaluate scenes --help`, the same as
`python -m relocation_app.evaluation.scenes` (scenes/cli.py).
--quick: 3 runs per cell, two (alpha, gamma) pairs, two random scenes per set, output under out/evaluation-quick/.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from relocation_app.evaluation.feasibility_cache import planner_params
from relocation_common.paths import data_dir, scenarios_dir, share_dir

ROOT = share_dir()  # the checkout: the evaluation writes docs/ and data/ of the source tree
SCEN_DIR = scenarios_dir()
MAIN = ("scenario1_5", "scenario2_10", "scenario3_15")  # this project's geometry
PAPER = ("paper1_5", "paper2_10", "paper3_15")  # scenes of the paper's size (scenes paper N)
EXPERIMENT = "paper_experiment_10"
QUICK_GRID = ((1.0, 0.1), (0.3, 0.9))


def scene_paths(quick: bool = False) -> tuple[list[Path], list[Path], list[Path]]:
    """Scenarios 1-3 (the paper-size scenes that exist first, then this project's), the random scenes of this
    project's geometry (random5/) and of the paper's size (paper_random5/)."""
    main = [SCEN_DIR / f"{n}.yaml" for n in PAPER if (SCEN_DIR / f"{n}.yaml").exists()]
    main += [SCEN_DIR / f"{n}.yaml" for n in MAIN]
    rnd, prnd = (sorted((SCEN_DIR / d).glob("*.yaml")) for d in ("random5", "paper_random5"))
    return main, (rnd[:2] if quick else rnd), (prnd[:2] if quick else prnd)


def scenes(paths, params, data_dir, grid=None):
    """The sweep's scenes (sweep.Scene) of the scenario files `paths`, each with its feasibility cache file."""
    from relocation_app.evaluation.feasibility_cache import cache_key, cache_path
    from relocation_app.evaluation.sweep import GRID, Scene
    from relocation_common.scenario import load_scenario
    out = []
    for p in paths:
        sc = load_scenario(p)
        out.append(Scene(sc.name, str(p), str(cache_path(sc, params, data_dir)), cache_key(sc, params),
                         tuple(grid or GRID)))
    return out


def cmd_fill(paths, params, data_dir, workers, replicas: int = 0) -> dict:
    """Fill each scene's table: with `workers` processes here, or (replicas > 0) through that many motion planner
    processes over ROS (replica_fill)."""
    from contextlib import nullcontext

    from relocation_app.evaluation.feasibility_cache import fill_reachable, open_table
    from relocation_app.evaluation.replica_fill import replica_oracle
    from relocation_common.scenario import load_scenario
    stats = {}
    for p in paths:
        sc = load_scenario(p)
        table, path = open_table(sc, params, data_dir)
        with replica_oracle(p, replicas, params.timeout) if replicas else nullcontext() as oracle:
            st = fill_reachable(sc, params, table, workers=workers, progress=True, save_to=path, oracle=oracle)
        stats[sc.name] = st | {"entries": len(table), "planner_seconds": round(table.planner_seconds, 1)}
        print(f"{sc.name}: {len(table)} answers in {path.relative_to(ROOT) if path.is_relative_to(ROOT) else path} "
              f"({st['real_calls']} new planner calls)", flush=True)
    return stats


def _only(paths: list[Path], only: set[str] | None) -> list[Path]:
    return [p for p in paths if only is None or p.stem in only]


def main(argv=None) -> int:
    """`./run evaluate ...` (the module docstring); exit status."""
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv[:1] == ["scenes"]:
        from relocation_app.evaluation.scenes.cli import main as scenes_main
        return scenes_main(argv[1:])
    ap = argparse.ArgumentParser(prog="evaluate", description=__doc__.splitlines()[0])
    ap.add_argument("command", nargs="?", default="all", choices=("all", "fill", "sweep", "report", "scenes"),
                    help="scenes KIND ...: the scene maker (its own options; `scenes --help`)")
    ap.add_argument("--runs", type=int, default=50, help="trainings per cell (default 50)")
    ap.add_argument("--quick", action="store_true", help="small version: 3 runs, 2 (alpha, gamma), 2 random scenes")
    ap.add_argument("--out", default=None, help="sweep results directory (default out/evaluation[-quick])")
    ap.add_argument("--docs", default=None, help="where evaluation.md and figures/ go (default docs/, quick: OUT/docs)")
    ap.add_argument("--data", default=str(data_dir() / "feasibility"), help="feasibility cache directory")
    ap.add_argument("--workers", type=int, default=None, help="processes (default: all cores)")
    ap.add_argument("--replicas", type=int, default=0,
                    help="fill: ask N motion planner processes over ROS instead of --workers local processes")
    ap.add_argument("--no-random", action="store_true", help="skip the random 5-obstacle scenes (Table 4, both sets)")
    ap.add_argument("--no-experiment", action="store_true", help="skip the Sect. 5.2 scene (paper_experiment_10)")
    ap.add_argument("--no-progress", action="store_true")
    ap.add_argument("--only", default=None, help="fill/sweep only these scenes (comma-separated names)")
    a = ap.parse_args(argv)
    if a.runs < 1:
        ap.error("--runs must be >= 1")
    runs = 3 if a.quick and a.runs == 50 else a.runs
    out = Path(a.out or ROOT / "out" / ("evaluation-quick" if a.quick else "evaluation"))
    docs = Path(a.docs or (out / "docs" if a.quick else ROOT / "docs"))
    params = planner_params()
    main_p, rnd_p, prnd_p = scene_paths(a.quick)
    if a.no_random:
        rnd_p, prnd_p = [], []
    exp_p = [] if a.quick or a.no_experiment else [SCEN_DIR / f"{EXPERIMENT}.yaml"]
    import os
    workers = a.workers or os.cpu_count() or 1
    only = set(a.only.split(",")) if a.only else None
    if a.command in ("all", "fill"):
        cmd_fill(_only(main_p + rnd_p + prnd_p + [SCEN_DIR / f"{EXPERIMENT}.yaml"], only), params, a.data, workers,
                 a.replicas)
    if a.command in ("all", "sweep"):
        from relocation_app.evaluation.sweep import sweep
        grid = QUICK_GRID if a.quick else None
        sc = scenes(_only(main_p + exp_p + rnd_p + prnd_p, only), params, a.data, grid)
        t = time.perf_counter()
        res = sweep(sc, runs, out / "sweep.jsonl", workers=workers, progress=not a.no_progress)
        res["wall_s"] = round(time.perf_counter() - t, 1)
        from qtree_task_planner.learning import kernel
        res |= {"runs": runs, "workers": workers, "cells": len(sc) * len(sc[0].grid) * 6, "time": time.time(),
                "engine": "C kernel" if kernel.available() else f"Python loop ({kernel.build_error})"}
        with (out / "timing.jsonl").open("a") as f:
            f.write(json.dumps(res) + "\n")
        print(f"sweep: {res['cells_run']} cells run in {res['wall_s']} s on {workers} workers", flush=True)
    if a.command in ("all", "report"):
        from relocation_app.evaluation.reports.report import write_report
        path = write_report(out, docs, params, a.data, [p.stem for p in main_p if p.stem in MAIN],
                            [p.stem for p in rnd_p], quick=a.quick, experiment=[p.stem for p in exp_p],
                            paper_set=[p.stem for p in main_p if p.stem in PAPER],
                            paper_random=[p.stem for p in prnd_p])
        print(f"report: {path}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
