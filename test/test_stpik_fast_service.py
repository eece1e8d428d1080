"""PlanFeasibility's label_only (docs/motion_planner.md, "Performance notes") over DDS: the same answer without the
trajectory; the service is served while the node's main executor is busy elsewhere (its own executor thread)."""
import contextlib
from unittest import mock

import pytest
import ros_procs
from ros_procs import REPO, RosGraph

pytest.importorskip("rclpy")
from qtree_relocation_msgs.srv import PlanFeasibility

pytestmark = pytest.mark.graph

SRV = "/motion_planner/plan_feasibility"


def _graph_on_domains_60_69(tmp) -> RosGraph:
    """A RosGraph whose ROS_DOMAIN_ID is one of 60-69 (this work's private range)."""
    used = ros_procs.domains_in_use
    others = set(range(1, 101)) - set(range(60, 70))
    with mock.patch.object(ros_procs, "domains_in_use", lambda: used() | others):
        return RosGraph(tmp)


@pytest.fixture(scope="module")
def graph(tmp_path_factory):
    with contextlib.closing(_graph_on_domains_60_69(tmp_path_factory.mktemp("planner_label_only"))) as g:
        g.planner = g.start("stpik_motion_planner.motion_planner_node",
                            params_file=REPO / "config" / "motion_planner.yaml")
        yield g


def _ask(g, object_id, removed=(), label_only=False):
    req = PlanFeasibility.Request(object_id=object_id, removed_ids=list(removed), label_only=label_only)
    return g.probe.call(PlanFeasibility, SRV, req, timeout=60)


@pytest.mark.parametrize("object_id, removed", [("o2", ()), ("o6", ("o2", "o3")), ("T", ())])
def test_label_only_same_answer_without_trajectory(graph, object_id, removed):
    full = _ask(graph, object_id, removed)
    short = _ask(graph, object_id, removed, label_only=True)
    assert full.ok and short.ok, (full.message, short.message)
    assert (short.label, short.attempts, short.message) == (full.label, full.attempts, full.message)
    assert len(short.trajectory.points) == 0 and not short.trajectory.joint_names
    assert len(short.blockers) == len(full.blockers)
    if full.label != PlanFeasibility.Response.UNFEASIBLE:
        assert len(full.trajectory.points) > 100  # execution still gets its 100 Hz trajectory
    else:
        assert len(full.trajectory.points) == 0


def test_label_only_bad_request_still_refused(graph):
    res = _ask(graph, "nope", label_only=True)
    assert not res.ok and "nope" in res.message


class _Future:
    def __init__(self, res):
        self.res = res

    def add_done_callback(self, f):
        f(self)

    def result(self):
        return self.res


class _Client:
    srv_name = "/fake/plan_feasibility"

    def __init__(self):
        self.requests = []

    def service_is_ready(self):
        return True

    def call_async(self, req):
        self.requests.append(req)
        return _Future(PlanFeasibility.Response(ok=True, label=PlanFeasibility.Response.OBSTACLE, attempts=1,
                                                action="top_grasp"))

    def remove_pending_request(self, fut):
        pass


def test_task_planner_oracle_asks_for_the_label_only():
    from qtree_task_planner.task_planner_node import ServiceOracle

    client = _Client()
    ans = ServiceOracle(client, timeout=1.0, margin=1.0).feasibility("o1", frozenset({"o2"}))
    assert ans.label.name == "OBSTACLE" and ans.trajectory is None
    assert ans.action == "top_grasp"  # the feasible answer's action, read from the response
    assert [(r.object_id, list(r.removed_ids), r.label_only) for r in client.requests] == [("o1", ["o2"], True)]


def test_trajectory_message_holds_the_trajectory_exactly():
    import numpy as np

    from relocation_common.paths import default_scenario
    from relocation_common.scenario import load_scenario
    from stpik_motion_planner.planning.params import PlannerParams
    from stpik_motion_planner.planning.planner import MotionPlanner
    from stpik_motion_planner.ros_interface import trajectory_to_msg

    tr = MotionPlanner(load_scenario(default_scenario()), PlannerParams.load()).feasibility("o2").trajectory
    msg = trajectory_to_msg(tr)
    assert list(msg.joint_names) == list(tr.joint_names)
    assert np.array_equal(np.array([p.positions for p in msg.points]), tr.positions)
    assert np.array_equal(np.array([p.velocities for p in msg.points]), tr.velocities)
    stamps = np.array([p.time_from_start.sec + p.time_from_start.nanosec * 1e-9 for p in msg.points])
    assert np.allclose(stamps, tr.times, atol=1e-9, rtol=0)
