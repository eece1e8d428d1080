#!/usr/bin/env python3
"""The task_planner node's training, old engine vs this tree's, side by side in one run.

The node trains with a per-episode callback (action feedback) and checkpoints every `checkpoint_every` episodes
(config/task_planner.yaml), after the exact solve (qtree_task_planner.executive.retrieval.solve_then_train). This runs
that same call (same scene, seeds, parameters, feasibility answers) in two subprocesses: one on another checkout
(--old DIR, e.g. `git worktree add /tmp/old <commit>` or `git archive <commit> | tar -x -C /tmp/old`) and one on
this tree. Feasibility comes from the committed planner answers (data/feasibility/), so what is timed is the
training engine, not the motion planner. The feedback callback stands in for publish_feedback (a no-op).
Usage: .venv/bin/python scripts/bench_node_training.py --old /tmp/old [--scenario paper_experiment_10] [--seeds 5]
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent.parent

CHILD = r"""
import inspect, json, sys, time
from qtree_task_planner.oracles import CachedOracle
from qtree_task_planner.learning.params import TrainingParams
from qtree_task_planner.problem import RelocationProblem
from qtree_task_planner.executive.retrieval import solve_then_train
from qtree_task_planner.learning.training import train
from relocation_app.evaluation.__main__ import planner_params
from relocation_app.evaluation.feasibility_cache import PlannerOracle, cache_key, cache_path, load_table
from relocation_common.scenario import load_scenario

name, seeds = sys.argv[1], int(sys.argv[2])
sc = load_scenario(name)
pp = planner_params()
table = load_table(cache_path(sc, pp), cache_key(sc, pp))
problem = RelocationProblem.from_scenario(sc)
base = TrainingParams.from_yaml()
every = 50  # config/task_planner.yaml checkpoint_every
out = []
for seed in range(seeds):
    oracle = CachedOracle(PlannerOracle(sc, None, table))
    feedback, kept, solved = [], [], []
    t0 = time.process_time()
    optimum, r = solve_then_train(problem, oracle, base.replace(seed=seed), resume=None, until_planner=lambda f: f(),
                                  keep=kept.append, on_episode=lambda s: feedback.append(s.episode) or True,
                                  checkpoint_every=every, on_solved=lambda o: solved.append(time.process_time()))
    dt = time.process_time() - solved[0]
    out.append(dict(seed=seed, s=dt, solve=solved[0] - t0, episodes=r.episodes, sequence=list(r.sequence or ()),
                    mp_q=r.mp_q, history=r.q_sum_history[-1], feedback=len(feedback), checkpoints=len(kept)))
print(json.dumps(out))
"""


def run(tree: Path, scenario: str, seeds: int) -> list[dict]:
    env = dict(os.environ, PYTHONPATH=str(tree))
    p = subprocess.run([sys.executable, "-c", CHILD, scenario, str(seeds)], cwd=tree, env=env, capture_output=True,
                       text=True, timeout=3600)
    if p.returncode != 0:
        sys.exit(f"{tree}: {p.stderr.strip()[-2000:]}")
    return json.loads(p.stdout)


def main() -> None:
    """Print one table row per engine: CPU seconds of the exact solve and of the training (medians), episodes,
    and whether the results agree."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--old", required=True, help="a checkout of the old code")
    ap.add_argument("--scenario", default="paper_experiment_10")
    ap.add_argument("--seeds", type=int, default=5)
    a = ap.parse_args()
    old, new = run(Path(a.old), a.scenario, a.seeds), run(HERE, a.scenario, a.seeds)
    same = all((o["episodes"], o["sequence"], o["mp_q"], o["history"]) == (n["episodes"], n["sequence"], n["mp_q"],
                                                                            n["history"]) for o, n in zip(old, new))
    print(f"scene {a.scenario}, {a.seeds} seeds, the node's call (feedback callback, checkpoint every 50 episodes)")
    print("| engine | exact solve CPU s | training CPU s (median) | episodes (median) | feedback calls | checkpoints |")
    print("|---|---|---|---|---|---|")
    for label, rows in (("old (reference loop: on_checkpoint)", old), ("new (C kernel, batches)", new)):
        print(f"| {label} | {statistics.median(r['solve'] for r in rows):.3f} | "
              f"{statistics.median(r['s'] for r in rows):.3f} | "
              f"{statistics.median(r['episodes'] for r in rows):.0f} | "
              f"{statistics.median(r['feedback'] for r in rows):.0f} | "
              f"{statistics.median(r['checkpoints'] for r in rows):.0f} |")
    speed = statistics.median(o["s"] for o in old) / max(1e-9, statistics.median(n["s"] for n in new))
    print(f"\ntraining speed-up {speed:.1f}x; same episodes, sequence, MP_q and final Eq. 15 sum: {same}")


if __name__ == "__main__":
    main()
