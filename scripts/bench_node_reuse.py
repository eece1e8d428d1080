#!/usr/bin/env python3
"""Benchmark: the real planner calls of the task planner's training through the node graph against in-process, and
how many feasible answers carried their near set (reuse across answers: docs/motion_planner.md). Not a timed test.

Through the nodes: the motion planner and replicas - 1 feasibility-only replicas (relocation_app.graph), the task
planner with its checkpoint in the run directory, the scene published from the scenario file (ground truth, no
simulator), a TrainPlanner goal without execution (the node's parameters: config/task_planner.yaml); the planner's
answers and their near sets are read from the checkpoint. In-process: the same call (retrieval.solve_then_train)
on MotionPlanner behind CachedOracle(reuse=True), as the node wraps its oracle.

    .venv/bin/python scripts/bench_node_reuse.py --scenario scenario3_15 [--replicas 2] [--in-process]
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from relocation_common.paths import resolve_scenario  # noqa: E402  (after the sys.path insert)
from relocation_common.scenario import load_scenario  # noqa: E402  (after the sys.path insert)


def through_nodes(scenario: Path, replicas: int, run_dir: Path) -> dict:
    """The training through the node graph: its TrainPlanner result and the answers of its checkpoint."""
    import rclpy
    from qtree_relocation_msgs.msg import ObjectArray
    from rclpy.context import Context
    from rclpy.qos import DurabilityPolicy, QoSProfile

    from qtree_task_planner.learning.checkpoint import load_checkpoint
    from relocation_app.client import RelocationClient
    from relocation_app.graph import Graph
    from relocation_common.ros_conversions import objects_to_msg

    ckpt, topic = run_dir / "qtree.ckpt", "/ground_truth/objects"
    with Graph(run_dir) as g:
        g.start_planners(replicas, {"scenario": str(scenario), "scene_topic": topic})
        g.start("task_planner", {"scenario": str(scenario), "scene_topic": topic, "checkpoint_path": str(ckpt),
                                 "replicas": replicas})
        ctx = Context()
        rclpy.init(context=ctx, domain_id=g.domain_id)
        try:
            with RelocationClient(context=ctx) as c:
                latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
                c.node.create_publisher(ObjectArray, topic, latched).publish(
                    objects_to_msg(load_scenario(scenario).objects))
                c.wait_until_ready(120, g.check_alive)
                t0 = time.monotonic()
                c.train(execute=False)
                res = c.wait(3600, g.check_alive).result
        finally:
            ctx.try_shutdown()
    rows = load_checkpoint(ckpt).feasibility  # [object, removed, label(, blockers(, near))]: the planner's answers
    feasible = [r for r in rows if r[2] != 0]
    return dict(s=round(time.monotonic() - t0, 1), planner_calls=res.planner_calls, picks=len(rows),
                feasible=len(feasible), feasible_with_near=sum(len(r) > 4 for r in feasible),
                episodes=res.episodes, e_ss=res.e_ss, sequence=list(res.sequence))


def in_process(scenario: Path) -> dict:
    """The node's training call on MotionPlanner behind CachedOracle(reuse=True)."""
    from qtree_task_planner.executive.retrieval import solve_then_train
    from qtree_task_planner.learning.params import TrainingParams
    from qtree_task_planner.oracles import CachedOracle
    from qtree_task_planner.problem import RelocationProblem
    from stpik_motion_planner.planning.planner import MotionPlanner

    sc = load_scenario(scenario)
    oracle = CachedOracle(MotionPlanner(sc), reuse=True)
    t0 = time.monotonic()
    _, r = solve_then_train(RelocationProblem.from_scenario(sc), oracle, TrainingParams.from_yaml(), resume=None,
                            until_planner=lambda f: f(), keep=lambda c: None, on_episode=lambda s: True,
                            checkpoint_every=50, on_solved=lambda o: None)
    feasible = [a for k, a in oracle.table.items() if k not in oracle.reused and int(a.label) != 0]
    return dict(s=round(time.monotonic() - t0, 1), planner_calls=oracle.planner_answers, picks=oracle.calls,
                feasible=len(feasible), feasible_with_near=sum(a.near is not None for a in feasible),
                episodes=r.episodes, e_ss=r.e_ss, sequence=list(r.sequence or ()))


def main() -> None:
    """Print one JSON line: the scene, the mode and its counts."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scenario", default="paper_experiment_10", help="a name under config/scenarios, or a YAML")
    ap.add_argument("--replicas", type=int, default=2)
    ap.add_argument("--in-process", action="store_true", help="the planner in this process, no nodes")
    ap.add_argument("--run-dir", help="the graph's logs and checkpoint (default: a new temporary directory)")
    a = ap.parse_args()
    scenario = resolve_scenario(a.scenario).resolve()
    if a.in_process:
        out = dict(mode="in-process", **in_process(scenario))
    else:
        run_dir = Path(a.run_dir or tempfile.mkdtemp(prefix="node_reuse_"))
        out = dict(mode=f"nodes ({a.replicas} planners)", **through_nodes(scenario, a.replicas, run_dir))
    print(json.dumps(dict(scene=a.scenario, **out)))


if __name__ == "__main__":
    main()
