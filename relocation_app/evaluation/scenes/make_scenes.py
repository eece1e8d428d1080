"""How the evaluation scenes were made (`./run evaluate scenes`); rerunning rewrites the same files.

- scenario1_5: lattice_scene(seed 50, 5 obstacles), the candidate closest to the paper's 10 feasible sequences
  among the lattice seeds 0-60 that passed `accept` (it has 7).
- scenario2_10: scenario3_15 without its five outermost obstacles (o1, o5, o6, o11, o15), renumbered o1..o10.
- random5/random5_XX: the first ten lattice seeds from RANDOM_SEED0 on that pass `accept` (Table 4).
- paper1_5, paper2_10, paper3_15 (`python -m relocation_app.evaluation.scenes.make_scenes paper N`): scenes of the
  paper's size, searched with the real planner (paper_scenes.search; docs/evaluation.md, "Complete trees"); the
  search log goes to out/paper_search/.
- paper_random5/paper_random5_XX (`... make_scenes paper-random`): Table 4's ten random cases at the paper's size,
  drawn with the real planner (paper_random.py).
- jitter (`... make_scenes jitter SCENE [--amplitude 0.012] [--seeds 0-3]`): perturbed copies of a shipped scene,
  every bottle moved by a seeded random amount of at most `amplitude` (hand-placed bottles on a real shelf), kept
  JITTER_GAP apart and on the top shelf (docs/benchmarks.md, "Perturbed layouts"); written to out/jitter/.
Feasibility comes from the real planner (evaluation parameters, feasibility_cache.planner_params).
"""
from __future__ import annotations

import math
import random
from pathlib import Path

import yaml

from relocation_app.evaluation.scenes.scenarios_gen import RADIUS, accept, evaluate_scene, lattice_scene, write_scene
from relocation_common.paths import scenarios_dir

PAPER_NAMES = {5: "paper1_5", 10: "paper2_10", 15: "paper3_15"}
PAPER_HEADER = ("# Scene of the paper's size (docs/evaluation.md \"Complete trees\"), found with the real "
                "motion\n"
                "# planner by relocation_app/evaluation/scenes/make_scenes.py paper on the shelf of "
                "paper_experiment_10.\n"
                "# Format: docs/scenarios.md.")

SCEN = scenarios_dir()
RANDOM_SEED0 = 1000
HEADER = ("# Evaluation scene (docs/evaluation.md), made by relocation_app/evaluation/scenes/make_scenes.py on the "
          "shelf\n"
          "# of paper_experiment_10. Format: docs/scenarios.md.")


JITTER_GAP = 0.005  # m between bottle surfaces after a jitter (the scene's own gap if it was smaller)
JITTER_TRIES = 200  # draws per bottle before the whole layout is drawn again


def jitter_scene(data: dict, amplitude: float, seed: int) -> dict:
    """A copy of the scene `data` (as read from YAML) with every bottle moved by an offset drawn uniformly in the
    disc of radius `amplitude` (m), seeded by (scene name, amplitude in mm, seed) only; bottles stay on the top
    shelf and at least JITTER_GAP (or their original gap, if smaller) apart. Named `<name>_j<mm>_s<seed>`."""
    import copy

    from relocation_common.scenario import parse_scenario
    if not (isinstance(amplitude, (int, float)) and 0 < amplitude <= 0.05):
        raise ValueError(f"jitter amplitude must be in (0, 0.05] m, got {amplitude!r}")
    sc = parse_scenario(data, str(data.get("name", "scene")))
    mm = int(round(amplitude * 1000))
    name = f"{sc.name}_j{mm}_s{seed}"
    rng = random.Random(f"{sc.name}:{mm}:{seed}")
    s, objs = sc.shelf, sc.objects
    gap = {(a.id, b.id): min(JITTER_GAP, math.hypot(a.x - b.x, a.y - b.y) - a.radius - b.radius)
           for a in objs for b in objs if a.id < b.id}
    for _ in range(JITTER_TRIES):
        pos: dict[str, tuple[float, float]] = {}
        for b in objs:
            for _ in range(JITTER_TRIES):
                rho, th = amplitude * math.sqrt(rng.random()), rng.uniform(-math.pi, math.pi)
                x, y = b.x + rho * math.cos(th), b.y + rho * math.sin(th)
                on_shelf = (s.x_front + b.radius <= x <= s.x_back - b.radius
                            and s.y_min + b.radius <= y <= s.y_max - b.radius)
                if on_shelf and all(math.hypot(x - px, y - py) >= b.radius + sc.object(o).radius
                                    + gap[(min(b.id, o), max(b.id, o))] for o, (px, py) in pos.items()):
                    pos[b.id] = (round(x, 4), round(y, 4))
                    break
            else:
                break
        if len(pos) == len(objs):
            break
    else:
        raise RuntimeError(f"{sc.name}: no layout within {amplitude} m keeps the bottles apart")
    out = copy.deepcopy(data)
    for o in out["objects"]:
        o["xy"] = list(pos[o["id"]])
    out["name"] = name
    out["description"] = (f"{sc.name} with every bottle moved by at most {mm} mm (make_scenes jitter, seed {seed}).")
    return out


def make_jitter(scene: str, amplitude: float, seeds, out_dir: str | Path | None = None) -> list[Path]:
    """`make_scenes jitter`: one perturbed copy of the shipped scene per seed (jitter_scene), as YAML files."""
    from relocation_common.paths import resolve_scenario, share_dir
    path = resolve_scenario(scene)
    data = yaml.safe_load(Path(path).read_text())
    out = Path(out_dir) if out_dir else share_dir() / "out" / "jitter"
    header = (f"# Perturbed copy of {Path(path).name} (relocation_app/evaluation/scenes/make_scenes.py jitter, "
              f"{amplitude * 1000:.0f} mm). Format: docs/scenarios.md.")
    written = []
    for seed in seeds:
        d = jitter_scene(data, amplitude, seed)
        written.append(write_scene(d, out / f"{d['name']}.yaml", header))
    return written


def _seed_range(text: str) -> list[int]:
    """'0-3' -> [0, 1, 2, 3]; '1,5' -> [1, 5]."""
    out: list[int] = []
    for part in text.split(","):
        a, _, b = part.partition("-")
        out += list(range(int(a), int(b) + 1)) if b else [int(a)]
    return out


def scenario2_from_3() -> dict:
    """scenario2_10's data: scenario3_15 without its five outermost obstacles, renumbered o1..o10."""
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
    """Write scenario1_5, scenario2_10 and the `n_random` Table 4 scenes random5/ (the module docstring)."""
    d1 = lattice_scene(50, 5, "scenario1_5", 0.3)
    d1["description"] = "Five obstacles in staggered rows in front of the target (lattice seed 50)."
    write_scene(d1, SCEN / "scenario1_5.yaml", HEADER)
    write_scene(scenario2_from_3(), SCEN / "scenario2_10.yaml", HEADER)
    found, seed = 0, RANDOM_SEED0
    while found < n_random:
        d = lattice_scene(seed, 5, f"random5_{found:02d}", 0.3)
        rep, _, _ = evaluate_scene(d, params, data_dir)
        if accept(rep):
            d["description"] = (f"Table 4 random scene {found} (lattice seed {seed}); {rep.n_sequences} feasible "
                                f"sequences.")
            write_scene(d, SCEN / "random5" / f"random5_{found:02d}.yaml", HEADER)
            print(f"random5_{found:02d}: seed {seed}, {rep.n_sequences} sequences", flush=True)
            found += 1
        seed += 1


def make_paper(n: int, params, data_dir, seeds: int, steps: int, minutes: float, out_dir=None,
               seed0: int = 0, write_best: bool = False, resume: bool = False, strict: bool = False,
               temperature: float = 0.0, radius: float | None = None) -> bool:
    """Search a scene of the paper's size with n obstacles (paper_scenes.search) and write it with its complete
    feasibility table when one matches; the best candidate goes to out/paper_search/ either way. `strict`: the
    climb keeps only valid scenes (one optimum, every bottle visible), and --write-best writes only a valid one."""
    import json
    import time

    from relocation_app.evaluation.feasibility_cache import open_table
    from relocation_app.evaluation.scenes import complete_tree, paper_scenes
    from relocation_common.paths import share_dir
    from relocation_common.scenario import parse_scenario
    name = PAPER_NAMES[n]
    logdir = share_dir() / "out" / "paper_search"
    logdir.mkdir(parents=True, exist_ok=True)
    work = logdir / "tables"

    def log(msg: str) -> None:
        print(time.strftime("%H:%M:%S"), msg, flush=True)
    smaller = Path(out_dir or SCEN) / f"{PAPER_NAMES[n - 5]}.yaml" if n > 5 else None
    base = yaml.safe_load(smaller.read_text()) if smaller is not None and smaller.exists() else None
    best, data, _ = paper_scenes.search(n, name, params, work, range(seed0, seed0 + seeds), steps, log,
                                        time.time() + 60 * minutes, base,
                                        _shipped(out_dir, name, radius) if resume else None,
                                        strict=strict, climb_seed=seed0 if resume else None,
                                        temperature=temperature, radius=radius or RADIUS,
                                        on_best=lambda c: (logdir / f"best_{name}.json")
                                        .write_text(json.dumps(c.weighted or c.data)))
    (logdir / f"best_{name}.json").write_text(json.dumps((best.weighted or best.data) if best else None))
    if data is None:
        log(f"{name}: no match; best {paper_scenes.describe(best) if best else 'none'}")
        if not write_best or best is None or best.size is None or (strict and not best.valid):
            return False
        data = best.weighted or best.data
        log(f"{name}: the closest; bottles perception cannot locate: {paper_scenes.visible(data) or 'none'}")
    sc = parse_scenario(data, name)
    table = best.table
    size = complete_tree.of_table(table, sc)
    data["description"] = (f"{n} obstacles in tight clutter: complete Q-Tree of {size.edges} edges, "
                           f"{size.target_leaves} target leaves, {size.optimal_leaves} optimal (paper: "
                           f"{paper_scenes.PAPER_TREES[n][0]}, {paper_scenes.PAPER_TREES[n][1]}, 1)"
                           + ("" if best.ok(paper_scenes.PAPER_TREES[n]) else "; the closest the search reached")
                           + ".")
    write_scene(data, Path(out_dir or SCEN) / f"{name}.yaml", PAPER_HEADER)
    final, path = open_table(sc, params, data_dir)
    final.entries.update(table.entries)
    final.planner_seconds = table.planner_seconds
    final.save(path)
    log(f"{name}: written ({size.edges} edges, {size.target_leaves} target leaves), table {path}")
    return True


def _shipped(out_dir, name: str, radius: float | None = None) -> dict:
    """The shipped scene `name`, its bottles of `radius` when given (the layout is kept: smaller bottles fit)."""
    d = yaml.safe_load((Path(out_dir or SCEN) / f"{name}.yaml").read_text())
    d["description"] = ""
    if radius:
        d["defaults"]["radius"] = radius
    return d


def main(argv=None) -> int:
    """`python -m relocation_app.evaluation.scenes.make_scenes paper N [--seeds S] [--steps K] [--minutes M]`, or
    `... paper-random [--cases 1,2] [--seed0 S] [--minutes M]`, or `... jitter SCENE [--amplitude A] [--seeds 0-3]`."""
    import argparse
    import sys
    if argv is None:
        argv = sys.argv[1:]
    if argv and argv[0] == "jitter":
        return _jitter_main(argv[1:])

    from relocation_app.evaluation.feasibility_cache import planner_params
    ap = argparse.ArgumentParser(description="search a scene of the paper's size with the real planner")
    ap.add_argument("what", choices=("paper", "paper-random", "jitter"))
    ap.add_argument("n", type=int, nargs="?", choices=sorted(PAPER_NAMES), help="obstacles (paper)")
    ap.add_argument("--cases", default=None, help="paper-random: only these Table 4 cases (comma-separated 1-10)")
    ap.add_argument("--seeds", type=int, default=200000, help="layouts proposed (most rejected by the sketch)")
    ap.add_argument("--steps", type=int, default=4000, help="hill-climbing steps with the real planner")
    ap.add_argument("--write-best", action="store_true", help="write the closest scene when none matches")
    ap.add_argument("--resume", action="store_true", help="climb on from the shipped scene of that size")
    ap.add_argument("--strict", action="store_true",
                    help="climb only through valid scenes (one optimum, every bottle visible)")
    ap.add_argument("--temperature", type=float, default=0.0,
                    help="annealing: keep a step worse by d with probability exp(-d / T) (0: plain climb)")
    ap.add_argument("--radius", type=float, default=None,
                    help="bottle radius of the proposals, m (default 0.033; 0.025 fits 5 bottles in a row)")
    ap.add_argument("--seed0", type=int, default=0, help="first layout seed (with --resume: the climb's seed)")
    ap.add_argument("--minutes", type=float, default=15.0)
    ap.add_argument("--data", default=None, help="feasibility cache directory (default data/feasibility)")
    ap.add_argument("--scenarios", default=None, help="where the YAML goes (default config/scenarios)")
    a = ap.parse_args(argv)
    from relocation_common.paths import data_dir
    if a.what == "paper-random":
        from relocation_app.evaluation.scenes import paper_random
        cases = [int(c) for c in a.cases.split(",")] if a.cases else None
        n = paper_random.make(planner_params(), a.data or data_dir() / "feasibility", Path(a.scenarios or SCEN),
                              cases, a.seed0 or paper_random.SEED0, a.minutes)
        return 0 if n == len(cases or paper_random.case_edges()) else 1
    if a.n is None:
        ap.error("paper needs N (5, 10 or 15)")
    ok = make_paper(a.n, planner_params(), a.data or data_dir() / "feasibility", a.seeds, a.steps, a.minutes,
                    a.scenarios, a.seed0, a.write_best, a.resume, a.strict, a.temperature, a.radius)
    return 0 if ok else 1


def _jitter_main(argv) -> int:
    """`make_scenes jitter SCENE [SCENE ...] [--amplitude 0.012] [--seeds 0-3] [--out DIR]`."""
    import argparse
    ap = argparse.ArgumentParser(prog="make_scenes jitter",
                                 description="perturbed copies of shipped scenes (every bottle moved <= amplitude)")
    ap.add_argument("scenes", nargs="+", help="scenario names or paths (e.g. paper_experiment_10)")
    ap.add_argument("--amplitude", type=float, default=0.012, help="largest displacement of a bottle, m")
    ap.add_argument("--seeds", default="0-3", help="seeds, e.g. 0-3 or 1,5 (default 0-3)")
    ap.add_argument("--out", default=None, help="directory of the YAML files (default out/jitter)")
    a = ap.parse_args(argv)
    try:
        for scene in a.scenes:
            for path in make_jitter(scene, a.amplitude, _seed_range(a.seeds), a.out):
                print(path)
    except (OSError, ValueError, RuntimeError) as e:
        print(f"make_scenes jitter: error: {e}")
        return 2
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
