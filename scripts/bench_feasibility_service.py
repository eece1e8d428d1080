"""Round trip of the PlanFeasibility service over DDS (loopback) against the planner's own planning time.

Starts the real motion_planner node (default scenario) on a private domain, sends N requests one at a time from
one client (the task planner's pattern: one query in flight; a background spin thread and a blocking call, as
the task planner's ServiceOracle), each query twice in a row, with the trajectory and label-only (the request's
`label_only`), and prints the round-trip time, the planning time the node reports, and the difference (the ROS
overhead: serialisation, DDS, executors).

    .venv/bin/python scripts/bench_feasibility_service.py --requests 200 [--baseline 5bd83aa] [--domain 61]

--baseline REV: the same, first with the motion planner package (stpik_motion_planner/) of git revision REV, then
with the working tree's, alternated `--rounds` times, on one domain (one node at a time).

    .venv/bin/python scripts/bench_feasibility_service.py --replicas 2 --requests 200 [--scenario scenario3_15]

--replicas N: throughput, not latency. The motion planner and N-1 replicas (Graph.start_planners, namespaces
/replica_<k>), asked the questions of a table fill (the scene's committed feasibility table, shuffled) through the
task planner's oracle (ReplicaOracle.feasibility_many: one in flight per replica); phases with 1 and with N replicas
alternated `--rounds` times. Prints queries/s of each, their ratio, and the CPU time per query of the planner
processes and of the client (utime + stime: what predicts the throughput on more cores).
"""
from __future__ import annotations

import argparse
import contextlib
import os
import random
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # this checkout's packages first

from bench_motion_planner import export_package  # scripts/ is sys.path[0]: the sibling benchmark

from relocation_app.graph import Graph, wait_for_interfaces
from relocation_common.paths import default_scenario, resolve_scenario
from relocation_common.scenario import load_scenario

REPO = Path(__file__).resolve().parent.parent


@contextlib.contextmanager
def client_node(g: Graph, name: str):
    """A client node on the graph's domain, spun by a SingleThreadedExecutor in a background thread (blocking
    calls from other threads, as the task planner's ServiceOracle)."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    os.environ.update({k: v for k, v in g.env.items() if k.startswith("ROS_")})
    rclpy.init()
    node = rclpy.create_node(name)
    ex = SingleThreadedExecutor()
    ex.add_node(node)
    spin = threading.Thread(target=ex.spin, daemon=True)
    spin.start()
    try:
        yield node
    finally:
        ex.shutdown(timeout_sec=2.0)
        spin.join(timeout=3.0)
        node.destroy_node()
        rclpy.try_shutdown()


def measure(n: int, seed: int, domain: int, impl: str = "") -> dict[str, list]:
    """Per mode ("trajectory", "label only"): (round trip ms, planning ms, label) of n queries, each asked in both
    modes back to back (which first alternates)."""
    from qtree_relocation_msgs.srv import PlanFeasibility

    scenario = load_scenario(default_scenario())
    rng = random.Random(seed)
    out: dict[str, list] = {"trajectory": [], "label only": []}
    with Graph(Path(tempfile.mkdtemp(prefix="bench_srv_")), domain_id=domain) as g:
        if impl:
            g.env["PYTHONPATH"] = os.pathsep.join([impl, g.env["PYTHONPATH"]])
        g.start("motion_planner")
        with client_node(g, "bench_feasibility_service") as node:
            wait_for_interfaces(node, services=[("/motion_planner/plan_feasibility", PlanFeasibility)], graph=g)
            cli = node.create_client(PlanFeasibility, "/motion_planner/plan_feasibility")
            for k in range(n + 5):
                obj = rng.choice(scenario.ids)
                others = [o for o in scenario.obstacle_ids if o != obj]
                removed = rng.sample(others, rng.randint(0, 4))
                modes = [False, True] if k % 2 else [True, False]
                for label_only in modes:
                    t0 = time.perf_counter()
                    res = cli.call(PlanFeasibility.Request(object_id=obj, removed_ids=removed, timeout=0.0,
                                                           label_only=label_only), timeout_sec=30.0)
                    dt = time.perf_counter() - t0
                    if k >= 5 and res is not None and res.ok:  # the first 5: warm-up
                        out["label only" if label_only else "trajectory"].append(
                            (dt * 1e3, res.planning_time * 1e3, res.label))
    return out


def q(x) -> str:
    x = np.asarray(x)
    return f"p50 {np.percentile(x, 50):7.2f} ms  p95 {np.percentile(x, 95):7.2f} ms  max {x.max():7.2f} ms"


def report(name: str, runs: list[dict[str, list]]) -> dict[str, float]:
    """Prints round trip, planning and overhead per mode; returns the p50s."""
    p50 = {}
    for mode in ("trajectory", "label only"):
        rows = np.array([r for run in runs for r in run[mode]])
        if not len(rows):
            continue
        rtt, plan, lab = rows[:, 0], rows[:, 1], rows[:, 2]
        feas = lab != 0
        print(f"  {name} / {mode} ({len(rows)} requests)")
        print(f"    round trip          {q(rtt)}")
        print(f"    planning (node)     {q(plan)}")
        print(f"    overhead            {q(rtt - plan)}")
        if feas.any():
            print(f"    round trip feasible   ({feas.sum():3d}) {q(rtt[feas])}   overhead {q((rtt - plan)[feas])}")
            p50[f"{mode} feasible rtt"] = float(np.percentile(rtt[feas], 50))
            p50[f"{mode} feasible overhead"] = float(np.percentile((rtt - plan)[feas], 50))
        p50[f"{mode} overhead"] = float(np.percentile(rtt - plan, 50))
    return p50


def _cpu_seconds(pids) -> float:
    """utime + stime of the processes (/proc/<pid>/stat), in s."""
    tick = os.sysconf("SC_CLK_TCK")
    total = 0
    for pid in pids:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        total += int(fields[11]) + int(fields[12])
    return total / tick


def _fill_questions(scenario, n: int, seed: int) -> list:
    """n questions a table fill asks (object, reachable set) from the scene's committed table, shuffled."""
    from relocation_app.evaluation.__main__ import planner_params
    from relocation_app.evaluation.feasibility_cache import open_table

    table, _ = open_table(scenario, planner_params())
    qs = list(table.entries)
    random.Random(seed).shuffle(qs)
    return qs[:n]


def replicas(n: int, seed: int, count: int, rounds: int, scenario_name: str) -> None:
    """Throughput with 1 and with `count` motion planner processes through the task planner's oracle
    (ReplicaOracle.feasibility_many; see the module docstring)."""
    from relocation_app.evaluation.replica_fill import replica_graph

    path = resolve_scenario(scenario_name)
    scenario = load_scenario(path)
    queries = _fill_questions(scenario, n, seed)
    rows = []
    with replica_graph(path, count) as (g, client):
        pids = [p.pid for p in g.procs.values()]
        one, many = (client.feasibility_oracle(k, timeout=60.0, margin=30.0) for k in (1, count))
        many.feasibility_many(queries[:10])  # warm-up, every replica
        for _ in range(rounds):
            for used, oracle in ((1, one), (count, many)):
                cpu, client_cpu, t0 = _cpu_seconds(pids), time.process_time(), time.perf_counter()
                answers = oracle.feasibility_many(queries)
                rows.append((used, time.perf_counter() - t0, len(answers), _cpu_seconds(pids) - cpu,
                             time.process_time() - client_cpu))
    print(f"PlanFeasibility throughput, {scenario.name}, {n} label-only table-fill questions per phase, "
          f"ReplicaOracle.feasibility_many, {os.cpu_count()} cores")
    rate = {}
    for used in (1, count):
        sub = [r for r in rows if r[0] == used]
        qps = [r[2] / r[1] for r in sub]
        asked = sum(r[2] for r in sub)
        rate[used] = float(np.median(qps))
        print(f"  {used} replica(s): {', '.join(f'{x:.1f}' for x in qps)} queries/s (median {rate[used]:.1f}); "
              f"CPU per query: planners {sum(r[3] for r in sub) / asked * 1e3:.2f} ms, client "
              f"{sum(r[4] for r in sub) / asked * 1e3:.2f} ms")
    print(f"  {count} replicas / 1: {rate[count] / rate[1]:.2f}x")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--requests", type=int, default=200)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--domain", type=int, default=61, help="ROS_DOMAIN_ID of the benchmark's graph")
    ap.add_argument("--baseline", help="git revision whose motion planner package to compare against")
    ap.add_argument("--rounds", type=int, default=1)
    ap.add_argument("--replicas", type=int, default=0, help="throughput with 1 and with N planner processes")
    ap.add_argument("--scenario", default="paper_experiment_10", help="--replicas: the planners' scenario")
    a = ap.parse_args()
    if a.replicas:
        return replicas(a.requests, a.seed, a.replicas, max(a.rounds, 2), a.scenario)
    impls = [("working tree", "")]
    if a.baseline:
        impls.insert(0, (a.baseline, export_package(a.baseline)))
    runs: dict[str, list] = {name: [] for name, _ in impls}
    for _ in range(a.rounds):
        for name, impl in impls:
            runs[name].append(measure(a.requests, a.seed, a.domain, impl))
    print(f"PlanFeasibility over DDS (loopback), {a.requests} queries x {a.rounds} rounds, each asked with the "
          f"trajectory and label-only, one in flight, default scenario")
    got = {name: report(name, rs) for name, rs in runs.items()}
    if a.baseline:
        b, w = got[a.baseline], got["working tree"]
        for k in ("trajectory feasible rtt", "trajectory overhead"):
            if k in b and k in w:
                print(f"  {k} p50: {a.baseline} {b[k]:.2f} ms, working tree {w[k]:.2f} ms ({b[k] / w[k]:.2f}x)")
    w = got["working tree"]
    if "label only feasible rtt" in w and "trajectory feasible rtt" in w:
        print(f"  working tree, feasible round trip p50: trajectory {w['trajectory feasible rtt']:.2f} ms, "
              f"label only {w['label only feasible rtt']:.2f} ms")


if __name__ == "__main__":
    main()
