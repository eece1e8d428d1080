"""The demo's loop when the task planner dies during the execution (relocation_app.demo._train_and_watch), with a
fake client and a fake graph: the motion planner's relocation in flight is waited for, the goal is sent again to
the respawned task planner, and the run goes on to the new goal's result (the old demo ended with exit 3)."""
import json
import threading
import time
import types

from qtree_task_planner.ros_clients import GOAL_STATUS
from relocation_app import demo


class FakeNode:
    def create_subscription(self, *args, **kwargs):
        return None


class FakeGraph:
    """The graph launcher as the loop sees it: its events, its processes (pid only), check_alive."""

    def __init__(self, tmp_path):
        self.events, self.run_dir = [], tmp_path
        self.procs = {"task_planner": types.SimpleNamespace(pid=100)}

    def check_alive(self):
        pass

    def dead(self):
        return {}

    def respawn_task_planner(self, w):
        """SIGKILL and respawn: the died event, a new pid, its /diagnostics (with a scene) every 0.1 s."""
        self.events.append({"node": "task_planner", "event": "died", "code": -9, "t": 1.0, "note": ""})
        self.procs["task_planner"] = types.SimpleNamespace(pid=101)

        def up():
            for _ in range(50):
                time.sleep(0.1)
                w.pids[GOAL_STATUS], w.planner_scene = "101", "0.1 s old"
        threading.Thread(target=up, daemon=True).start()


class FakeClient:
    """Two goals: the first one's task planner dies during the execution, with o4's relocation in flight (the
    motion planner's goal ends 0.5 s later); the second one ends with success."""

    def __init__(self, graph, w):
        self.graph, self.w, self.sent, self.waits = graph, w, [], 0
        self.in_flight_until = None

    def wait_until_ready(self, timeout, check):
        pass

    def train(self, on_feedback=None, timeout=30.0, check=lambda: None, **goal):
        self.sent.append((time.monotonic(), goal))
        on_feedback(types.SimpleNamespace(phase="training", episode=1, q_sum=0.0, tree_nodes=1, mp_queries=1,
                                          planner_calls=1))
        return True

    def wait(self, timeout, check):
        self.waits += 1
        if self.waits == 1:  # executing: o4 relocated before, o5 in flight, then the task planner is killed
            w = self.w
            w.on_feedback("executing")
            w.execution(types.SimpleNamespace(data=json.dumps({"relocated": ["o4"], "sequence": ["o4", "o5", "T"],
                                                               "steps": [], "replans": []})))
            w.relocating.append("o5")
            w.status(types.SimpleNamespace(status_list=[types.SimpleNamespace(status=2)]))
            self.in_flight_until = time.monotonic() + 0.5
            threading.Timer(0.5, lambda: w.status(types.SimpleNamespace(status_list=[]))).start()
            self.graph.respawn_task_planner(w)
            check()
        return types.SimpleNamespace(result=types.SimpleNamespace(success=True), message="")

    def abandon(self):
        pass


def test_a_task_planner_killed_in_the_execution_gets_the_goal_again_after_the_motion_ended(tmp_path, monkeypatch):
    monkeypatch.setattr(demo, "DISCOVERY_SETTLE", 0.0)
    w = demo._Watch(FakeNode(), "/scene/objects")
    w.scene(types.SimpleNamespace(objects=[object()]))
    w.planner_scene = "0.5 s old"
    g = FakeGraph(tmp_path)
    client = FakeClient(g, w)
    a = types.SimpleNamespace(timeout=60.0, no_execute=False, execute_optimum=False)
    used = types.SimpleNamespace(policy="h-eg", search="depth", seed=0)
    end, result = demo._train_and_watch(client, g, a, used, w, time.monotonic())
    assert end is None, end.message  # old demo: End("node_died", "the task planner died during the execution ...")
    assert result.success and len(client.sent) == 2 and client.sent[0][1] == client.sent[1][1]
    assert client.sent[1][0] >= client.in_flight_until  # no second motion while the arm moved
    assert w.resumed == [{"t": w.resumed[0]["t"], "phase": "executing", "relocated_before": ["o4"], "in_flight": "o5",
                          "in_flight_ended": True, "steps_before": [], "replans_before": [],
                          "sequence_before": ["o4", "o5", "T"]}]
    assert not w.executing  # the new goal trains first: a death there resumes the training
