#!/usr/bin/env python3
"""The task planner's own share of a training (everything but the motion planner), old vs new, on the real planner's
answers replayed; alternated in fresh processes in one run.

`--record FILE`: the node's call (qtree_task_planner.executive.retrieval.solve_then_train: the A*, then training with a
checkpoint file every `checkpoint_every` episodes, feedback every 10) once with the real MotionPlanner in-process
behind CachedOracle(reuse=True) (the node's `reuse_answers`); every answer it gave (feasibility, certification, lane
blockers) is pickled to FILE, with the planner's own time. Then (`--old DIR`) the same call on the other checkout and
on this tree, `--rounds` times alternately, each in a fresh process, the planner replaced by those answers (a question
never asked in the recording raises: the course would differ). Printed per run: the training's CPU and wall time, the
checkpoints' share (the snapshot of the tree and the file written), the planner calls, E_ss, MP_q, the learned
sequence, and whether old and new agree bit for bit (sequence, weight, E_ss, MP_q, planner answers, the Eq. 15
history, the last checkpoint file but its wall-clock elapsed_s, the final tree's state). Not a timed test: numbers to
read (and paste into docs/bench/).
Usage: .venv/bin/python scripts/bench_training_replay.py --record /tmp/s315.pkl [--scenario scenario3_15]
       .venv/bin/python scripts/bench_training_replay.py --old /tmp/old --answers /tmp/s315.pkl [--rounds 3]
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

COMMON = r"""
import hashlib, json, pickle, sys, tempfile, time
from pathlib import Path
from qtree_task_planner.executive.retrieval import solve_then_train
from qtree_task_planner.learning import training
from qtree_task_planner.learning.checkpoint import save_checkpoint
from qtree_task_planner.learning.params import TrainingParams
from qtree_task_planner.oracles import CachedOracle
from qtree_task_planner.problem import ActionCosts, RelocationProblem
from relocation_common.scenario import load_scenario

spent = {"checkpoints": [0.0, 0.0]}  # part -> [CPU s, wall s]


def timed(part, f):
    def g(*a, **kw):
        c0, w0 = time.process_time(), time.perf_counter()
        try:
            return f(*a, **kw)
        finally:
            spent[part][0] += time.process_time() - c0
            spent[part][1] += time.perf_counter() - w0
    return g


def node_call(name, planner, every):
    sc = load_scenario(name)
    ck_file = Path(tempfile.mkdtemp()) / "checkpoint.json"
    training._Run.snapshot = timed("checkpoints", training._Run.snapshot)
    keep = timed("checkpoints", lambda ck: save_checkpoint(ck, ck_file))
    problem = RelocationProblem.from_scenario(sc, ActionCosts.from_yaml(None))
    oracle = CachedOracle(planner, reuse=True)
    marks = []
    optimum, r = solve_then_train(problem, oracle, TrainingParams.from_yaml(), resume=None,
                                  until_planner=lambda f: f(), keep=keep, on_episode=lambda s: True,
                                  checkpoint_every=every, episode_every=10,
                                  on_solved=lambda o: marks.append((time.process_time(), time.perf_counter())))
    cpu, wall = time.process_time() - marks[0][0], time.perf_counter() - marks[0][1]
    payload = json.loads(ck_file.read_bytes())["payload"]
    digest = lambda x: hashlib.sha256(json.dumps(x, sort_keys=True).encode()).hexdigest()
    return dict(cpu=cpu, wall=wall, ck_cpu=spent["checkpoints"][0], ck_wall=spent["checkpoints"][1],
                optimum=list(optimum.sequence or ()), sequence=list(r.sequence or ()), weight=r.total_weight,
                e_ss=r.e_ss, mp_q=r.mp_q, planner_calls=r.planner_calls, planner_answers=oracle.planner_answers,
                history=digest(r.q_sum_history), checkpoint=digest(dict(payload, elapsed_s=None)),
                tree=digest(r.tree.to_state()))
"""

RECORD = COMMON + r"""
from stpik_motion_planner.planning.params import PlannerParams
from stpik_motion_planner.planning.planner import MotionPlanner


class Recorder:
    def __init__(self, mp):
        self.mp, self.answers, self.planner_s = mp, {}, 0.0

    def _ask(self, kind, f, *key):
        c0 = time.process_time()
        a = f(*key)
        self.planner_s += time.process_time() - c0
        self.answers[(kind,) + key] = a
        return a

    def feasibility(self, o, removed):
        return self._ask("feasibility", self.mp.feasibility, o, frozenset(removed))

    def certify(self, o, removed):
        return self._ask("certify", self.mp.certify, o, frozenset(removed))

    def lane_blockers(self, removed):
        return self._ask("lanes", self.mp.lane_blockers, frozenset(removed))


name, every, out = sys.argv[1], int(sys.argv[2]), sys.argv[3]
rec = Recorder(MotionPlanner(load_scenario(name), PlannerParams.load()))
res = node_call(name, rec, every)
Path(out).write_bytes(pickle.dumps(dict(scenario=name, every=every, answers=rec.answers)))
print(json.dumps(dict(res, planner_cpu=rec.planner_s, answers=len(rec.answers))))
"""

REPLAY = COMMON + r"""
class Replay:
    def __init__(self, answers):
        self.answers = answers

    def feasibility(self, o, removed):
        return self.answers[("feasibility", o, frozenset(removed))]

    def certify(self, o, removed):
        return self.answers[("certify", o, frozenset(removed))]

    def lane_blockers(self, removed):
        return self.answers[("lanes", frozenset(removed))]


rec = pickle.loads(Path(sys.argv[1]).read_bytes())
print(json.dumps(node_call(rec["scenario"], Replay(rec["answers"]), rec["every"])))
"""

SAME = ("optimum", "sequence", "weight", "e_ss", "mp_q", "planner_calls", "planner_answers", "history", "checkpoint",
        "tree")


def child(tree: Path, code: str, *args: str) -> dict:
    """The child's JSON line, run on `tree` (its packages first on sys.path)."""
    env = dict(os.environ, PYTHONPATH=str(tree))
    p = subprocess.run([sys.executable, "-c", code, *args], cwd=tree, env=env, capture_output=True, text=True,
                       timeout=3600)
    if p.returncode != 0:
        sys.exit(f"{tree}: {p.stderr.strip()[-2000:]}")
    return json.loads(p.stdout.strip().splitlines()[-1])


def replay(a: argparse.Namespace) -> None:
    """Old and new alternated, `rounds` times; a table row per run, the medians' ratio, and the agreement."""
    runs: dict[str, list[dict]] = {"old": [], "new": []}
    print("| run | round | training CPU s | wall s | checkpoints CPU s | wall s | E_ss | MP_q | planner calls | "
          "learned |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for k in range(a.rounds):
        for label, tree in (("old", Path(a.old)), ("new", HERE)):
            r = child(tree, REPLAY, a.answers)
            runs[label].append(r)
            print(f"| {label} | {k + 1} | {r['cpu']:.2f} | {r['wall']:.2f} | {r['ck_cpu']:.2f} | {r['ck_wall']:.2f} | "
                  f"{r['e_ss']} | {r['mp_q']} | {r['planner_calls']} | {' '.join(r['sequence'])} "
                  f"({r['weight']:.2f}) |", flush=True)
    for key in ("cpu", "ck_cpu"):
        old, new = (statistics.median(r[key] for r in runs[s]) for s in ("old", "new"))
        print(f"median {key}: old {old:.3f} s, new {new:.3f} s, old / new = {old / max(new, 1e-9):.2f}")
    every = runs["old"] + runs["new"]
    differ = [k for k in SAME if len({json.dumps(r[k]) for r in every}) != 1]
    print("every run the same " + ", ".join(SAME) + ": " + (f"no, {', '.join(differ)} differ" if differ else "yes"))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--record", help="run the real planner once and pickle its answers here")
    ap.add_argument("--scenario", default="scenario3_15")
    ap.add_argument("--checkpoint-every", type=int, default=50, help="config/task_planner.yaml checkpoint_every")
    ap.add_argument("--old", help="a checkout of the old code")
    ap.add_argument("--answers", help="a recording (--record)")
    ap.add_argument("--rounds", type=int, default=3)
    a = ap.parse_args()
    if a.record:
        r = child(HERE, RECORD, a.scenario, str(a.checkpoint_every), a.record)
        print(f"recorded {a.scenario}: {r['answers']} answers, planner {r['planner_cpu']:.2f} s CPU of the whole "
              f"call; training {r['cpu']:.2f} s CPU ({r['wall']:.2f} s wall), checkpoints {r['ck_cpu']:.2f} s CPU, "
              f"E_ss {r['e_ss']}, MP_q {r['mp_q']}, {r['planner_calls']} planner calls, learned "
              f"{' '.join(r['sequence'])} ({r['weight']:.2f}), optimum {' '.join(r['optimum'])}")
    elif a.old and a.answers:
        replay(a)
    else:
        ap.error("give --record FILE, or --old DIR and --answers FILE")


if __name__ == "__main__":
    main()
