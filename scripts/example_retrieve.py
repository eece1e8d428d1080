#!/usr/bin/env python3
"""Example: ask the running graph about feasibility, then train and retrieve the target (RelocationClient).

Start the graph first (e.g. `./run demo` starts its own; or the four nodes with `ros2 run qtree_relocation ...` /
`.venv/bin/<node>` on the same ROS_DOMAIN_ID), then: .venv/bin/python scripts/example_retrieve.py [--execute]
"""
import argparse
import time

from relocation_app.client import RelocationClient

ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
ap.add_argument("--object", default="o2", help="object to ask about")
ap.add_argument("--execute", action="store_true", help="relocate the learned sequence on the robot")
a = ap.parse_args()

client = RelocationClient("example_client")
try:
    client.wait_until_ready(timeout=60)
    label, res = client.plan_feasibility(a.object)
    print(f"{a.object}: {label.name} in {res.planning_time:.3f} s ({res.attempts} attempts)")
    client.train(execute=a.execute, on_feedback=lambda f: print(f"  {f.phase} episode {f.episode}", end="\r"))
    while not client.is_done():
        time.sleep(0.2)
    r = client.result()
    print(f"\nlearned {' -> '.join(r.sequence)} (weight {r.total_weight:.2f}); optimum {r.optimal_weight:.2f}; "
          f"{r.message}")
finally:
    client.close()
