"""A feasibility table filled through motion planner processes over ROS (planner replicas: docs/architecture.md),
instead of this process's pool.

`replica_oracle(scenario_path, replicas)` starts the motion planner and replicas - 1 feasibility-only replicas
(relocation_app.graph.Graph.start_planners) on the scene, on a private domain, and yields the task planner's
oracle over them (RelocationClient.feasibility_oracle): fill_reachable(..., oracle=...) then keeps one question
in flight per replica. Planners on other machines join the same way (docs/reliability.md, "Planner replicas").
The planners read config/motion_planner.yaml, the parameters the evaluation's cache key is computed from; the
request's timeout is the evaluation's safety net.
"""
from __future__ import annotations

import os
import tempfile
from contextlib import contextmanager
from pathlib import Path

from relocation_common.feasibility import replica_services


@contextmanager
def replica_graph(scenario_path: str | Path, replicas: int, run_dir: str | Path | None = None):
    """(Graph, RelocationClient): the planners up and their services seen; everything stopped on exit."""
    from qtree_relocation_msgs.srv import PlanFeasibility

    from relocation_app.client import FEASIBILITY, RelocationClient
    from relocation_app.graph import Graph, wait_for_interfaces

    keys = ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE")
    saved = {k: os.environ.get(k) for k in keys}
    with Graph(Path(run_dir or tempfile.mkdtemp(prefix="replica_fill_"))) as g:
        g.start_planners(replicas, {"scenario": str(scenario_path)})
        os.environ.update({k: g.env[k] for k in keys})
        client = RelocationClient("replica_fill")
        try:
            services = [(name, PlanFeasibility) for name in replica_services(FEASIBILITY, replicas)]
            wait_for_interfaces(client.node, services=services, timeout=180.0, graph=g)
            yield g, client
        finally:
            client.close()
            for k, v in saved.items():
                if v is None:
                    os.environ.pop(k, None)
                else:
                    os.environ[k] = v


@contextmanager
def replica_oracle(scenario_path: str | Path, replicas: int, timeout: float = 60.0, run_dir: str | Path | None = None):
    """The oracle over `replicas` planners started on the scene (replica_graph)."""
    with replica_graph(scenario_path, replicas, run_dir) as (_, client):
        yield client.feasibility_oracle(replicas, timeout=timeout, margin=30.0)
