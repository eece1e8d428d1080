"""Benchmark: plans on layouts nobody tuned (docs/benchmarks.md, "Perturbed layouts"). Not a timed test.

For each shipped scene x seeds x amplitudes, a perturbed layout (`scenes jitter`: every bottle moved by at
most 12 or 20 mm, kept apart and on the shelf); per layout, in a fresh process (as `./run qtree solve --scenario F
--oracle planner` runs: one planner, OMPL seeded as configured, no cache; the wall-clock safety nets raised to
SAFETY_NET so that a loaded machine changes no answer), the exact solve (`--solver`, default
the blocker A*) with the real motion planner, then the optimum's relocations planned (relocation.plan_relocation,
as the RelocateObject action plans them) and replayed in MuJoCo by the independent checker (test/motion_checker.py),
contacts counted. Reported: fraction solved, fraction executed with 0 contacts, planner calls and wall per solve
(median, p95, max), and every failure's reason.

    .venv/bin/python scripts/bench_perturbed_layouts.py                      # default: 4 scenes x 2 seeds x 12/20 mm
    .venv/bin/python scripts/bench_perturbed_layouts.py --all --seeds 0-3    # every shipped scene, 4 seeds (hours)
    .venv/bin/python scripts/bench_perturbed_layouts.py --set seed_per_query=true   # a planner parameter changed
    .venv/bin/python scripts/bench_perturbed_layouts.py --all --seeds 0-2 --out rows.jsonl   # resumable
"""
from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "test")]

DEFAULT_SCENES = ("paper_experiment_10", "scenario2_10", "scenario3_15", "paper2_10")


def shipped_scenes() -> list[str]:
    """Every shipped relocation scene (blocking_* are BlockingOracle scenes, not relocation scenes)."""
    from relocation_common.paths import scenarios_dir
    root = scenarios_dir()
    names = [p.stem for p in sorted(root.glob("*.yaml")) if not p.stem.startswith("blocking_")]
    return names + [f"{d}/{p.stem}" for d in ("random5", "paper_random5") for p in sorted((root / d).glob("*.yaml"))]


SAFETY_NET = 300.0  # s: the wall-clock safety nets, far above the work budgets on a loaded machine (no answer moves)


def _params(sets: list[str]):
    """config/motion_planner.yaml with the `key=value` changes, the safety nets at SAFETY_NET."""
    import dataclasses

    from stpik_motion_planner.planning.planner import PlannerParams
    base = dataclasses.replace(PlannerParams.load(), timeout=SAFETY_NET, carry_timeout=SAFETY_NET)
    if not sets:
        return base
    import yaml

    from relocation_common.config import node_section
    from relocation_common.paths import config_file
    flat = {k: v for k, v in node_section(config_file("motion_planner.yaml"), "motion_planner").items()
            if k in PlannerParams.keys()}
    for kv in sets:
        k, _, v = kv.partition("=")
        flat[k] = yaml.safe_load(v)
    return dataclasses.replace(PlannerParams.from_mapping(flat), timeout=SAFETY_NET, carry_timeout=SAFETY_NET)


def one(path: str, solver: str, sets: list[str]) -> dict:
    """Solve one layout and replay its optimum (run in its own process)."""
    from motion_checker import MotionChecker, Report, replay_relocation

    from qtree_task_planner.oracles import CachedOracle
    from qtree_task_planner.problem import RelocationProblem
    from qtree_task_planner.search import astar, exact
    from relocation_common.feasibility import Label
    from relocation_common.scenario import load_scenario
    from stpik_motion_planner.execution.relocation import plan_relocation
    from stpik_motion_planner.planning.planner import MotionPlanner, PlanningError

    sc = load_scenario(path)
    planner = MotionPlanner(sc, _params(sets))
    cache = CachedOracle(planner)
    t0, c0 = time.perf_counter(), time.process_time()
    result = {"astar": astar.solve, "ucs": exact.solve}[solver](RelocationProblem.from_scenario(sc), cache)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    out = {"layout": sc.name, "found": result.found, "sequence": result.sequence, "weight": result.total_weight,
           "calls": cache.calls, "wall": round(wall, 2), "cpu": round(cpu, 2), "executed": False, "contacts": None,
           "reason": ""}
    if not result.found:
        reason = getattr(result, "reason", "")
        if not reason:  # the solver gives none: the target's last unfeasible answer
            last = [a.message for (o, _), a in cache.table.items() if o == sc.target_id
                    and Label(a.label) == Label.UNFEASIBLE]
            reason = f"no sequence; {sc.target_id}: {last[-1] if last else 'never asked'}"
        out["reason"] = reason
        return out
    checker, rep = MotionChecker(sc), Report()
    done: list[str] = []
    try:
        for oid in result.sequence or ():
            plan = plan_relocation(planner, oid, done)
            rep.merge(replay_relocation(checker, plan.pick, [plan.carry, plan.retreat], plan.home, oid))
            done.append(oid)
    except PlanningError as e:
        out["reason"] = f"execution not planned: {e}"
        return out
    out.update(executed=True, contacts=len(rep.contacts), relocations=len(done))
    if rep.contacts:
        out["reason"] = f"{len(rep.contacts)} contacts, deepest {rep.max_depth * 1000:.1f} mm: {rep.contacts[0]}"
    return out


def _pct(xs, q):
    xs = sorted(xs)
    return xs[min(len(xs) - 1, int(round(q * (len(xs) - 1))))] if xs else float("nan")


def summarize(rows: list[dict], label: str) -> str:
    """One markdown row per amplitude and the failures' reasons."""
    lines = []
    for amp in sorted({r["amp"] for r in rows}):
        rs = [r for r in rows if r["amp"] == amp]
        n = len(rs)
        solved = sum(r["found"] for r in rs)
        clean = sum(r["executed"] and r["contacts"] == 0 for r in rs)
        cycles = sum(not r["found"] and "blocking cycle" in (r["reason"] or "") for r in rs)
        calls, wall = [r["calls"] for r in rs], [r["wall"] for r in rs]
        cpu = [r["cpu"] for r in rs if "cpu" in r]  # rows of runs before the CPU column have none
        lines.append(f"| {label} | {amp} mm | {n} | {solved}/{n} ({100 * solved / n:.0f} %) | "
                     f"{clean}/{n} ({100 * clean / n:.0f} %) | {cycles} | {clean}/{n - cycles} "
                     f"({100 * clean / max(1, n - cycles):.0f} %) | "
                     f"{statistics.median(calls):.0f} / {_pct(calls, .95)} / {max(calls)} | "
                     f"{statistics.median(wall):.1f} / {_pct(wall, .95):.1f} / {max(wall):.1f} | "
                     + (f"{statistics.median(cpu):.1f} / {_pct(cpu, .95):.1f} |" if cpu else "- |"))
    fails = [f"- {r['layout']}: {r['reason']}" for r in rows if r["reason"]]
    return "\n".join(lines + (["", "Failures:"] + fails if fails else []))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", nargs="*", default=list(DEFAULT_SCENES))
    ap.add_argument("--all", action="store_true", help="every shipped relocation scene")
    ap.add_argument("--seeds", default="0-1", help="jitter seeds (scenes jitter --seeds), default 0-1")
    ap.add_argument("--amplitudes", default="0.012,0.020", help="m, comma-separated")
    ap.add_argument("--solver", choices=("astar", "ucs"), default="astar")
    ap.add_argument("--set", action="append", default=[], help="planner parameter key=value (repeatable)")
    ap.add_argument("--label", default="", help="row label in the table (default: the --set values or 'today')")
    ap.add_argument("--json", default=None, help="write every row here")
    ap.add_argument("--out", default=None, help="JSON lines: every row appended as it ends; layouts already in it "
                    "are not run again (a run cut short goes on where it stopped), the table covers them all")
    ap.add_argument("--one", default=None, help=argparse.SUPPRESS)
    ap.add_argument("--table", default=None, help="print the table of an --out file and stop")
    a = ap.parse_args()
    if a.table:
        print(table([json.loads(x) for x in Path(a.table).read_text().splitlines() if x.strip()], a.label or "today"))
        return 0
    if a.one:
        print(json.dumps(one(a.one, a.solver, a.set)))
        return 0
    from relocation_app.evaluation.scenes.cli import seed_range
    from relocation_app.evaluation.scenes.jitter import make_jitter
    scenes = shipped_scenes() if a.all else a.scenes
    out = Path(a.out) if a.out else None
    rows = [json.loads(x) for x in out.read_text().splitlines() if x.strip()] if out and out.exists() else []
    done = {(r["layout"], r["amp"]) for r in rows}
    with tempfile.TemporaryDirectory() as tmp:
        for scene in scenes:  # scene by scene, both amplitudes: a run stopped early is still a sample of both
            for amp in (float(x) for x in a.amplitudes.split(",")):
                for path in make_jitter(scene, amp, seed_range(a.seeds), tmp):
                    if (path.stem, int(round(amp * 1000))) in done:
                        continue
                    cmd = [sys.executable, __file__, "--one", str(path), "--solver", a.solver]
                    for kv in a.set:
                        cmd += ["--set", kv]
                    p = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT)
                    try:
                        row = json.loads(p.stdout.strip().splitlines()[-1])
                    except (IndexError, json.JSONDecodeError):
                        row = {"layout": path.stem, "found": False, "executed": False, "contacts": None, "calls": 0,
                               "wall": 0.0, "reason": f"crashed: {p.stderr.strip().splitlines()[-1:]}"}
                    row["amp"] = int(round(amp * 1000))
                    rows.append(row)
                    print(json.dumps(row), flush=True)
                    if out:
                        with out.open("a") as f:
                            f.write(json.dumps(row) + "\n")
    if a.json:
        Path(a.json).write_text(json.dumps(rows, indent=1))
    print(table(rows, a.label or (", ".join(a.set) or "today")))
    return 0


def table(rows: list[dict], label: str) -> str:
    """The markdown table: a blocking cycle (every lane of the target needs an object that can never leave first,
    over the planner's whole grasp set) is a layout with no retrieval, listed with its reason and left out of the
    last rate."""
    return ("\n| code | jitter | layouts | solved | executed, 0 contacts | no retrieval (blocking cycle) | "
            "executed, of the rest | planner calls p50 / p95 / max | wall s p50 / p95 / max | CPU s p50 / p95 |\n"
            "|---|---|---|---|---|---|---|---|---|---|\n" + summarize(rows, label))


if __name__ == "__main__":
    raise SystemExit(main())
