"""Benchmark of closed-loop retrieval against the paper's open-loop execution, over DDS (docs/closed_loop.md).

For every scene x seed x K (disturbances drawn by DisturbancePlan.draw(K, seed, relocations=2), applied by the sim
driver's `disturbance_plan`) and both executors (task planner `closed_loop` true / false), a fresh node graph (sim
driver, motion planner, task planner on the ground-truth scene /sim/objects) executes the exact optimum
(`execute_optimum`; training capped at 5 episodes: the executor is measured, not the Q-Tree). Success: the goal
succeeded AND the simulator shows the target on the bottom shelf; a run that reports success without it is counted
as `false success`. Printed: success rate, re-plans, extra relocations against the undisturbed optimum, wall time.

    .venv/bin/python scripts/bench_closed_loop.py [--scenes scenario1_5 paper1_5] [--seeds 0 1 2] [--k 0 1 2]
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # this checkout's packages first

from jaco2_sim_driver.disturbance import DisturbancePlan
from relocation_app.client import RelocationClient
from relocation_app.graph import Graph
from relocation_common.paths import resolve_scenario
from relocation_common.scenario import load_scenario


def run_once(scene: Path, seed: int, k: int, closed: bool, run_dir: Path) -> dict:
    """One execution in a fresh graph: success, target on the bottom shelf, re-plans, relocations, wall s."""
    from qtree_relocation_msgs.msg import ObjectArray
    from rclpy.qos import QoSDurabilityPolicy, QoSProfile
    from std_msgs.msg import String

    latched = QoSProfile(depth=1, durability=QoSDurabilityPolicy.TRANSIENT_LOCAL)
    plan = DisturbancePlan.draw(k, seed, relocations=2) if k else None
    common = {"scenario": str(scene)}
    with Graph(run_dir) as g:
        g.start("jaco2_sim_driver", dict(common, camera_rate=0.0, **(
            {"disturbance_plan": f"'{plan.to_json()}'"} if plan else {})))
        g.start("motion_planner", dict(common, scene_topic="/sim/objects"))
        g.start("task_planner", dict(common, scene_topic="/sim/objects", closed_loop=closed))
        os.environ.update(g.env)
        client = RelocationClient("bench_closed_loop")
        box: dict = {"truth": None, "execution": None, "disturbances": []}

        def on_execution(m: String) -> None:
            box["execution"] = json.loads(m.data)

        def on_disturbance(m: String) -> None:
            box["disturbances"].append(json.loads(m.data))

        try:
            client.node.create_subscription(ObjectArray, "/sim/objects", lambda m: box.update(truth=m), latched)
            client.node.create_subscription(String, "/task_planner/execution", on_execution, latched)
            client.node.create_subscription(String, "/sim/disturbances", on_disturbance,
                                            QoSProfile(depth=100, durability=QoSDurabilityPolicy.TRANSIENT_LOCAL))
            client.wait_until_ready(120, check=g.check_alive)
            t0 = time.monotonic()
            client.train(check=g.check_alive, seed=seed, max_episodes=5, execute=True, execute_optimum=True)
            outcome = client.wait(900, check=g.check_alive)
            wall = time.monotonic() - t0
            time.sleep(1.5)  # the last bottle settles; ground truth at 10 Hz
        finally:
            client.close()
    sc = load_scenario(scene)
    t = next((o.pose.position for o in box["truth"].objects if o.id == sc.target_id), None) if box["truth"] else None
    on_bottom = t is not None and abs(t.z - sc.shelf.bottom_z) < 0.02
    ex = box["execution"] or {}
    res = outcome.result
    return {"success": bool(res is not None and res.success), "on_bottom": on_bottom,
            "replans": len(ex.get("replans", [])), "relocations": len(ex.get("steps", [])) or len(ex.get(
                "relocated", [])), "optimum": len(res.optimal_sequence) if res is not None else 0, "wall": wall,
            "applied": sum("skipped" not in d for d in box["disturbances"]), "message": outcome.message}


def main() -> None:
    """Run the grid and print the table (docs/benchmarks.md)."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scenes", nargs="+", default=["scenario1_5", "paper1_5"])
    p.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2])
    p.add_argument("--k", nargs="+", type=int, default=[0, 1, 2])
    a = p.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for name in a.scenes:
            scene = resolve_scenario(name).resolve()
            for k in a.k:
                for closed in (True, False):
                    runs = []
                    for seed in a.seeds:
                        r = run_once(scene, seed, k, closed, Path(tmp) / f"{name}_{k}_{closed}_{seed}")
                        runs.append(r)
                        print(f"  {name} K={k} {'closed' if closed else 'open'} seed {seed}: "
                              f"{'ok' if r['success'] and r['on_bottom'] else 'FAILED'} ({r['wall']:.0f} s, "
                              f"{r['applied']} disturbances applied, {r['replans']} re-plans) {r['message']}",
                              flush=True)
                    rows.append((name, k, closed, runs))
    print("\n| scene | K | executor | runs | success | false success | disturbances applied | re-plans (mean) "
          "| extra relocations (mean) | wall s (mean) |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for name, k, closed, runs in rows:
        ok = sum(r["success"] and r["on_bottom"] for r in runs)
        false = sum(r["success"] and not r["on_bottom"] for r in runs)
        extra = statistics.fmean(max(0, r["relocations"] - r["optimum"]) for r in runs)
        print(f"| {name} | {k} | {'closed' if closed else 'open'} | {len(runs)} | {ok}/{len(runs)} | {false} | "
              f"{sum(r['applied'] for r in runs)} | {statistics.fmean(r['replans'] for r in runs):.1f} | "
              f"{extra:.1f} | {statistics.fmean(r['wall'] for r in runs):.0f} |")


if __name__ == "__main__":
    main()
