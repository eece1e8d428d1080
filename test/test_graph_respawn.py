"""The graph launcher's respawn (relocation_app.graph, config/graph.yaml; launch_ros's respawn, respawn_delay):
a node that dies comes back after its delay, up to max_respawns times, and says so; a node without respawn (the
driver) stops the run at once. Fake node processes (test/fake_node.py) stand in for the real ones: the launcher is
the part under test. The old launcher had no respawn: every death raised at once."""
import os
import signal
import time
from pathlib import Path

import pytest

from relocation_app import graph
from relocation_app.graph import Graph, NodeDied, Respawn, respawn_policies
from relocation_common.config import ConfigError

TEST_DIR = Path(__file__).resolve().parent


def _graph(tmp_path, monkeypatch, **policies):
    monkeypatch.setattr(graph, "NODES", {name: ("fake_node", "perception.yaml") for name in graph.NODES})
    monkeypatch.setattr(graph, "respawn_policies", lambda: policies)
    g = Graph(tmp_path, respawn=True)
    g.env["PYTHONPATH"] = os.pathsep.join([str(TEST_DIR), g.env["PYTHONPATH"]])
    return g


def _wait(predicate, timeout=20.0):
    deadline = time.monotonic() + timeout
    while not predicate():
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.05)


def test_a_dead_node_is_respawned_after_its_delay_up_to_its_limit(tmp_path, monkeypatch):
    g = _graph(tmp_path, monkeypatch, perception=Respawn(True, 0.5, 2), jaco2_sim_driver=Respawn(False, 0.0, 0))
    with g:
        first = g.start("perception")
        _wait(lambda: "respawn 0" in g.log("perception"))
        os.kill(first.pid, signal.SIGKILL)
        t0 = time.monotonic()
        _wait(lambda: any(e["event"] == "respawned" for e in g.events))
        assert time.monotonic() - t0 >= 0.4  # respawn_delay
        g.check_alive()  # coming back: not an end of the run
        second = g.procs["perception"]
        assert second.pid != first.pid
        _wait(lambda: "respawn 1" in g.log("perception"))  # the node is told (its /diagnostics says so)
        assert "[graph] respawned after exit -9" in g.log("perception")  # the log goes on, marked
        os.kill(second.pid, signal.SIGKILL)
        _wait(lambda: sum(e["event"] == "respawned" for e in g.events) == 2)
        os.kill(g.procs["perception"].pid, signal.SIGKILL)  # the third death: max_respawns 2 reached
        _wait(lambda: "perception" in g.dead())
        with pytest.raises(NodeDied, match="node perception exited with -9"):
            g.check_alive()
        assert [e["event"] for e in g.events] == ["died", "respawned", "died", "respawned", "died"]
        assert "max_respawns reached" in g.events[-1]["note"]


def test_a_node_without_respawn_ends_the_run_and_a_stopped_node_is_not_respawned(tmp_path, monkeypatch):
    g = _graph(tmp_path, monkeypatch, perception=Respawn(True, 0.0, 3), jaco2_sim_driver=Respawn(False, 0.0, 0))
    with g:
        driver = g.start("jaco2_sim_driver")
        g.start("perception")
        _wait(lambda: "respawn 0" in g.log("perception"))
        assert g.stop("perception") == 0  # stopped on purpose: never respawned
        time.sleep(0.6)
        assert not g.events
        os.kill(driver.pid, signal.SIGKILL)
        _wait(lambda: bool(g.dead()))
        with pytest.raises(NodeDied) as e:
            g.check_alive()
        assert e.value.name == "jaco2_sim_driver" and e.value.code == -signal.SIGKILL
        assert "no respawn" in g.events[-1]["note"]
    assert g.procs == {}


def test_the_shipped_policies_and_bad_ones(tmp_path):
    p = respawn_policies()
    assert not p["jaco2_sim_driver"].respawn and p["perception"].respawn and p["motion_planner"].respawn
    from relocation_common.paths import config_file
    good = config_file("graph.yaml").read_text()
    bad = tmp_path / "graph.yaml"
    for old, new, says in (("max_respawns: 3", "max_respawns: -1", "max_respawns"),
                           ("respawn_delay: 1.0", "respawn_delay: soon", "respawn_delay"),
                           ("task_planner:", "task_planner_typo:", "task_planner needs")):
        bad.write_text(good.replace(old, new, 1))
        with pytest.raises(ConfigError, match=says):
            respawn_policies(bad)
