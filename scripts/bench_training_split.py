#!/usr/bin/env python3
"""Where the task_planner node's training time goes, with the real motion planner in-process; old vs new in one run.

Runs the node's call (qtree_task_planner.executive.retrieval.solve_then_train: the A*, then training with a
checkpoint written every `checkpoint_every` episodes as the node's keeper does, feedback every 10 episodes) on one
scene with MotionPlanner in this process behind CachedOracle(reuse=True) (the node's `reuse_answers`), in two
subprocesses: one on another checkout (--old DIR, e.g. `git worktree add /tmp/old <commit>`) and one on this tree,
one after the other. Prints the split of the training's wall and CPU time: the planner's feasibility answers (by
kind: refused after the whole attempt budget, refused at once, feasible), its certifications, the checkpoints
written, and the rest (the Q-Tree's episodes in the C kernel, reuse and claim lookups, feedback); and whether both
runs agree (sequence, episodes, MP_q, planner answers, the Eq. 15 history, every answer's label, attempts and
message, the last checkpoint but its wall-clock elapsed_s). Not a timed test: numbers to read (and paste into
docs/bench/).
Usage: .venv/bin/python scripts/bench_training_split.py --old /tmp/old [--scenario scenario3_15]
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent.parent

CHILD = r"""
import hashlib, json, sys, tempfile, time
from pathlib import Path
from qtree_task_planner.executive.retrieval import solve_then_train
from qtree_task_planner.learning.checkpoint import save_checkpoint
from qtree_task_planner.learning.params import TrainingParams
from qtree_task_planner.oracles import CachedOracle
from qtree_task_planner.problem import ActionCosts, RelocationProblem
from relocation_common.feasibility import Label
from relocation_common.scenario import load_scenario
from stpik_motion_planner.planning.params import PlannerParams
from stpik_motion_planner.planning.planner import MotionPlanner

name, every = sys.argv[1], int(sys.argv[2])
sc = load_scenario(name)
mp = MotionPlanner(sc, PlannerParams.load())
clock = {"wall": time.perf_counter, "cpu": time.process_time}
spent = {}  # (part, clock) -> seconds; (part, "n") -> count
answers = []


def add(part, t0, n=1):
    for k, c in clock.items():
        spent[(part, k)] = spent.get((part, k), 0.0) + c() - t0[k]
    spent[(part, "n")] = spent.get((part, "n"), 0) + n


def timed(part_of, f):
    def g(*a, **kw):
        t0 = {k: c() for k, c in clock.items()}
        r = f(*a, **kw)
        add(part_of(r), t0)
        if hasattr(r, "label"):
            answers.append([part_of(r), a[0], sorted(a[1]), int(r.label), r.attempts, r.message])
        return r
    return g


def kind(r):
    if Label(r.label) != Label.UNFEASIBLE:
        return "feasible"
    return "refused after attempts" if r.attempts else "refused at once"


mp.feasibility = timed(kind, mp.feasibility)
mp.certify = timed(lambda r: "certification", mp.certify)
mp.lane_blockers = timed(lambda r: "lane blockers", mp.lane_blockers)
ck_file = Path(tempfile.mkdtemp()) / "checkpoint.json"


def keep(ck):
    t0 = {k: c() for k, c in clock.items()}
    save_checkpoint(ck, ck_file)
    add("checkpoints", t0)


problem = RelocationProblem.from_scenario(sc, ActionCosts.from_yaml(None))
oracle = CachedOracle(mp, reuse=True)
marks = []
start = {k: c() for k, c in clock.items()}
optimum, r = solve_then_train(problem, oracle, TrainingParams.from_yaml(), resume=None, until_planner=lambda f: f(),
                              keep=keep, on_episode=lambda s: True, checkpoint_every=every, episode_every=10,
                              on_solved=lambda o: marks.append(({k: c() for k, c in clock.items()}, dict(spent))))
end = {k: c() for k, c in clock.items()}
at, before = marks[0]
split = {f"{p}|{k}": v - before.get((p, k), 0) for (p, k), v in spent.items()}
print(json.dumps(dict(
    solve={k: at[k] - start[k] for k in clock}, train={k: end[k] - at[k] for k in clock}, split=split,
    optimum=list(optimum.sequence or ()), sequence=list(r.sequence or ()), episodes=r.episodes, mp_q=r.mp_q,
    planner_answers=oracle.planner_answers, history=r.q_sum_history[-1] if r.q_sum_history else None,
    answers=hashlib.sha256(json.dumps(answers).encode()).hexdigest(),
    checkpoint=hashlib.sha256(json.dumps(dict(json.loads(ck_file.read_bytes())["payload"], elapsed_s=None),
                                          sort_keys=True).encode()).hexdigest(),
    checkpoint_bytes=ck_file.stat().st_size)))
"""

PARTS = ("refused after attempts", "refused at once", "feasible", "certification", "lane blockers", "checkpoints")
SAME = ("optimum", "sequence", "episodes", "mp_q", "planner_answers", "history", "answers", "checkpoint")


def run(tree: Path, scenario: str, every: int) -> dict:
    """The child's JSON, run on `tree` (its packages first on sys.path)."""
    env = dict(os.environ, PYTHONPATH=str(tree))
    p = subprocess.run([sys.executable, "-c", CHILD, scenario, str(every)], cwd=tree, env=env, capture_output=True,
                       text=True, timeout=3600)
    if p.returncode != 0:
        sys.exit(f"{tree}: {p.stderr.strip()[-2000:]}")
    return json.loads(p.stdout.strip().splitlines()[-1])


def rows(label: str, r: dict) -> list[str]:
    """Table rows of one run: each part's calls, wall s, CPU s and share of the training's wall time."""
    s, total = r["split"], r["train"]
    out, wall, cpu = [], 0.0, 0.0
    for p in PARTS:
        if f"{p}|n" in s:
            w, c = s[f"{p}|wall"], s[f"{p}|cpu"]
            wall, cpu = wall + w, cpu + c
            out.append(f"| {label} | {p} | {s[f'{p}|n']} | {w:.2f} | {c:.2f} | {100 * w / total['wall']:.1f} % |")
    rest_w, rest_c = total["wall"] - wall, total["cpu"] - cpu
    out.append(f"| {label} | the rest (Q-Tree kernel, reuse lookups, feedback) | | {rest_w:.2f} | {rest_c:.2f} | "
               f"{100 * rest_w / total['wall']:.1f} % |")
    out.append(f"| {label} | **training** | {r['episodes']} episodes | {total['wall']:.2f} | {total['cpu']:.2f} | "
               "100 % |")
    return out


def main() -> None:
    """Old, then new; the split table, the ratio of the checkpoints' and the training's time, and the agreement."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--old", required=True, help="a checkout of the old code")
    ap.add_argument("--scenario", default="scenario3_15")
    ap.add_argument("--checkpoint-every", type=int, default=50, help="config/task_planner.yaml checkpoint_every")
    a = ap.parse_args()
    old, new = run(Path(a.old), a.scenario, a.checkpoint_every), run(HERE, a.scenario, a.checkpoint_every)
    print(f"scene {a.scenario}: the node's solve_then_train, MotionPlanner in-process, CachedOracle(reuse=True), "
          f"checkpoint every {a.checkpoint_every} episodes; A* {old['solve']['wall']:.1f} / "
          f"{new['solve']['wall']:.1f} s wall (old / new), optimum {' '.join(new['optimum'])}, "
          f"learned {' '.join(new['sequence'])}, "
          f"{new['planner_answers']} planner answers, MP_q {new['mp_q']}, last checkpoint {new['checkpoint_bytes']} B")
    print("| run | part | calls | wall s | CPU s | share of training wall |")
    print("|---|---|---|---|---|---|")
    for line in rows("old", old) + rows("new", new):
        print(line)
    for p, k in (("checkpoints", "cpu"), ("checkpoints", "wall")):
        print(f"{p} {k}: old / new = {old['split'][f'{p}|{k}'] / max(1e-9, new['split'][f'{p}|{k}']):.2f}")
    print(f"training CPU: old / new = {old['train']['cpu'] / max(1e-9, new['train']['cpu']):.3f}")
    differ = [k for k in SAME if old[k] != new[k]]
    print("same " + ", ".join(SAME) + " (the last checkpoint but its elapsed_s, a wall time): "
          + (f"no, {', '.join(differ)} differ" if differ else "yes"))


if __name__ == "__main__":
    main()
