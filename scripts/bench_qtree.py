#!/usr/bin/env python3
"""Benchmark of the Q-Tree core on the 15-object blocking instance (config/scenarios/blocking_15.yaml).

Prints: training throughput (episodes per CPU second of this process, so that other jobs on a shared machine
distort it less) for each policy x search, with a cold cache (BlockingOracle behind a
fresh CachedOracle) and a warm shared cache (the evaluation sweeps' case); the exact solver's oracle calls and
time; and a sweep of quiet_episodes (Eq. 16) behind the default in config/task_planner.yaml.
Training runs on the C kernel (qtree_task_planner/learning/kernel.py), the one engine; on a checkout from before it
(no kernel module) the script measures that checkout's loop (before/after comparisons).
Usage: .venv/bin/python scripts/bench_qtree.py [--seeds N] [--episodes E] [--no-sweep]
"""
from __future__ import annotations

import argparse
import platform
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from qtree_task_planner.learning.params import POLICIES, SEARCHES, TrainingParams
from qtree_task_planner.learning.training import train
from qtree_task_planner.oracles import BlockingOracle, CachedOracle
from qtree_task_planner.search.exact import brute_force, solve
from relocation_common.paths import scenarios_dir
from relocation_common.scenario import load_scenario


def throughput(sc, seeds: int, episodes: int) -> list[dict]:
    rows, warm = [], CachedOracle(BlockingOracle(sc))
    opt = solve(sc, BlockingOracle(sc)).total_weight
    for policy in POLICIES:
        for search in SEARCHES:
            p = TrainingParams.defaults().replace(policy=policy, search=search, max_episodes=episodes, beta=0.0)
            for cache_kind in ("cold", "warm"):
                eps, mpq, calls, nodes, optimal = [], [], [], [], 0
                for s in range(seeds):
                    oracle = CachedOracle(BlockingOracle(sc)) if cache_kind == "cold" else warm
                    t0 = time.process_time()
                    r = train(sc, oracle, p.replace(seed=s))
                    dt = time.process_time() - t0
                    eps.append(r.episodes / dt)
                    mpq.append(r.mp_q)
                    calls.append(r.planner_calls)
                    nodes.append(r.tree_nodes)
                    optimal += r.found and abs(r.total_weight - opt) < 1e-9
                rows.append(dict(policy=policy, search=search, cache=cache_kind, eps=statistics.median(eps),
                                 mpq=statistics.median(mpq), calls=statistics.median(calls),
                                 nodes=statistics.median(nodes), optimal=f"{optimal}/{seeds}"))
    return rows


def exact(sc) -> dict:
    t0 = time.perf_counter()
    r = solve(sc, BlockingOracle(sc))
    dt = time.perf_counter() - t0
    t1 = time.perf_counter()
    b = brute_force(sc, BlockingOracle(sc))
    db = time.perf_counter() - t1
    return dict(sequence=", ".join(r.sequence), weight=r.total_weight, calls=r.oracle_calls,
                settled=r.sets_settled, ms=dt * 1e3, brute_calls=b.oracle_calls, brute_ms=db * 1e3,
                brute_weight=b.total_weight)


def quiet_sweep(scenarios, seeds: int) -> list[tuple]:
    rows = []
    base = TrainingParams.defaults()
    for sc in scenarios:
        oracle = CachedOracle(BlockingOracle(sc))
        opt = solve(sc, oracle).total_weight
        for search in SEARCHES:
            for quiet in (1, 5, 10, 20, 50, 100):
                rs = [train(sc, oracle, base.replace(search=search, quiet_episodes=quiet, seed=s),
                            optimal_weight=opt) for s in range(seeds)]
                ok = sum(r.found and abs(r.total_weight - opt) < 1e-9 for r in rs)
                rows.append((sc.name, search, quiet, f"{ok}/{seeds}", statistics.median(r.e_ss for r in rs),
                             sum(r.converged for r in rs), statistics.median(r.mp_q for r in rs)))
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--episodes", type=int, default=2000)
    ap.add_argument("--no-sweep", action="store_true")
    a = ap.parse_args(argv)
    try:
        from qtree_task_planner.learning import kernel
    except ImportError:  # a tree from before the kernel (for before/after comparisons)
        kernel = None
    engine = "none (reference loop)" if kernel is None else "C kernel" if kernel.available() else \
        f"Python loop ({kernel.build_error})"
    sc = load_scenario(scenarios_dir() / "blocking_15.yaml")
    print(f"# bench_qtree: {sc.name}, {len(sc.obstacle_ids)} obstacles; Python {platform.python_version()}, "
          f"{platform.machine()}; engine: {engine}; defaults {TrainingParams.defaults().to_dict()}")
    print(f"\n## Training throughput: E_max={a.episodes} (beta=0: no early stop), {a.seeds} seeds, medians")
    print("| policy | search | cache | episodes/s | MP_q | planner calls | tree nodes | optimal |")
    print("|---|---|---|---:|---:|---:|---:|---:|")
    for r in throughput(sc, a.seeds, a.episodes):
        print(f"| {r['policy']} | {r['search']} | {r['cache']} | {r['eps']:.0f} | {r['mpq']:.0f} | "
              f"{r['calls']:.0f} | {r['nodes']:.0f} | {r['optimal']} |")
    e = exact(sc)
    print("\n## Exact solver (lazy uniform-cost search over removed sets)")
    print(f"optimum: {e['sequence']}  weight {e['weight']:.2f}; oracle calls {e['calls']}; sets settled "
          f"{e['settled']}; {e['ms']:.1f} ms")
    print(f"brute force (every reachable set): weight {e['brute_weight']:.2f}; oracle calls {e['brute_calls']}; "
          f"{e['brute_ms']:.0f} ms")
    if not a.no_sweep:
        scs = [load_scenario(scenarios_dir() / f"blocking_{n}.yaml") for n in (10, 15)]
        print(f"\n## Eq. 16 quiet_episodes sweep (defaults otherwise), {a.seeds} seeds")
        print("| scenario | search | quiet_episodes | optimal | E_ss median | converged | MP_q median |")
        print("|---|---|---:|---:|---:|---:|---:|")
        for row in quiet_sweep(scs, a.seeds):
            print("| " + " | ".join(str(x) for x in row) + " |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
