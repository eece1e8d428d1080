"""Benchmark: what the push opens among the blocking cycles of perturbed layouts (docs/motion_planner.md, "The push";
rows pasted into docs/bench/push.md). Not a timed test.

For each shipped scene (config/scenarios/*.yaml) x seeds (default 0-3, fixed before any result) a perturbed layout
(`scenes jitter`: every bottle moved by at most 12 mm, kept apart and on the shelf). Per layout, in this process, the
motion planner's lane screen with nothing removed (the certain blockers the blocker A*'s proofs are made of): the layout
has a picks-only "X needs T moved" proof when every grasp lane of the target T holds, besides free objects, an object X
every lane of which holds T (neither can be picked first). For each such X: the push of X out of T's lanes, and the push
of T out of X's lanes, with the free objects gone (those the picks alone can take away first, grown to a fixpoint from
the lanes; MotionPlanner.push_feasibility, the wall-clock safety net raised so that load changes no answer). Each
feasible push is carried out (execution.push.push) in MuJoCo's physics on the layout without the free objects and
checked as test/test_push.py checks it. Printed: one row per layout, and the counts.

    .venv/bin/python scripts/bench_push.py                  # every shipped scene, seeds 0-3, 12 mm
    .venv/bin/python scripts/bench_push.py --seeds 0-7 --amplitude 0.02
    .venv/bin/python scripts/bench_push.py --scenes '*random5/*.yaml'   # the generated scenes of the closed loop
"""
from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "test")]

from test_push import PushWatch, push_problems  # noqa: E402  (after the sys.path insert)

from jaco2_sim_driver.sim import Jaco2Sim  # noqa: E402  (after the sys.path insert)
from relocation_app.evaluation.scenes.jitter import jitter_scene  # noqa: E402  (after the sys.path insert)
from relocation_common.feasibility import Label  # noqa: E402  (after the sys.path insert)
from relocation_common.scenario import parse_scenario  # noqa: E402  (after the sys.path insert)
from stpik_motion_planner.planning.params import PlannerParams  # noqa: E402  (after the sys.path insert)
from stpik_motion_planner.planning.planner import MotionPlanner  # noqa: E402  (after the sys.path insert)

SAFETY_NET = 600.0  # s: the wall-clock nets raised (the work budgets decide the answers)


def free_objects(lanes: dict) -> set[str]:
    """The objects the picks alone can take away first, grown to a fixpoint from the screen's lanes (as the
    blocker A*'s proofs are): an object with a lane whose blockers are all free is free."""
    free: set[str] = set()
    grew = True
    while grew:
        grew = False
        for x, ls in lanes.items():
            if x not in free and any(b.objects <= free for b in ls):
                free.add(x)
                grew = True
    return free


def stuck_beside_target(planner: MotionPlanner) -> tuple[list[str] | None, set[str]]:
    """(the objects X in the target's lanes, not free, every lane of which holds the target, when every lane of the
    target holds one besides free objects: the picks-only proof "X needs T moved"; None when there is no such
    proof or the target is free; the free objects)."""
    t = planner.scenario.target_id
    lanes = planner.lane_blockers([])
    free = free_objects(lanes)
    if t in free or not lanes.get(t):
        return None, free
    stuck = {x for x, ls in lanes.items() if x != t and x not in free and ls and all(t in b.objects for b in ls)}
    if not all((b.objects - free) & stuck for b in lanes[t]):
        return None, free
    return sorted({x for b in lanes[t] for x in b.objects & stuck}), free


def measure(path: Path, amplitude: float, seed: int, params: PlannerParams) -> dict:
    """One layout's row."""
    data = yaml.safe_load(path.read_text())
    d = jitter_scene(data, amplitude, seed)
    planner = MotionPlanner(parse_scenario(d, d["name"]), params)
    t = planner.scenario.target_id
    stuck, free = stuck_beside_target(planner)
    row: dict = {"layout": d["name"], "stuck": stuck, "free": sorted(free), "pushes": []}
    for x in stuck or []:
        for obj, clear in ((x, t), (t, x)):
            t0 = time.process_time()
            ans, plan = planner.push_feasibility(obj, clear, free)
            row["pushes"].append({"push": obj, "clear_for": clear, "feasible": ans.label != Label.UNFEASIBLE,
                                  "message": ans.message, "cpu_s": round(time.process_time() - t0, 2)})
            if plan is not None:
                row["pushes"][-1]["physics"] = replayed(planner.scenario, free, obj, clear, params)
    return row


def replayed(scenario, free: set[str], obj: str, clear: str, params: PlannerParams) -> list[str]:
    """The push carried out (execution.push.push) in MuJoCo's physics on the layout without the free objects (gone
    first, as the plan assumed): what it did otherwise than planned (test_push.push_problems; empty: as predicted)."""
    from stpik_motion_planner.execution.push import push

    rest = scenario.with_objects([o for o in scenario.objects if o.id not in free])
    sim = Jaco2Sim(rest)
    start = {p.id: np.array(p.position) for p in sim.object_poses()}
    watch = PushWatch(sim, obj)
    try:
        plan = push(MotionPlanner(rest, params), watch, obj, clear, [])
    except Exception as e:  # the follower, the planner: said
        return [f"{type(e).__name__}: {e}"]
    watch.step(300)
    return push_problems(sim, watch, plan, start, plan.end)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="0-3")
    ap.add_argument("--amplitude", type=float, default=0.012)
    ap.add_argument("--scenes", default="*.yaml", help="glob under config/scenarios (e.g. '*random5/*.yaml')")
    args = ap.parse_args()
    lo, hi = (int(x) for x in args.seeds.split("-"))
    params = dataclasses.replace(PlannerParams.load(), timeout=SAFETY_NET, carry_timeout=SAFETY_NET)
    scenes = sorted((ROOT / "config" / "scenarios").glob(args.scenes))
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
                               + (f" in MuJoCo: {'as predicted' if not p['physics'] else p['physics']}"
                                  if "physics" in p else "") for p in row["pushes"])
            print(f"{row['layout']}: " + (f"'{', '.join(row['stuck'])} needs T moved'; {pushes}" if row["stuck"]
                                          else "no such proof"), flush=True)
    ok = [r for r in rows if "error" not in r]
    proofs = [r for r in ok if r["stuck"]]
    opened = [r for r in proofs if any(p["feasible"] for p in r["pushes"])]
    by_x = [r for r in proofs if any(p["feasible"] and p["clear_for"] == "T" for p in r["pushes"])]
    physics = [p for r in proofs for p in r["pushes"] if "physics" in p]
    print(f"layouts {len(ok)} ({len(rows) - len(ok)} not made); with an 'X needs T moved' proof {len(proofs)}; "
          f"a feasible push opening it {len(opened)}/{len(proofs)} (a push of X out of T's lanes: {len(by_x)}); "
          f"feasible pushes replayed in MuJoCo as predicted {sum(not p['physics'] for p in physics)}/{len(physics)}")


if __name__ == "__main__":
    main()
