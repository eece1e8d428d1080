#!/usr/bin/env python3
"""Example: ask the running graph about feasibility, then train and retrieve the target (RelocationClient).

Start the graph first (e.g. `./run demo` starts its own; or the four nodes with `ros2 run qtree_relocation ...` /
`.venv/bin/<node>` on the same ROS_DOMAIN_ID), then: .venv/bin/python scripts/example_retrieve.py [--execute]
"""
import argparse
import time

from relocation_app.client import RelocationClient, TaskResult

ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
ap.add_argument("--object", default="o2", help="object to ask about")
ap.add_argument("--execute", action="store_true", help="relocate the learned sequence on the robot")
a = ap.parse_args()

with RelocationClient("example_client") as client:  # Ctrl-C: the goal in flight is canceled, the node closed
    client.wait_until_ready(timeout=60)
    label, res = client.plan_feasibility(a.object)
    print(f"{a.object}: {label.name} in {res.planning_time:.3f} s ({res.attempts} attempts)")
    client.train(execute=a.execute)
    while not client.is_done():
        f = client.feedback()
        if f is not None:
            print(f"  {f.phase} episode {f.episode}", end="\r")
        time.sleep(0.2)
    result = client.result()
    if result.status is TaskResult.SUCCEEDED:
        r = result.result
        print(f"\nlearned {' -> '.join(r.sequence)} (weight {r.total_weight:.2f}); optimum {r.optimal_weight:.2f}")
    else:
        print(f"\ntraining {result.status.value}: {result.message}")
