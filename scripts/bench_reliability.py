#!/usr/bin/env python3
"""Load test of the motion planner's feasibility service (docs/reliability.md, section 6): N requests from C concurrent
clients.

Starts the real motion_planner node (config/motion_planner.yaml) on a private ROS domain with loopback discovery,
then C client processes, each its own ROS node, sending its share of the requests back to back: valid questions
(a random object and a random removed set of the default scenario) mixed with bad ones (unknown id, empty id,
the object in its own removed set, an unknown removed id, a NaN timeout). Every request must be answered: ok with a
label, or refused (ok = false) with a reason. Reports answers, refusals, latency, throughput, and the planner's
resident memory (VmRSS) before and after plus its peak (VmHWM); then stops the node with SIGINT (exit status 0).

    .venv/bin/python scripts/bench_reliability.py                 # 1,000 requests, 4 clients
    .venv/bin/python scripts/bench_reliability.py -n 40 --json    # the size of the test
"""
from __future__ import annotations

import argparse
import json
import math
import os
import random
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
SRV = "/motion_planner/plan_feasibility"
BAD_EVERY = 10  # one request in ten is a bad one


def requests_for(client: int, n: int, ids: list[str], target: str, seed: int) -> list[tuple[str, list[str], float]]:
    """(object_id, removed_ids, timeout) for one client: valid questions with one bad request in BAD_EVERY."""
    rng = random.Random(seed * 1000 + client)
    obstacles = [i for i in ids if i != target]
    bad = [("ghost", [], 0.0), ("", [], 0.0), (obstacles[0], [obstacles[0]], 0.0), (target, ["nobody"], 0.0),
           (obstacles[1], [], math.nan)]
    out = []
    for k in range(n):
        if k % BAD_EVERY == BAD_EVERY - 1:
            out.append(bad[(k // BAD_EVERY + client) % len(bad)])
            continue
        removed = [o for o in obstacles if rng.random() < 0.3]
        obj = rng.choice([o for o in ids if o not in removed])
        out.append((obj, removed, 0.0))
    return out


def is_bad(req) -> bool:
    obj, removed, timeout = req
    return obj in ("ghost", "") or obj in removed or "nobody" in removed or not math.isfinite(timeout)


def run_client(client: int, n: int, seed: int, answer_timeout: float) -> None:
    """Runs in a client process: prints one JSON line with every request's outcome."""
    import rclpy
    from qtree_relocation_msgs.srv import PlanFeasibility

    from relocation_common.paths import default_scenario
    from relocation_common.scenario import load_scenario

    sc = load_scenario(default_scenario())
    reqs = requests_for(client, n, list(sc.ids), sc.target_id, seed)
    rclpy.init()
    node = rclpy.create_node(f"load_client_{client}")
    cli = node.create_client(PlanFeasibility, SRV)
    if not cli.wait_for_service(timeout_sec=60):
        print(json.dumps({"client": client, "error": "service never appeared"}), flush=True)
        return
    outcomes = []
    for obj, removed, timeout in reqs:
        t0 = time.perf_counter()
        fut = cli.call_async(PlanFeasibility.Request(object_id=obj, removed_ids=removed, timeout=timeout))
        rclpy.spin_until_future_complete(node, fut, timeout_sec=answer_timeout)
        dt = time.perf_counter() - t0
        if not fut.done():
            cli.remove_pending_request(fut)
            outcomes.append({"bad": is_bad((obj, removed, timeout)), "answered": False, "latency": dt})
            continue
        r = fut.result()
        outcomes.append({"bad": is_bad((obj, removed, timeout)), "answered": True, "ok": bool(r.ok),
                         "label": int(r.label), "message": r.message, "latency": dt})
    print(json.dumps({"client": client, "outcomes": outcomes}), flush=True)
    node.destroy_node()
    rclpy.try_shutdown()


def rss_kb(pid: int) -> dict[str, int]:
    out = {}
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith(("VmRSS:", "VmHWM:")):
            out[line.split(":")[0]] = int(line.split()[1])
    return out


def bench(n: int, clients: int, seed: int, answer_timeout: float, run_dir: Path) -> dict:
    from relocation_app.graph import Graph

    with Graph(run_dir) as g:
        planner = g.start("motion_planner")
        deadline = time.monotonic() + 120
        while "ready: " not in g.log("motion_planner"):
            g.check_alive()
            if time.monotonic() > deadline:
                raise RuntimeError("motion_planner not ready:\n" + g.log("motion_planner")[-2000:])
            time.sleep(0.1)
        # warm up (first queries build caches) before the memory baseline
        warm = subprocess.run([sys.executable, __file__, "--client", "99", "-n", "3", "--seed", str(seed)],
                              env=g.env, capture_output=True, text=True, timeout=300)
        if warm.returncode != 0:
            raise RuntimeError(f"warm-up client failed: {warm.stderr[-2000:]}")
        before = rss_kb(planner.pid)
        share = [n // clients + (1 if k < n % clients else 0) for k in range(clients)]
        t0 = time.perf_counter()
        procs = [subprocess.Popen([sys.executable, __file__, "--client", str(k), "-n", str(share[k]), "--seed",
                                   str(seed), "--answer-timeout", str(answer_timeout)], env=g.env,
                                  stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for k in range(clients)]
        peak_during = 0
        while any(p.poll() is None for p in procs):
            peak_during = max(peak_during, rss_kb(planner.pid)["VmRSS"])
            time.sleep(0.2)
        wall = time.perf_counter() - t0
        results = []
        for p in procs:
            out, err = p.communicate()
            line = next((ln for ln in out.splitlines() if ln.startswith("{")), None)
            if p.returncode != 0 or line is None:
                raise RuntimeError(f"client failed ({p.returncode}): {err[-2000:]}")
            results.append(json.loads(line))
        after = rss_kb(planner.pid)
        alive = planner.poll() is None
        code = g.stop("motion_planner", signal.SIGINT)
    outcomes = [o for r in results for o in r.get("outcomes", [])]
    lat = sorted(o["latency"] for o in outcomes)
    answered = [o for o in outcomes if o["answered"]]

    def pct(p):
        return lat[min(len(lat) - 1, int(p * len(lat)))] if lat else float("nan")

    return {
        "requests": len(outcomes), "clients": clients, "client_errors": [r["error"] for r in results if "error" in r],
        "answered": len(answered), "unanswered": len(outcomes) - len(answered),
        "ok": sum(o["ok"] for o in answered), "refused": sum(not o["ok"] for o in answered),
        "refused_without_reason": sum(not o["ok"] and not o["message"].strip() for o in answered),
        "bad_sent": sum(o["bad"] for o in outcomes), "bad_refused": sum(o["bad"] and not o["ok"] for o in answered),
        "good_refused": sum(not o["bad"] and not o["ok"] for o in answered),
        "labels": {lab: sum(o["ok"] and o["label"] == v for o in answered)
                   for lab, v in (("UNFEASIBLE", 0), ("OBSTACLE", 1), ("TARGET", 2))},
        "refusal_reasons": sorted({o["message"].split(":")[0][:60] for o in answered if not o["ok"]}),
        "wall_s": wall, "throughput_per_s": len(outcomes) / wall if wall > 0 else float("nan"),
        "latency_ms": {"p50": 1e3 * pct(0.5), "p95": 1e3 * pct(0.95), "max": 1e3 * (lat[-1] if lat else math.nan)},
        "rss_kb": {"before": before["VmRSS"], "after": after["VmRSS"], "peak_sampled": max(peak_during, after["VmRSS"]),
                   "VmHWM_after": after["VmHWM"]},
        "planner_alive_after": alive, "planner_exit_code": code,
    }


def bench_checkpoint(scenarios=("blocking_10", "blocking_15", "scenario3_15"), repeats: int = 5) -> list[dict]:
    """Checkpoint size and save/load time of the final Q-Tree of a default training (BlockingOracle, seed 0)."""
    from qtree_task_planner.learning.checkpoint import load_checkpoint, save_checkpoint
    from qtree_task_planner.learning.params import TrainingParams
    from qtree_task_planner.learning.training import train
    from qtree_task_planner.oracles import BlockingOracle
    from relocation_common.paths import scenarios_dir
    from relocation_common.scenario import load_scenario

    rows = []
    for name in scenarios:
        sc = load_scenario(scenarios_dir() / f"{name}.yaml")
        if sc.blocking is None:
            continue
        got = []
        r = train(sc, BlockingOracle(sc), TrainingParams.defaults(), on_checkpoint=got.append)
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / "ck.json"
            t0 = time.perf_counter()
            for _ in range(repeats):
                save_checkpoint(got[-1], path)
            t_save = (time.perf_counter() - t0) / repeats
            t0 = time.perf_counter()
            for _ in range(repeats):
                load_checkpoint(path)
            t_load = (time.perf_counter() - t0) / repeats
            size = path.stat().st_size
        rows.append({"scenario": name, "episodes": r.episodes, "tree_nodes": r.tree_nodes, "edges": r.tree_edges,
                     "answers": len(got[-1].feasibility), "bytes": size, "save_ms": 1e3 * t_save,
                     "load_ms": 1e3 * t_load})
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("-n", "--requests", type=int, default=1000)
    ap.add_argument("-c", "--clients", type=int, default=4)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--answer-timeout", type=float, default=60.0, help="s a client waits for one answer")
    ap.add_argument("--json", action="store_true", help="print the summary as JSON")
    ap.add_argument("--checkpoint-only", action="store_true", help="only the checkpoint size/time table")
    ap.add_argument("--client", type=int, help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.client is not None:
        run_client(a.client, a.requests, a.seed, a.answer_timeout)
        return
    if not a.json:
        print("Q-Tree checkpoint (final tree of a default training, BlockingOracle; atomic write incl. fsync):")
        for row in bench_checkpoint():
            print(f"  {row['scenario']:13s} {row['episodes']:5d} episodes, {row['tree_nodes']:5d} nodes, "
                  f"{row['edges']:5d} edges, {row['answers']:4d} answers: {row['bytes'] / 1024:7.1f} KiB, "
                  f"save {row['save_ms']:6.1f} ms, load {row['load_ms']:6.1f} ms")
        if a.checkpoint_only:
            return
    with tempfile.TemporaryDirectory(prefix="bench_reliability_") as tmp:
        s = bench(a.requests, a.clients, a.seed, a.answer_timeout, Path(tmp))
    if a.json:
        print(json.dumps(s))
        return
    r, lat = s["rss_kb"], s["latency_ms"]
    print(f"feasibility load test: {s['requests']} requests from {s['clients']} concurrent clients "
          f"({os.cpu_count()} cores)")
    print(f"  answered {s['answered']} / {s['requests']} (unanswered {s['unanswered']}): ok {s['ok']} "
          f"{s['labels']}, refused {s['refused']} (without a reason: {s['refused_without_reason']})")
    print(f"  bad requests sent {s['bad_sent']}, refused {s['bad_refused']}; valid requests refused "
          f"{s['good_refused']}")
    print(f"  refusal reasons: {s['refusal_reasons']}")
    print(f"  wall {s['wall_s']:.1f} s, {s['throughput_per_s']:.1f} requests/s; latency p50 {lat['p50']:.0f} ms, "
          f"p95 {lat['p95']:.0f} ms, max {lat['max']:.0f} ms (queueing behind the other clients included)")
    print(f"  planner RSS before {r['before'] / 1024:.1f} MiB, after {r['after'] / 1024:.1f} MiB, peak sampled "
          f"{r['peak_sampled'] / 1024:.1f} MiB, VmHWM {r['VmHWM_after'] / 1024:.1f} MiB")
    print(f"  planner alive after: {s['planner_alive_after']}, exit status on SIGINT: {s['planner_exit_code']}")


if __name__ == "__main__":
    main()
