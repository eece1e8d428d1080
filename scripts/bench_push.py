"""Benchmark: what the push opens among the blocking cycles of perturbed layouts (docs/motion_planner.md, "The
push"; rows pasted into docs/bench/push.md). Not a timed test.

For each shipped scene (config/scenarios/*.yaml) x seeds (default 0-3, fixed before any result) a perturbed layout
(`scenes jitter`: every bottle moved by at most 12 mm, kept apart and on the shelf). Per layout, in this process, the
motion planner's lane screen with nothing removed (the certain blockers the blocker A*'s proofs are made of): the
layout has a picks-only "X needs T moved" proof when every grasp lane of the target T holds an object X every lane
of which holds T (neither can be picked first). For each such X: the push of X out of T's lanes, and the push of T
out of X's lanes (MotionPlanner.push_feasibility, the wall-clock safety net raised so that load changes no answer).
Printed: one row per layout, and the counts.

    .venv/bin/python scripts/bench_push.py                  # every shipped scene, seeds 0-3, 12 mm
    .venv/bin/python scripts/bench_push.py --seeds 0-7 --amplitude 0.02
"""
from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT)]

from relocation_app.evaluation.scenes.jitter import jitter_scene  # noqa: E402
from relocation_common.feasibility import Label  # noqa: E402
from relocation_common.scenario import parse_scenario  # noqa: E402
from stpik_motion_planner.planning.params import PlannerParams  # noqa: E402
from stpik_motion_planner.planning.planner import MotionPlanner  # noqa: E402

SAFETY_NET = 600.0  # s: the wall-clock nets raised (the work budgets decide the answers)


def stuck_beside_target(planner: MotionPlanner) -> list[str] | None:
    """The objects X in the target's lanes every lane of which holds the target, when every lane of the target
    holds one (the picks-only proof "X needs T moved"); None when there is no such proof."""
    t = planner.scenario.target_id
    lanes = planner.lane_blockers([])
    if not lanes.get(t):
        return None
    stuck = {x for x, ls in lanes.items() if x != t and ls and all(t in b.objects for b in ls)}
    if not all(b.objects & stuck for b in lanes[t]):
        return None
    return sorted({x for b in lanes[t] for x in b.objects & stuck})


def measure(path: Path, amplitude: float, seed: int, params: PlannerParams) -> dict:
    """One layout's row."""
    data = yaml.safe_load(path.read_text())
    d = jitter_scene(data, amplitude, seed)
    planner = MotionPlanner(parse_scenario(d, d["name"]), params)
    t = planner.scenario.target_id
    row: dict = {"layout": d["name"], "stuck": stuck_beside_target(planner), "pushes": []}
    for x in row["stuck"] or []:
        for obj, clear in ((x, t), (t, x)):
            t0 = time.process_time()
            ans, plan = planner.push_feasibility(obj, clear, [])
            row["pushes"].append({"push": obj, "clear_for": clear, "feasible": ans.label != Label.UNFEASIBLE,
                                  "message": ans.message, "cpu_s": round(time.process_time() - t0, 2)})
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="0-3")
    ap.add_argument("--amplitude", type=float, default=0.012)
    args = ap.parse_args()
    lo, hi = (int(x) for x in args.seeds.split("-"))
    params = dataclasses.replace(PlannerParams.load(), timeout=SAFETY_NET, carry_timeout=SAFETY_NET)
    scenes = sorted((ROOT / "config" / "scenarios").glob("*.yaml"))
    rows = []
    for path in scenes:
        for seed in range(lo, hi + 1):
            try:
                row = measure(path, args.amplitude, seed, params)
            except Exception as e:  # a layout the jitter cannot make, a scene the planner refuses: said, counted
                row = {"layout": f"{path.stem} seed {seed}", "error": f"{type(e).__name__}: {e}"}
            rows.append(row)
            if "error" in row:
                print(f"{row['layout']}: {row['error']}", flush=True)
                continue
            pushes = "; ".join(f"push {p['push']} for {p['clear_for']}: "
                               f"{'FEASIBLE' if p['feasible'] else 'no'} ({p['message']}; {p['cpu_s']} s CPU)"
                               for p in row["pushes"])
            print(f"{row['layout']}: " + (f"'{', '.join(row['stuck'])} needs T moved'; {pushes}" if row["stuck"]
                                          else "no such proof"), flush=True)
    ok = [r for r in rows if "error" not in r]
    proofs = [r for r in ok if r["stuck"]]
    opened = [r for r in proofs if any(p["feasible"] for p in r["pushes"])]
    by_x = [r for r in proofs if any(p["feasible"] and p["clear_for"] == "T" for p in r["pushes"])]
    print(f"layouts {len(ok)} ({len(rows) - len(ok)} not made); with an 'X needs T moved' proof {len(proofs)}; "
          f"a feasible push opening it {len(opened)}/{len(proofs)} (a push of X out of T's lanes: {len(by_x)})")


if __name__ == "__main__":
    main()
