#!/usr/bin/env python3
"""Example: your own search over the running motion planners - the exact optimum (Eq. 8) with the blocker A*,
asking the motion planner and its replicas (one question in flight each) through RelocationClient.

Start the planners first on your ROS_DOMAIN_ID: `motion_planner` and, for replicas, `motion_planner --ros-args
-p serve_relocation:=false -r __ns:=/replica_1` (docs/reliability.md, "Planner replicas"); or
`./run demo --replicas 2`. Then: .venv/bin/python scripts/example_exact_over_replicas.py --replicas 2
"""
import argparse

from qtree_task_planner.oracles import CachedOracle
from qtree_task_planner.problem import RelocationProblem
from qtree_task_planner.search import astar
from relocation_app.client import RelocationClient
from relocation_common.paths import default_scenario
from relocation_common.scenario import load_scenario

ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
ap.add_argument("--scenario", default=str(default_scenario()), help="the scene the planners were started on")
ap.add_argument("--replicas", type=int, default=1, help="the motion planner and replicas - 1 under /replica_<k>")
a = ap.parse_args()

problem = RelocationProblem.from_scenario(load_scenario(a.scenario))
client = RelocationClient("example_exact")
try:
    oracle = CachedOracle(client.feasibility_oracle(replicas=a.replicas))
    result = astar.solve(problem, oracle)
    print(f"optimum {' -> '.join(result.sequence or ['none'])} (weight {result.total_weight}) in {oracle.calls} "
          f"planner calls; {oracle.oracle.summary()}")
finally:
    client.close()
