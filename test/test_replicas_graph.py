"""Planner replicas in the real graph (docs/architecture.md, "planner replicas"), each test with real motion planner
processes (Graph.start_planners): a task planner with `replicas: 2` whose first planner is SIGKILLed during training
(the replica answers the rest, the goal ends with a learned sequence instead of aborting after planner_wait); a table
fill, `qtree --oracle replicas`, and the example script, each through two planners."""
import re
import signal
import time
from pathlib import Path

import pytest

from relocation_app.graph import Graph
from relocation_common.paths import scenarios_dir
from relocation_common.scenario import load_scenario

pytestmark = pytest.mark.graph

SCENARIO = scenarios_dir() / "scenario1_5.yaml"  # its 84 questions keep the test short
TOPIC = "/test/objects"


@pytest.mark.slow
def test_training_goes_on_when_the_first_planner_is_killed(tmp_path, monkeypatch):
    from qtree_relocation_msgs.msg import ObjectArray
    from rclpy.qos import DurabilityPolicy, QoSProfile

    from relocation_app.client import RelocationClient
    from relocation_common.ros_conversions import objects_to_msg

    scenario = load_scenario(SCENARIO)
    # feasibility_timeout: a certified answer (pick, carry, way home) can take over 2 s of wall on this shared
    # machine; at 2 s one question ran into the safety net again and again (no answer)
    with Graph(tmp_path) as g:
        g.start_planners(2, {"scenario": str(SCENARIO), "scene_topic": TOPIC})
        g.start("task_planner", {"scene_topic": TOPIC, "replicas": 2, "feasibility_timeout": 15.0,
                                 "feasibility_margin": 1.0, "planner_wait": 5.0,
                                 "reuse_answers": False})  # each question asked: training outlasts the kill
        for k in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE"):
            monkeypatch.setenv(k, g.env[k])
        client = RelocationClient("replica_test")
        try:
            pub = client.node.create_publisher(ObjectArray, TOPIC, QoSProfile(
                depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL))
            pub.publish(objects_to_msg(scenario.objects))
            client.wait_until_ready(120, check=g.check_alive)
            deadline = time.monotonic() + 120
            while "feasibility only" not in g.log("motion_planner_replica_1"):
                g.check_alive()
                assert time.monotonic() < deadline, g.log("motion_planner_replica_1")[-2000:]
                time.sleep(0.1)
            episodes = []
            client.train(on_feedback=lambda f: episodes.append(f.episode), check=g.check_alive, execute=False,
                         max_episodes=100, seed=0)
            while not episodes or max(episodes) < 3:
                assert not client.is_done(), client.result()
                time.sleep(0.02)
            killed_at = max(episodes)  # when the signal goes: training may end while the process is reaped
            g.stop("motion_planner", signal.SIGKILL)  # mid-training: its questions must go to the replica
            result = client.wait(300, check=g.check_alive).result
        finally:
            client.close()
        log = g.log("task_planner")
    assert result.success, result.message
    assert result.sequence[-1] == scenario.target_id and result.episodes > killed_at
    assert result.optimal_weight == pytest.approx(0.62, abs=1e-6)  # o4 T (`qtree solve --scenario scenario1_5`)
    learned = [line for line in log.splitlines() if "learned" in line][-1]
    answers = dict(re.findall(r"(/\S*plan_feasibility): (\d+) answers", learned))
    assert int(answers["/replica_1/motion_planner/plan_feasibility"]) > 0, learned
    assert "(down)" in learned.split("/replica_1")[0], learned  # the first planner, marked down
    assert "waiting for" not in log  # no outage: the replica took over at once


def test_a_table_filled_through_two_replicas_equals_the_committed_one(tmp_path):
    """`python -m relocation_app.evaluation fill --replicas 2`: scenario1_5's 96 answers asked of two planner
    processes over ROS, one in flight each, equal the committed table (filled in-process)."""
    from relocation_app.evaluation.__main__ import planner_params
    from relocation_app.evaluation.feasibility_cache import fill_reachable, open_table
    from relocation_app.evaluation.replica_fill import replica_oracle

    path = scenarios_dir() / "scenario1_5.yaml"
    scenario, params = load_scenario(path), planner_params()
    committed, _ = open_table(scenario, params)
    table, _ = open_table(scenario, params, tmp_path / "feasibility")
    with replica_oracle(path, 2, params.timeout, tmp_path / "run") as oracle:
        st = fill_reachable(scenario, params, table, progress=False, oracle=oracle)
    assert st["real_calls"] == len(table.entries) == len(committed.entries) == 96
    assert all(oracle.answers) and sum(oracle.answers) == 96, oracle.summary()
    assert {k: v[0] for k, v in table.entries.items()} == {k: v[0] for k, v in committed.entries.items()}


def test_qtree_solve_through_two_replicas_finds_the_planners_optimum(tmp_path, capsys):
    """`qtree solve --oracle replicas --replicas 2 --solver ucs`: uniform-cost search with two questions in flight
    finds the same sequence as with the motion planner in this process; a bad count is one line, exit 2."""
    import json

    from relocation_app.cli import main

    outs = {}
    for oracle in ("planner", "replicas"):
        assert main(["solve", "--scenario", "scenario1_5", "--solver", "ucs", "--oracle", oracle,
                     "--json", str(tmp_path / f"{oracle}.json")]) == 0
        outs[oracle] = json.loads((tmp_path / f"{oracle}.json").read_text())
    assert outs["replicas"]["sequence"] == outs["planner"]["sequence"]
    assert outs["replicas"]["planner_calls"] >= outs["planner"]["planner_calls"]
    capsys.readouterr()
    assert main(["solve", "--scenario", "scenario1_5", "--oracle", "replicas", "--replicas", "0"]) == 2
    assert capsys.readouterr().err.strip() == "qtree: error: --replicas must be in 1..16, got 0"


def test_the_example_script_finds_the_optimum_over_two_running_planners(tmp_path):
    """scripts/example_exact_over_replicas.py against two planner processes started as its docstring says."""
    import subprocess
    import sys

    from relocation_common.paths import default_scenario

    with Graph(tmp_path) as g:
        g.start_planners(2)
        script = Path(__file__).resolve().parent.parent / "scripts" / "example_exact_over_replicas.py"
        out = subprocess.run([sys.executable, str(script), "--scenario", str(default_scenario()), "--replicas", "2"],
                             env=g.env, capture_output=True, text=True, timeout=180)
    assert out.returncode == 0, out.stderr[-2000:]
    assert "optimum o2 -> o6 -> T (weight 0.91" in out.stdout, out.stdout  # a second-tier lane of T
    assert re.search(r"/replica_1/motion_planner/plan_feasibility: [1-9]\d* answers", out.stdout), out.stdout
