#!/usr/bin/env python3
"""Benchmark of the feasibility query (paper Sect. 4.1) on a 15-bottle shelf: latency p50/p95, answers,
time split into candidate screening, Cartesian RRT-Connect and the STPIK check, plus joint-space RRT-Connect with
the same collision checker for comparison, and a profile of where the time goes.

Usage: .venv/bin/python scripts/bench_motion_planner.py [--queries 150] [--seed 1] [--scenario PATH] [--profile]
       .venv/bin/python scripts/bench_motion_planner.py --baseline 5bd83aa [--rounds 3] [--scenario NAME ...]
Workload: random (object, removed set) pairs as the Q-Tree's training asks them (removed sets of 0-6 obstacles).
--baseline REV: side by side in one run, the planner package (stpik_motion_planner/) of git revision REV against the
working tree's, each in its own fresh process, alternated `--rounds` times so that a change of the machine's load
hits both; prints feasible p50/p95 of each and their ratio, and checks that both gave the same labels.
"""
from __future__ import annotations

import argparse
import cProfile
import io
import json
import os
import pstats
import random
import subprocess
import sys
import tarfile
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # this checkout's packages
# BENCH_IMPL_DIR: a directory holding another stpik_motion_planner/ (--baseline), found first (else this checkout)
sys.path.insert(0, os.environ.get("BENCH_IMPL_DIR", sys.path[0]))

from relocation_common import robot_description as rd
from relocation_common.feasibility import Label
from relocation_common.paths import scenarios_dir
from relocation_common.scenario import load_scenario
from stpik_motion_planner.planning.params import PlannerParams
from stpik_motion_planner.planning.planner import MotionPlanner

REPO = Path(__file__).resolve().parent.parent


def pct(xs, p):
    return float(np.percentile(xs, p)) * 1e3 if len(xs) else float("nan")


def workload(scenario, n, seed):
    rng = random.Random(seed)
    obst = list(scenario.obstacle_ids)
    out = []
    for _ in range(n):
        removed = frozenset(rng.sample(obst, rng.randint(0, 6)))
        choices = [i for i in scenario.ids if i not in removed]
        out.append((rng.choice(choices), removed))
    return out


def latencies(scenario: str, n: int, seed: int) -> list[tuple[str, str, float]]:
    """(object, label, wall s) of each query of the workload, in order, after one warm-up query."""
    sc = load_scenario(scenario)
    mp = MotionPlanner(sc, PlannerParams.load())
    mp.feasibility(sc.ids[0], frozenset())
    out = []
    for oid, removed in workload(sc, n, seed):
        t = time.perf_counter()
        ans = mp.feasibility(oid, removed)
        out.append((oid, ans.label.name, time.perf_counter() - t))
    return out


def export_package(rev: str, package: str = "stpik_motion_planner") -> str:
    """`package`/ of git revision `rev` in a temporary directory."""
    d = tempfile.mkdtemp(prefix="bench_mp_base_")
    tar = subprocess.run(["git", "-C", str(REPO), "archive", rev, package], capture_output=True, check=True).stdout
    with tarfile.open(fileobj=io.BytesIO(tar)) as t:
        t.extractall(d, filter="data")
    return d


def compare(rev: str, scenarios: list[str], n: int, seed: int, rounds: int) -> None:
    """Side by side: REV's planner package and the working tree's, alternated, each run a fresh process."""
    base = export_package(rev)
    for scen in scenarios:
        runs: dict[str, list] = {rev: [], "working tree": []}
        for _ in range(rounds):
            for name, impl in ((rev, base), ("working tree", "")):
                env = dict(os.environ, BENCH_IMPL_DIR=impl)
                out = subprocess.run([sys.executable, __file__, "--latencies", "--scenario", scen, "--queries",
                                      str(n), "--seed", str(seed)], env=env, capture_output=True, text=True,
                                     check=True).stdout
                runs[name].append(json.loads(out.strip().splitlines()[-1]))
        labels = {k: [[r[1] for r in run] for run in v] for k, v in runs.items()}
        same = all(x == labels[rev][0] for v in labels.values() for x in v)
        stats = {}
        for name, rs in runs.items():
            feas = [r[2] for run in rs for r in run if r[1] != "UNFEASIBLE"]
            unf = [r[2] for run in rs for r in run if r[1] == "UNFEASIBLE"]
            stats[name] = (pct(feas, 50), pct(feas, 95), pct(unf, 50), pct(unf, 95), len(feas))
        print(f"{Path(scen).stem}: {n} queries x {rounds} rounds, labels identical: {same}")
        for name, (f50, f95, u50, u95, nf) in stats.items():
            print(f"  {name:14s} feasible ({nf:3d}) p50 {f50:7.2f} ms  p95 {f95:7.2f} ms   "
                  f"unfeasible p50 {u50:6.2f} ms  p95 {u95:6.2f} ms")
        b, w = stats[rev], stats["working tree"]
        print(f"  ratio {rev}/working tree: feasible p50 {b[0] / w[0]:.2f}x  p95 {b[1] / w[1]:.2f}x")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--queries", type=int, default=150)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--scenario", action="append", help="path or name (repeatable with --baseline)")
    ap.add_argument("--profile", action="store_true")
    ap.add_argument("--baseline", help="git revision to compare against, side by side")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--latencies", action="store_true", help=argparse.SUPPRESS)
    a = ap.parse_args()
    names = a.scenario or ["scenario3_15"]
    paths = [n if n.endswith(".yaml") else str(scenarios_dir() / f"{n}.yaml") for n in names]
    if a.baseline:
        return compare(a.baseline, paths, a.queries, a.seed, a.rounds)
    if a.latencies:
        print(json.dumps(latencies(paths[0], a.queries, a.seed)))
        return
    sc = load_scenario(paths[0])
    params = PlannerParams.load()
    mp = MotionPlanner(sc, params)
    queries = workload(sc, a.queries, a.seed)
    mp.feasibility(sc.ids[0], frozenset())  # warm-up (imports, caches)

    rows = []
    prof = cProfile.Profile() if a.profile else None
    for oid, removed in queries:
        if prof:
            prof.enable()
        t = time.perf_counter()
        ans = mp.feasibility(oid, removed)
        wall = time.perf_counter() - t
        if prof:
            prof.disable()
        s = mp.last_stats
        rows.append(dict(oid=oid, removed=removed, label=ans.label, wall=wall, rrt=s.rrt_time, stpik=s.stpik_time,
                         rrt_calls=s.rrt_calls, direct=s.direct_paths, attempts=ans.attempts,
                         budget="budget" in ans.message, traj=ans.trajectory,
                         screened=ans.attempts == 0))
    walls = [r["wall"] for r in rows]
    feas = [r for r in rows if r["label"] != Label.UNFEASIBLE]
    unf = [r for r in rows if r["label"] == Label.UNFEASIBLE]
    print(f"scenario {sc.name}: {len(sc.obstacle_ids)} obstacles; {len(rows)} queries; budget "
          f"{params.rrt_max_checks} checks per RRT attempt, safety net {params.timeout} s; "
          f"seed {a.seed}")
    print(f"feasibility latency  p50 {pct(walls, 50):7.2f} ms   p95 {pct(walls, 95):7.2f} ms   "
          f"max {max(walls) * 1e3:7.2f} ms   mean {np.mean(walls) * 1e3:6.2f} ms")
    print(f"answers: feasible {len(feas)}  unfeasible {len(unf)} (screened by grasp/approach check "
          f"{sum(r['screened'] for r in unf)}, after sampling {sum(not r['screened'] for r in unf)}, "
          f"of which STPIK step budget spent {sum(r['budget'] for r in unf)})")
    for name, sub in (("feasible", feas), ("unfeasible", unf)):
        if sub:
            w = [r["wall"] for r in sub]
            print(f"  {name:10s} p50 {pct(w, 50):7.2f} ms  p95 {pct(w, 95):7.2f} ms   "
                  f"rrt p50 {pct([r['rrt'] for r in sub], 50):6.2f} ms  "
                  f"stpik p50 {pct([r['stpik'] for r in sub], 50):6.2f} ms"
                  f"   mean attempts {np.mean([r['attempts'] for r in sub]):.2f}")
    tot = sum(walls)
    rrt_t = sum(r["rrt"] for r in rows)
    st_t = sum(r["stpik"] for r in rows)
    print(f"time split over all queries: Cartesian RRT-Connect {rrt_t / tot:.1%}, STPIK {st_t / tot:.1%}, "
          f"screening/direct-path checks/other {(tot - rrt_t - st_t) / tot:.1%}")
    print(f"RRT-Connect calls {sum(r['rrt_calls'] for r in rows)}, direct paths accepted "
          f"{sum(r['direct'] for r in rows)}")
    if feas:
        durs = [r["traj"].duration for r in feas]
        vmax = max(float(np.max(np.abs(r["traj"].velocities) / rd.QDOT_MAX)) for r in feas)
        print(f"trajectories: duration p50 {np.median(durs):.2f} s, max |qdot|/limit {vmax:.3f}")

    # the same feasible queries with RRT-Connect always (no direct path first)
    mp.params.direct_first = False
    walls2, rrt2, st2, ok2 = [], [], [], 0
    for r in feas:
        t = time.perf_counter()
        ans = mp.feasibility(r["oid"], r["removed"])
        walls2.append(time.perf_counter() - t)
        rrt2.append(mp.last_stats.rrt_time)
        st2.append(mp.last_stats.stpik_time)
        ok2 += ans.label != Label.UNFEASIBLE
    mp.params.direct_first = True
    if walls2:
        print(f"feasible queries, RRT-Connect always: p50 {pct(walls2, 50):7.2f} ms  p95 {pct(walls2, 95):7.2f} ms  "
              f"rrt p50 {pct(rrt2, 50):6.2f} ms  stpik p50 {pct(st2, 50):6.2f} ms  still feasible {ok2}/{len(walls2)}")

    # joint-space RRT-Connect, same collision checker, home -> the pre-grasp configuration STPIK found
    jt, jok = [], 0
    for r in feas:
        obs = mp.scene.obstacles(r["removed"])
        tr = r["traj"]
        goal = tr.positions[int(np.searchsorted(tr.times, dict(tr.phases)["approach"] - 1e-9))]
        t = time.perf_counter()
        traj = mp.plan_joint(rd.Q_HOME, goal, obs, 4 * params.rrt_max_checks, time.perf_counter() + 10.0, margin=0.0)
        jt.append(time.perf_counter() - t)
        jok += traj is not None
    if jt:
        print(f"joint-space RRT-Connect (same checker, home -> STPIK's pre-grasp configuration): "
              f"p50 {pct(jt, 50):7.2f} ms  p95 {pct(jt, 95):7.2f} ms  solved {jok}/{len(jt)}")
    if prof:
        out = io.StringIO()
        pstats.Stats(prof, stream=out).sort_stats("tottime").print_stats(12)
        text = out.getvalue()
        print("profile (tottime, top 12):")
        print("\n".join(line for line in text.splitlines()[6:] if line.strip()))


if __name__ == "__main__":
    main()
