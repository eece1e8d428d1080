"""PlanFeasibility's blocker fields, served by the motion_planner node as a real process (docs/motion_planner.md,
"Blockers")."""
import pytest
import ros_procs
from ros_procs import REPO, RosGraph

pytest.importorskip("rclpy")
from qtree_relocation_msgs.srv import PlanFeasibility

from relocation_common.feasibility import Label
from relocation_common.paths import default_scenario
from relocation_common.ros_conversions import blockers_from_msgs, lanes_from_msgs
from relocation_common.scenario import load_scenario
from stpik_motion_planner.planning.params import PlannerParams
from stpik_motion_planner.planning.planner import MotionPlanner

pytestmark = pytest.mark.graph

SRV = "/motion_planner/plan_feasibility"


@pytest.fixture(scope="module")
def graph(tmp_path_factory):
    used = ros_procs.domains_in_use
    ros_procs.domains_in_use = lambda: used() | (set(range(1, 101)) - set(range(50, 60)))  # domains 50-59 only
    try:
        g = RosGraph(tmp_path_factory.mktemp("blockers"))
    finally:
        ros_procs.domains_in_use = used
    try:
        g.planner = g.start("stpik_motion_planner.motion_planner_node",
                            params_file=REPO / "config" / "motion_planner.yaml")
        yield g
    finally:
        g.close()


def _ask(g, object_id, removed=(), all_lanes=False):
    req = PlanFeasibility.Request(object_id=object_id, removed_ids=list(removed), all_lanes=all_lanes)
    return g.probe.call(PlanFeasibility, SRV, req, timeout=60)


def test_blockers_and_lanes_over_the_service(graph):
    core = MotionPlanner(load_scenario(default_scenario()), PlannerParams.load())
    res = _ask(graph, "T")
    assert res.ok and Label(res.label) == Label.UNFEASIBLE and not res.lanes
    assert blockers_from_msgs(res.blockers) == core.feasibility("T", frozenset()).blockers
    assert all(b.certain for b in blockers_from_msgs(res.blockers)) and res.blockers
    res = _ask(graph, "", ("o2",), all_lanes=True)  # lanes only
    assert res.ok and res.message == "lanes only" and not res.blockers
    assert lanes_from_msgs(res.lanes) == core.lane_blockers(frozenset({"o2"}))
    res = _ask(graph, "o1", (), all_lanes=True)  # a question and every lane
    assert res.ok and Label(res.label) == Label.OBSTACLE and not res.blockers and len(res.lanes) == 11
    res = _ask(graph, "", ())  # no object and no lanes asked: a bad request, as before
    assert not res.ok and "unknown object id" in res.message
