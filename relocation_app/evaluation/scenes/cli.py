"""`python -m relocation_app.evaluation.scenes KIND ...` (also `./run evaluate scenes KIND ...`): make scenes.

  generated [--random N]                 scenario1_5, scenario2_10 and the Table 4 scenes random5/ (generated.py)
  paper N [--seeds S] [--steps K] ...    a scene of the paper's size with N obstacles, searched (paper_size.py)
  paper-random [--cases 1,2] ...         Table 4's random cases at the paper's size (paper_random.py)
  jitter SCENE... [--amplitude A]        perturbed copies of shipped scenes, to out/jitter/ (jitter.py)
  world [--only NAME,...]                the shelf as it is: unlisted, lying, boxes, 20 / 30 objects (world.py)
Scenes go to config/scenarios/ (--scenarios), feasibility tables to data/feasibility/ (--data); feasibility comes from
the real planner with the evaluation's parameters (feasibility_cache.planner_params).
"""
from __future__ import annotations

import argparse
from pathlib import Path


def seed_range(text: str) -> list[int]:
    """'0-3' -> [0, 1, 2, 3]; '1,5' -> [1, 5]."""
    out: list[int] = []
    for part in text.split(","):
        a, _, b = part.partition("-")
        out += list(range(int(a), int(b) + 1)) if b else [int(a)]
    return out


def parser() -> argparse.ArgumentParser:
    """The command's parser: one sub-command per kind of scene."""
    ap = argparse.ArgumentParser(prog="python -m relocation_app.evaluation.scenes",
                                 description="make the evaluation's scenes: one sub-command per kind",
                                 formatter_class=argparse.RawDescriptionHelpFormatter, epilog=__doc__.split("\n\n")[1])
    sub = ap.add_subparsers(dest="kind", required=True, metavar="KIND")
    gen = sub.add_parser("generated", help="scenario1_5, scenario2_10, random5/ (this project's geometry)")
    gen.add_argument("--random", type=int, default=10, help="Table 4 random scenes random5/ (default 10)")
    paper = sub.add_parser("paper", help="a scene of the paper's size, searched with the real planner")
    paper.add_argument("n", type=int, choices=(5, 10, 15), help="obstacles")
    paper.add_argument("--seeds", type=int, default=200000, help="layouts proposed (most rejected by the screen)")
    paper.add_argument("--steps", type=int, default=4000, help="hill-climbing steps with the real planner")
    paper.add_argument("--write-best", action="store_true", help="write the closest scene when none matches")
    paper.add_argument("--resume", action="store_true", help="climb on from the shipped scene of that size")
    paper.add_argument("--strict", action="store_true",
                       help="climb only through valid scenes (one optimum, every bottle visible)")
    paper.add_argument("--temperature", type=float, default=0.0,
                       help="annealing: keep a step worse by d with probability exp(-d / T) (0: plain climb)")
    paper.add_argument("--radius", type=float, default=None,
                       help="bottle radius of the proposals, m (default 0.033; 0.025 fits 5 bottles in a row)")
    paper.add_argument("--seed0", type=int, default=0, help="first layout seed (with --resume: the climb's seed)")
    rnd = sub.add_parser("paper-random", help="Table 4's random cases at the paper's size")
    rnd.add_argument("--cases", default=None, help="only these Table 4 cases (comma-separated 1-10)")
    rnd.add_argument("--seed0", type=int, default=None, help="the first layout seed tried is SEED0 + 1 (default 5000)")
    for p in (paper, rnd):
        p.add_argument("--minutes", type=float, default=15.0)
    for p in (gen, paper, rnd):
        p.add_argument("--data", default=None, help="feasibility cache directory (default data/feasibility)")
        p.add_argument("--scenarios", default=None, help="where the YAML goes (default config/scenarios)")
    world = sub.add_parser("world", help="unlisted objects, boxes, lying bottles, 20 / 30 objects (world/)")
    world.add_argument("--only", default=None, help="only these scenes (comma-separated names)")
    world.add_argument("--scenarios", default=None, help="where the YAML goes (default config/scenarios)")
    jit = sub.add_parser("jitter", help="perturbed copies of shipped scenes (every bottle moved <= amplitude)")
    jit.add_argument("scenes", nargs="+", help="scenario names or paths (e.g. paper_experiment_10)")
    jit.add_argument("--amplitude", type=float, default=0.012, help="largest displacement of a bottle, m")
    jit.add_argument("--seeds", default="0-3", help="seeds, e.g. 0-3 or 1,5 (default 0-3)")
    jit.add_argument("--out", default=None, help="directory of the YAML files (default out/jitter)")
    return ap


def main(argv=None) -> int:
    """Run one sub-command (the module docstring); exit status: 0 done, 1 no scene found, 2 bad input."""
    a = parser().parse_args(argv)
    if a.kind == "jitter":
        return _jitter(a)
    if a.kind == "world":
        return _world(a)
    from relocation_app.evaluation.feasibility_cache import planner_params
    from relocation_common.paths import data_dir, scenarios_dir
    params = planner_params()
    data = a.data or data_dir() / "feasibility"
    scenarios = Path(a.scenarios) if a.scenarios else scenarios_dir()
    if a.kind == "generated":
        from relocation_app.evaluation.scenes import generated
        generated.make(params, data, scenarios, a.random)
        return 0
    if a.kind == "paper-random":
        from relocation_app.evaluation.scenes import paper_random
        cases = [int(c) for c in a.cases.split(",")] if a.cases else None
        n = paper_random.make(params, data, scenarios, cases,
                              paper_random.SEED0 if a.seed0 is None else a.seed0, a.minutes)
        return 0 if n == len(cases or paper_random.case_edges()) else 1
    from relocation_app.evaluation.scenes import paper_size
    ok = paper_size.make(a.n, params, data, scenarios, a.seeds, a.steps, a.minutes, a.seed0, a.write_best,
                         a.resume, a.strict, a.temperature, a.radius)
    return 0 if ok else 1


def _jitter(a: argparse.Namespace) -> int:
    from relocation_app.evaluation.scenes.jitter import make_jitter
    try:
        for scene in a.scenes:
            for path in make_jitter(scene, a.amplitude, seed_range(a.seeds), a.out):
                print(path)
    except (OSError, ValueError, RuntimeError) as e:
        print(f"scenes jitter: error: {e}")
        return 2
    return 0


def _world(a: argparse.Namespace) -> int:
    from relocation_app.evaluation.scenes import world
    from relocation_common.paths import scenarios_dir
    out = (Path(a.scenarios) if a.scenarios else scenarios_dir()) / world.DIR
    names = tuple(a.only.split(",")) if a.only else world.ORDER
    unknown = sorted(set(names) - set(world.ORDER))
    if unknown:
        print(f"scenes world: error: unknown scene(s) {', '.join(unknown)}; known: {', '.join(world.ORDER)}")
        return 2
    try:
        world.make_world(out, names)
    except RuntimeError as e:
        print(f"scenes world: error: {e}")
        return 1
    return 0
