"""Round trip of the PlanFeasibility service over DDS (loopback) against the planner's own planning time.

Starts the real motion_planner node (default scenario) on a private domain, sends N requests one at a time from
one client (the task planner's pattern: one query in flight), and prints the round-trip time, the planning time
the node reports, and the difference (the ROS overhead: serialisation, DDS, executor).

    .venv/bin/python scripts/bench_feasibility_service.py --requests 200
"""
from __future__ import annotations

import argparse
import os
import random
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from relocation_app.graph import Graph, wait_for_interfaces  # noqa: E402
from relocation_common.paths import default_scenario
from relocation_common.scenario import load_scenario  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--requests", type=int, default=200)
    ap.add_argument("--seed", type=int, default=1)
    a = ap.parse_args()
    import rclpy
    from qtree_relocation_msgs.srv import PlanFeasibility

    scenario = load_scenario(default_scenario())
    rng = random.Random(a.seed)
    with Graph(Path(tempfile.mkdtemp(prefix="bench_srv_"))) as g:
        g.start("motion_planner")
        os.environ.update(g.env)
        rclpy.init()
        node = rclpy.create_node("bench_feasibility_service")
        try:
            wait_for_interfaces(node, services=[("/motion_planner/plan_feasibility", PlanFeasibility)], graph=g)
            cli = node.create_client(PlanFeasibility, "/motion_planner/plan_feasibility")
            rtt, plan, labels = [], [], []
            for k in range(a.requests + 5):
                obj = rng.choice(scenario.ids)
                others = [o for o in scenario.obstacle_ids if o != obj]
                removed = rng.sample(others, rng.randint(0, 4))
                t0 = time.perf_counter()
                fut = cli.call_async(PlanFeasibility.Request(object_id=obj, removed_ids=removed, timeout=0.0))
                rclpy.spin_until_future_complete(node, fut, timeout_sec=30)
                dt = time.perf_counter() - t0
                res = fut.result()
                if k < 5 or res is None:  # warm-up
                    continue
                rtt.append(dt * 1e3)
                plan.append(res.planning_time * 1e3)
                labels.append(res.label)
        finally:
            node.destroy_node()
            rclpy.try_shutdown()
    rtt, plan = np.array(rtt), np.array(plan)
    over = rtt - plan

    def q(x):
        return f"p50 {np.percentile(x, 50):7.2f} ms  p95 {np.percentile(x, 95):7.2f} ms  max {x.max():7.2f} ms"

    feas = np.array(labels) != 0
    print(f"PlanFeasibility over DDS (loopback), {len(rtt)} sequential requests, default scenario")
    print(f"round trip          {q(rtt)}")
    print(f"planning (node)     {q(plan)}")
    print(f"overhead            {q(over)}")
    if feas.any():
        print(f"round trip feasible   ({feas.sum():3d}) {q(rtt[feas])}  (the answer carries the 100 Hz trajectory)")
    if (~feas).any():
        print(f"round trip unfeasible ({(~feas).sum():3d}) {q(rtt[~feas])}")


if __name__ == "__main__":
    main()
