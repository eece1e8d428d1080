#!/usr/bin/env python3
"""CPU time of a feasible answer (the pick) on the same seeded questions, on this tree and on another checkout.

120 random questions (object, removed set of 0-6 obstacles; random.Random(0)) on scenario3_15, asked of one
MotionPlanner in-process; prints the feasible answers' CPU time p50 / p95 and, where the tree has it, the part spent
on the near set (planning/pick.near_objects, the reuse's). --old DIR runs the same on another checkout, e.g. one
from before certification was the default (`git archive 7301738^ | tar -x -C /tmp/pre`: its planner was the
module feasibility.py of the motion planner package then). Not a timed test: numbers to read.
Usage: .venv/bin/python scripts/bench_pick_cpu.py [--old DIR]
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent.parent

CHILD = r"""
import importlib, random, time
try:
    from stpik_motion_planner.planning.params import PlannerParams
    from stpik_motion_planner.planning.planner import MotionPlanner
    pick = importlib.import_module("stpik_motion_planner.planning.pick")
except ImportError:  # the planner before it was split by phase
    from stpik_motion_planner.feasibility import MotionPlanner, PlannerParams
    pick = None
from relocation_common.feasibility import Label
from relocation_common.scenario import load_scenario

sc = load_scenario("scenario3_15")
mp = MotionPlanner(sc, PlannerParams.load())
near = []
if pick is not None and hasattr(pick, "near_objects"):
    f = pick.near_objects
    def g(*a, **k):
        t = time.process_time(); r = f(*a, **k); near.append(time.process_time() - t); return r
    pick.near_objects = g
rng, ids, rows = random.Random(0), [o for o in sc.ids if o != sc.target_id], []
for _ in range(120):
    o = rng.choice(sc.ids)
    rem = frozenset(rng.sample([x for x in ids if x != o], rng.randint(0, 6)))
    n0, t = len(near), time.process_time()
    a = mp.feasibility(o, rem)
    dt = time.process_time() - t
    if Label(a.label) != Label.UNFEASIBLE:
        rows.append((dt, near[-1] if len(near) > n0 else 0.0))
d, n = sorted(r[0] for r in rows), sorted(r[1] for r in rows)
q = lambda v, p: 1000 * v[min(len(v) - 1, int(p * len(v)))]
print(f"{len(rows)} feasible of 120: CPU p50 {q(d, .5):.1f} ms, p95 {q(d, .95):.1f} ms; near set p50 {q(n, .5):.1f} "
      f"ms ({100 * sum(n) / sum(d):.0f} % of the feasible answers' CPU)")
"""


def run(tree: Path) -> str:
    """The child's line, run on `tree` (its packages first on sys.path)."""
    p = subprocess.run([sys.executable, "-c", CHILD], cwd=tree, env=dict(os.environ, PYTHONPATH=str(tree)),
                       capture_output=True, text=True, timeout=1800)
    if p.returncode != 0:
        sys.exit(f"{tree}: {p.stderr.strip()[-2000:]}")
    return p.stdout.strip().splitlines()[-1]


def main() -> None:
    """This tree, then --old if given."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--old", help="another checkout")
    a = ap.parse_args()
    print(f"this tree: {run(HERE)}")
    if a.old:
        print(f"{a.old}: {run(Path(a.old))}")


if __name__ == "__main__":
    main()
