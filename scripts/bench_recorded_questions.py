#!/usr/bin/env python3
"""The feasibility questions of a recording (scripts/bench_training_replay.py --record) asked again of the planner of
this tree and of another checkout (`--old DIR`), each in its own fresh process (both at once: a change of the
machine's load hits both), every question in the recorded order of one MotionPlanner, as the training asked them.

Printed: per tree the planner's CPU (process time) over the questions, and per answer against the recording: labels
that changed (question, recorded and new label and message), feasible answers whose trajectory changed, answers
whose attempts or message changed (counted, a few shown). Not a timed test: numbers to read (docs/bench/).
Usage: .venv/bin/python scripts/bench_recorded_questions.py --answers /tmp/s315.pkl --old /work/main
"""
from __future__ import annotations

import argparse
import hashlib
import json
import os
import pickle
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent.parent

ASK = r"""
import hashlib, json, pickle, sys, time
import numpy as np
from relocation_common.scenario import load_scenario
from stpik_motion_planner.planning.params import PlannerParams
from stpik_motion_planner.planning.planner import MotionPlanner
rec = pickle.loads(open(sys.argv[1], "rb").read())
mp = MotionPlanner(load_scenario(rec["scenario"]), PlannerParams.load())
out = []
for k in rec["answers"]:
    if k[0] != "feasibility":
        continue
    c0 = time.process_time()
    a = mp.feasibility(k[1], k[2], timeout=300.0)
    cpu = time.process_time() - c0
    traj = "" if a.trajectory is None else hashlib.sha256(
        np.ascontiguousarray(a.trajectory.positions).tobytes()).hexdigest()
    out.append([k[1], sorted(k[2]), a.label.name, a.attempts, a.message, traj, cpu])
print(json.dumps(out))
"""


def traj_digest(a: object) -> str:
    """The recorded answer's trajectory as the child digests it."""
    import numpy as np
    t = getattr(a, "trajectory", None)
    return "" if t is None else hashlib.sha256(np.ascontiguousarray(t.positions).tobytes()).hexdigest()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--answers", required=True, help="a recording (bench_training_replay.py --record)")
    ap.add_argument("--old", required=True, help="a checkout of the old code")
    a = ap.parse_args()
    procs = {}
    for label, tree in (("old", Path(a.old)), ("new", HERE)):
        env = dict(os.environ, PYTHONPATH=str(tree))
        procs[label] = subprocess.Popen([sys.executable, "-c", ASK, a.answers], cwd=tree, env=env,
                                        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    got = {}
    for label, p in procs.items():
        out, err = p.communicate()
        if p.returncode:
            sys.exit(f"{label}: {err.strip()[-2000:]}")
        got[label] = json.loads(out.strip().splitlines()[-1])
    rec = pickle.loads(Path(a.answers).read_bytes())["answers"]
    recorded = [(k, v) for k, v in rec.items() if k[0] == "feasibility"]
    for label, rows in got.items():
        labels, trajs, other = [], 0, []
        for (k, v), (_, _, lab, att, msg, traj, _) in zip(recorded, rows):
            if lab != v.label.name:
                labels.append(f"{k[1]} removed {sorted(k[2])}: {v.label.name} ({v.message}) -> {lab} ({msg})")
            elif traj != traj_digest(v):
                trajs += 1
            elif (att, msg) != (v.attempts, v.message):
                other.append(f"{k[1]}: {v.attempts} '{v.message}' -> {att} '{msg}'")
        cpu = sum(r[-1] for r in rows)
        feasible = sum(r[2] != "UNFEASIBLE" for r in rows)
        print(f"{label}: {len(rows)} questions, {feasible} feasible, planner CPU {cpu:.2f} s; against the recording: "
              f"{len(labels)} labels changed, {trajs} feasible trajectories changed, {len(other)} answers changed in "
              f"attempts or message only")
        for line in labels + other[:3]:
            print("   ", line)
    old, new = (sum(r[-1] for r in got[s]) for s in ("old", "new"))
    print(f"planner CPU old / new = {old / max(new, 1e-9):.2f}")


if __name__ == "__main__":
    main()
