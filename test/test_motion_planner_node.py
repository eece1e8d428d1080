"""motion_planner node as a real process with the MuJoCo driver over DDS: feasibility service, relocation action."""
import math
import time

import numpy as np
import pytest
from ros_procs import REPO, RosGraph, future_result

pytest.importorskip("rclpy")
from qtree_relocation_msgs.action import RelocateObject
from qtree_relocation_msgs.msg import ObjectArray
from qtree_relocation_msgs.srv import PlanFeasibility
from rclpy.qos import QoSDurabilityPolicy, QoSProfile
from sensor_msgs.msg import JointState
from visualization_msgs.msg import Marker

from relocation_common import robot_description as rd
from relocation_common.feasibility import Label
from relocation_common.paths import default_scenario
from relocation_common.ros_conversions import msg_to_objects
from relocation_common.scenario import load_scenario
from stpik_motion_planner.planning.params import PlannerParams
from stpik_motion_planner.planning.planner import MotionPlanner

pytestmark = pytest.mark.graph

SRV = "/motion_planner/plan_feasibility"
LATCHED = QoSProfile(depth=1, durability=QoSDurabilityPolicy.TRANSIENT_LOCAL)
SCENARIO = load_scenario(default_scenario())


@pytest.fixture(scope="module")
def graph(tmp_path_factory):
    g = RosGraph(tmp_path_factory.mktemp("motion_planner"))
    try:
        g.driver = g.start("jaco2_sim_driver.driver_node", params_file=REPO / "config" / "jaco2_sim_driver.yaml",
                           params={"camera_rate": 0.0})
        g.planner = g.start("stpik_motion_planner.motion_planner_node",
                            params_file=REPO / "config" / "motion_planner.yaml", params={"scene_topic": "/sim/objects"})
        g.objects = g.probe.collect("/sim/objects", ObjectArray, LATCHED)
        g.states = g.probe.collect("/j2s7s300_driver/out/joint_state", JointState, 50)
        g.path = g.probe.collect("/motion_planner/path", Marker, LATCHED)
        g.action = g.relocate_client(g.driver, g.planner)
        g.objects.wait(timeout=30)
        g.states.wait(timeout=30)
        yield g
    finally:
        g.close()


def _ask(g, object_id, removed=(), timeout=0.0):
    return g.probe.call(PlanFeasibility, SRV, PlanFeasibility.Request(object_id=object_id, removed_ids=list(removed),
                                                                       timeout=timeout), timeout=30)


def _positions(g) -> dict[str, np.ndarray]:
    g.objects.clear()
    msg = g.objects.wait(timeout=5)[-1]
    return {o.id: o.base() for o in msg_to_objects(msg)}  # base centres


def _send(g, object_id, removed=()):
    """Send a goal; returns (handle or None if rejected, feedback list)."""
    feedback = []
    fut = g.action.send_goal_async(RelocateObject.Goal(object_id=object_id, removed_ids=list(removed)),
                                   feedback_callback=lambda f: feedback.append(f.feedback))
    handle = future_result(fut, 30, "goal response never came")
    return (handle if handle.accepted else None), feedback


def _result(handle, timeout=120.0):
    return future_result(handle.get_result_async(), timeout)


def test_feasibility_service_answers_as_the_core(graph):
    core = MotionPlanner(SCENARIO, PlannerParams.load())
    for object_id, removed in [("o2", ()), ("T", ()), ("o6", ("o2", "o3")), ("o6", ("o2",))]:
        # a generous timeout: labels must agree on the planner's logic, not on how loaded the machine is
        res = _ask(graph, object_id, removed, timeout=5.0)
        ans = core.feasibility(object_id, frozenset(removed), timeout=5.0)
        assert res.ok and Label(res.label) == ans.label, (object_id, removed, res.message, ans.message)
        if ans.label != Label.UNFEASIBLE:
            pts = res.trajectory.points
            assert len(pts) > 10 and list(res.trajectory.joint_names)[0] == "j2s7s300_joint_1"
            dt = pts[1].time_from_start.nanosec * 1e-9 + pts[1].time_from_start.sec
            assert dt == pytest.approx(0.01, abs=1e-6)  # 100 Hz, ready to stream
        else:
            assert not res.trajectory.points


def test_a_certify_request_answers_as_the_core_and_a_pick_names_what_it_comes_near(graph):
    """PlanFeasibility's certify (the whole relocation), near_ids (the pick's near set) and action (a feasible
    answer's), as the core gives them."""
    core = MotionPlanner(SCENARIO, PlannerParams.load())
    for object_id, removed in [("o6", ("o2",)), ("T", ("o2", "o6")), ("T", ())]:
        req = PlanFeasibility.Request(object_id=object_id, removed_ids=list(removed), timeout=5.0, label_only=True)
        pick = graph.probe.call(PlanFeasibility, SRV, req, timeout=30)
        req.certify = True
        cert = graph.probe.call(PlanFeasibility, SRV, req, timeout=60)
        want, want_cert = core.feasibility(object_id, frozenset(removed)), core.certify(object_id, frozenset(removed))
        assert pick.ok and cert.ok and (Label(pick.label), Label(cert.label)) == (want.label, want_cert.label)
        assert pick.near_known == (want.label != Label.UNFEASIBLE) and not cert.near_known
        assert frozenset(pick.near_ids) == (want.near or frozenset())
        assert (pick.action, cert.action) == (want.action, want_cert.action)  # side_grasp, or "" when unfeasible
    assert want.label == Label.UNFEASIBLE and not pick.near_ids  # T with nothing removed: blocked


@pytest.mark.parametrize("object_id, removed, timeout, fragment", [
    ("ghost", (), 0.0, "unknown object id 'ghost'"),
    ("o2", ("o2",), 0.0, "is in the removed set"),
    ("o2", ("nobody",), 0.0, "nobody"),
    ("", (), 0.0, "unknown object id"),
    ("o2", (), math.nan, "timeout"),
])
def test_bad_feasibility_requests_are_refused_and_the_node_keeps_serving(graph, object_id, removed, timeout,
                                                                          fragment):
    res = _ask(graph, object_id, removed, timeout)
    assert not res.ok and fragment in res.message, res.message
    assert _ask(graph, "o2").ok and graph.planner.alive


@pytest.mark.slow
def test_relocation_moves_the_bottle_to_its_slot_and_leaves_the_others(graph):
    before = _positions(graph)
    handle, feedback = _send(graph, "o2")
    assert handle is not None
    res = _result(handle)
    assert res.result.success, res.result.message
    phases = [f.phase for f in feedback]
    order = ["plan_pick", "approach", "grasp", "plan_carry", "carry", "release", "retreat", "plan_home", "home"]
    seen = [p for p in dict.fromkeys(phases) if p in order]
    assert seen == order, phases
    paths = graph.path.wait(timeout=5)
    path = paths[-1]  # the last motion: the way home (or the settle move after it), ending at the home tool position
    assert path.text == "home" and any(p.text == "home" and len(p.points) > 2 for p in paths)
    home = (path.points[-1].x, path.points[-1].y, path.points[-1].z)
    np.testing.assert_allclose(home, rd.dh_fk(rd.Q_HOME)[-1][:3, 3], atol=1e-6)
    progress = [f.progress for f in feedback]
    assert progress == sorted(progress) and progress[-1] == pytest.approx(1.0)
    time.sleep(0.5)
    after = _positions(graph)
    slot = SCENARIO.slot(0)
    np.testing.assert_allclose(after["o2"], (slot[0], slot[1], SCENARIO.shelf.bottom_z), atol=0.01)
    for oid in SCENARIO.ids:
        if oid != "o2":
            assert np.linalg.norm(after[oid] - before[oid]) < 0.01, oid
    # bad goals are refused with the reason (accepted, then aborted), the node keeps serving
    assert "unknown object id 'ghost'" in _refused(graph, "ghost")
    assert "in its own removed set" in _refused(graph, "o3", ["o3"])
    assert _ask(graph, "o3", ["o2"]).ok


def _refused(g, object_id, removed=()) -> str:
    """The reason of a goal the node refuses: accepted, then aborted with it (as nav2 does)."""
    handle, _ = _send(g, object_id, removed)
    res = _result(handle, 10)
    assert res.status == 6 and not res.result.success, res.result.message  # GoalStatus.STATUS_ABORTED
    return res.result.message


def _joint_speed(g) -> float:
    g.states.clear()
    msgs = g.states.wait(lambda m: len(m) >= 5, timeout=5)
    return max(float(np.max(np.abs(m.velocity[:7]))) for m in msgs[-3:])


def test_a_relocated_object_cannot_be_relocated_again(graph):
    """Old code: accepted; the arm drove to the empty place, closed on nothing and aborted 0.95 rad from home, and
    every later goal failed. Runs after the o2 relocation above."""
    assert "already relocated" in _refused(graph, "o2", ())


def test_the_driver_and_the_planner_report_their_health_on_diagnostics(graph):
    """diagnostic_msgs on /diagnostics, as rqt_robot_monitor reads it (the old driver and planner published none):
    the driver's command age and watchdog stops, the planner's questions in flight, its last answer and the bottles
    it placed (o2, by the relocation above), each with its pid. Runs after the o2 relocation above."""
    from diagnostic_msgs.msg import DiagnosticArray

    diag = graph.probe.collect("/diagnostics", DiagnosticArray, 50)

    def status(name):
        msgs = diag.wait(lambda m: any(st.name == name for x in m for st in x.status), timeout=10)
        st = [st for x in msgs for st in x.status if st.name == name][-1]
        return st, {kv.key: kv.value for kv in st.values}

    st, values = status("jaco2_sim_driver: arm")
    assert st.level == b"\x00" and values["pid"] == str(graph.driver.pid), (st, values)
    assert "command age (s)" in values and int(values["watchdog stops"]) >= 0, values
    st, values = status("motion_planner: planning")
    assert st.level == b"\x00" and values["pid"] == str(graph.planner.pid), (st, values)
    assert values["feasibility questions in flight"] == "0" and int(values["feasibility answers"]) >= 1, values
    assert '"o2"' in values["relocated"] and values["last answer"], values


@pytest.mark.slow
def test_cancel_during_the_carry_sets_the_bottle_down_and_the_next_goal_works(graph):
    """The old node stopped the arm where it was, the bottle held in the air. Now the goal ends cancelled
    after the recovery: back along the carry, the bottle let go where it was picked, back along the approach."""
    before = _positions(graph)
    handle, feedback = _send(graph, "o3", ["o2"])
    deadline = time.monotonic() + 90
    while not any(f.phase == "carry" and f.progress > 0.5 for f in feedback):
        assert time.monotonic() < deadline, [f.phase for f in feedback]
        time.sleep(0.02)
    handle.cancel_goal_async()
    res = _result(handle, 60)
    assert res.status == 5 and "set down where it was picked" in res.result.message, res.result.message
    time.sleep(0.5)
    after = _positions(graph)
    moved = {oid: float(np.linalg.norm(after[oid] - before[oid])) for oid in SCENARIO.ids}
    assert max(moved.values()) < 0.01, moved
    graph.states.clear()
    q = np.array(graph.states.wait(timeout=5)[-1].position[:7])
    # home: within 0.03 rad (config/motion_planner.yaml home_tol; the recovery's last motion once ended 0.044 rad off)
    np.testing.assert_allclose(q, rd.Q_HOME, atol=0.03)
    handle, _ = _send(graph, "o3", ["o2"])
    res = _result(handle)
    assert res.result.success, res.result.message


def test_cancel_stops_the_arm_and_a_dead_driver_aborts_the_relocation(graph):
    handle, feedback = _send(graph, "o6", ["o2", "o3"])
    deadline = time.monotonic() + 60
    while not any(f.phase == "approach" and f.progress > 0.2 for f in feedback):
        assert time.monotonic() < deadline, [f.phase for f in feedback]
        time.sleep(0.02)
    assert _joint_speed(graph) > 0.05  # moving
    handle.cancel_goal_async()
    res = _result(handle, 30)
    assert res.status == 5 and "cancelled" in res.result.message  # GoalStatus.STATUS_CANCELED
    assert "arm back home along its approach" in res.result.message, res.result.message
    time.sleep(0.2)
    assert _joint_speed(graph) < 0.01
    # again (the arm is home after the recovery); kill the driver on the way
    handle, feedback = _send(graph, "o6", ["o2", "o3"])
    while not any(f.phase in ("home", "approach") for f in feedback):
        assert time.monotonic() < deadline + 60
        time.sleep(0.02)
    graph.driver.stop(timeout=5)
    t0 = time.monotonic()
    res = _result(handle, 10)
    assert res.status == 6 and "no joint state" in res.result.message, res.result.message  # ABORTED
    assert time.monotonic() - t0 < 5.0
    assert _ask(graph, "o6", ["o2", "o3"]).ok and graph.planner.alive
