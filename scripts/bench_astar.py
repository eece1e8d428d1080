"""Benchmark of the blocker A* (docs/qtree.md, astar.solve) against uniform-cost search (not a timed test).

1. Every shipped relocation scene, cold, real motion planner: one `qtree solve` process per (scene, solver) (a
   fresh planner, no cache, OMPL seeded as configured); planner calls and the solver's wall time (planner calls
   included, the process start and the planner's construction not).
2. 15-object blocking instances (test double): blocking_15 and random declared relations (as test_exact's
   instances: each object blocked by 0-3 others), oracle calls of uniform-cost search and of the A* with the
   oracle's lane blockers, and with blockers from its answers only.

    .venv/bin/python scripts/bench_astar.py [--instances 30] [--scenes name ...] [--qtree] [--skip-scenes]
"""
from __future__ import annotations

import argparse
import json
import random
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from qtree_task_planner.oracles import BlockingOracle, CachedOracle
from qtree_task_planner.problem import RelocationProblem
from qtree_task_planner.search import astar, exact
from relocation_common.paths import scenarios_dir
from relocation_common.scenario import load_scenario

WEIGHTS = (0.05, 0.1, 0.25, 0.3, 0.5, 0.7, 1.0)


def shipped_scenes() -> list[str]:
    root = scenarios_dir()
    names = [p.stem for p in sorted(root.glob("*.yaml")) if "blocking" not in load_scenario(p).__dict__
             or load_scenario(p).blocking is None]
    return names + [f"random5/{p.stem}" for p in sorted((root / "random5").glob("*.yaml"))]


def solve_cli(scene: str, solver: str) -> dict:
    """`qtree solve` (solver astar / ucs) or, for solver "qtree", `qtree train` H-eG depth, seed 1."""
    how = ["train", "--policy", "h-eg", "--search", "depth", "--seed", "1", "--no-progress"] if solver == "qtree" \
        else ["solve", "--solver", solver]
    with tempfile.TemporaryDirectory() as d:
        out = Path(d) / "r.json"
        p = subprocess.run([sys.executable, "-m", "relocation_app.cli", *how, "--scenario", scene, "--oracle",
                            "planner", "--json", str(out)], capture_output=True, text=True)
        if p.returncode != 0:
            return {"error": p.stderr.strip().splitlines()[-1]}
        return json.loads(out.read_text())


def _w(r: dict):
    return None if r.get("total_weight") is None else round(r["total_weight"], 4)


def scenes_table(scenes: list[str], qtree: bool) -> None:
    extra = (" Q-Tree calls | Q-Tree s | Q-Tree weight |", "---|---|---|") if qtree else ("", "")
    print("| scene | UCS calls | UCS s | A* calls | A* s | weight (UCS / A*) | A* sequence |" + extra[0])
    print("|---|---|---|---|---|---|---|" + extra[1])
    for s in scenes:
        u, a = solve_cli(s, "ucs"), solve_cli(s, "astar")
        if "error" in u or "error" in a:
            print(f"| {s} | {u.get('error', '')} | | {a.get('error', '')} | | | |")
            continue
        seq = " ".join(a["sequence"]) if a["found"] else "none"
        q = ""
        if qtree:
            t = solve_cli(s, "qtree")
            q = f" {t.get('error', t.get('planner_calls'))} | {t.get('wall_time_s', 0):.1f} | {_w(t)} |" \
                if "error" not in t else f" {t['error']} | | |"
        print(f"| {s} | {u['planner_calls']} | {u['wall_time_s']:.2f} | {a['planner_calls']} | "
              f"{a['wall_time_s']:.2f} | {_w(u)} / {_w(a)} | {seq} |{q}", flush=True)


class AnswersOnly:
    """The oracle without lane_blockers: the A* learns blockers from its unfeasible answers only."""

    def __init__(self, oracle) -> None:
        self.oracle = oracle

    def feasibility(self, object_id, removed):
        return self.oracle.feasibility(object_id, removed)


def random_relation(seed: int, n: int = 15):
    rnd = random.Random(seed)
    obstacles = tuple(f"o{i}" for i in range(n))
    problem = RelocationProblem(obstacles, {o: rnd.choice(WEIGHTS) for o in obstacles}, "T")
    ids = obstacles + ("T",)
    blocking = {o: rnd.sample([x for x in ids if x != o], rnd.randint(0, 3)) for o in ids}
    return problem, BlockingOracle.from_relation(blocking, "T", ids)


def run(solver, problem, oracle) -> tuple[int, float, float | None]:
    cache = CachedOracle(oracle)
    t0 = time.perf_counter()
    r = solver(problem, cache)
    return cache.calls, time.perf_counter() - t0, r.total_weight


def blocking_table(instances: int) -> None:
    sc = load_scenario(scenarios_dir() / "blocking_15.yaml")
    cases = [("blocking_15", RelocationProblem.from_scenario(sc), BlockingOracle(sc))]
    cases += [(f"random seed {s}", *random_relation(s)) for s in range(instances)]
    rows = []
    for name, problem, oracle in cases:
        u = run(exact.solve, problem, oracle)
        a = run(astar.solve, problem, oracle)
        b = run(astar.solve, problem, AnswersOnly(oracle))
        assert (u[2] is None) == (a[2] is None) == (b[2] is None), name
        assert u[2] is None or abs(u[2] - a[2]) < 1e-9 and abs(u[2] - b[2]) < 1e-9, name
        rows.append((name, u, a, b))
    print("| instance | UCS calls | A* calls (lane blockers) | A* calls (answers' blockers) | optimum |")
    print("|---|---|---|---|---|")
    for name, u, a, b in rows[:1]:
        print(f"| {name} | {u[0]} | {a[0]} | {b[0]} | {u[2]} |")
    for k, label in ((0, "calls"), (1, "s")):
        us, as_, bs = ([r[i][k] for r in rows[1:]] for i in (1, 2, 3))
        fmt = (lambda v: f"{v:.0f}") if k == 0 else (lambda v: f"{v * 1e3:.2f} ms")
        print(f"| {len(rows) - 1} random, mean {label} | {fmt(statistics.mean(us))} (max {fmt(max(us))}) | "
              f"{fmt(statistics.mean(as_))} (max {fmt(max(as_))}) | {fmt(statistics.mean(bs))} (max {fmt(max(bs))}) "
              f"| |")
    big = [r for r in rows[1:] if r[1][0] >= 20]
    tot = [sum(r[i][0] for r in rows[1:]) for i in (1, 2, 3)]
    print(f"\nall {len(rows) - 1} random: calls in total UCS {tot[0]}, A* {tot[1]} ({tot[1] / tot[0]:.3f}), answers "
          f"only {tot[2]} ({tot[2] / tot[0]:.3f}); target freed in {sum(r[1][2] is not None for r in rows[1:])}; "
          f"the {len(big)} with >= 20 UCS calls: A*/UCS per instance at most "
          f"{max(r[2][0] / r[1][0] for r in big):.3f} (answers only {max(r[3][0] / r[1][0] for r in big):.3f})")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--instances", type=int, default=30)
    ap.add_argument("--scenes", nargs="*", help="scene names (default: every shipped relocation scene)")
    ap.add_argument("--skip-scenes", action="store_true")
    ap.add_argument("--qtree", action="store_true", help="also train the Q-Tree (H-eG depth, seed 1) per scene")
    args = ap.parse_args()
    if not args.skip_scenes:
        scenes_table(args.scenes or shipped_scenes(), args.qtree)
        print()
    blocking_table(args.instances)


if __name__ == "__main__":
    main()
