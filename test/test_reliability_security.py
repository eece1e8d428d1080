"""Security basics (docs/reliability.md, section 8): the graph starts with discovery on the loopback only and on a
private domain id, and a graph on one domain is invisible from another. (That LOCALHOST keeps other machines out cannot
be shown on one host: docs/reliability.md says how to open it up across machines and what that exposes.)"""
import time

import pytest
from ros_procs import RosGraph

from relocation_app.graph import Graph, private_domain_id, ros_env
from relocation_common.paths import config_file

pytestmark = pytest.mark.graph


def test_bringup_environment_is_loopback_and_a_private_domain(tmp_path, monkeypatch):
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "SUBNET")  # an inherited wide setting is overridden
    env = ros_env(42, tmp_path)
    assert env["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST" and env["ROS_DOMAIN_ID"] == "42"
    assert env["ROS_LOG_DIR"].startswith(str(tmp_path)) and env["ROS_HOME"].startswith(str(tmp_path))
    domain, lock = private_domain_id()
    if lock is not None:
        lock.unlink()
    assert 0 < domain <= 100  # never the default domain 0
    g = Graph(tmp_path)
    assert g.env["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"
    g.stop_all()  # releases its reserved domain


def test_a_graph_is_invisible_from_another_domain(tmp_path):
    with RosGraph(tmp_path / "a") as a, RosGraph(tmp_path / "b") as b:
        assert a.domain_id != b.domain_id
        tp = a.start("qtree_task_planner.task_planner_node", params_file=config_file("task_planner.yaml"))
        deadline = time.monotonic() + 30
        while "/task_planner/train/_action/send_goal" not in dict(a.probe.node.get_service_names_and_types()):
            assert tp.alive() and time.monotonic() < deadline, tp.log()
            time.sleep(0.1)
        time.sleep(1.0)  # same time for the other domain to (not) see it
        assert "task_planner" in a.probe.node.get_node_names()
        assert "task_planner" not in b.probe.node.get_node_names()
        assert not [n for n, _ in b.probe.node.get_service_names_and_types() if n.startswith("/task_planner")]
