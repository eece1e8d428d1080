"""Feasibility queries (Eq. 11) on small scenes, with every trajectory verified independently of the planner:
joint limits (Table 6), velocity limits (Table 7) and clearance measured with coal (not python-fcl) on shapes
built here from the scenario and the robot description."""
import dataclasses
import math
import time

import coal
import numpy as np
import pinocchio as pin
import pytest

from jaco2_sim_driver.sim import GRASP_RADIAL_TOL
from relocation_common import robot_description as rd
from relocation_common.feasibility import NO_GRASP, Label
from relocation_common.scenario import UnknownObjectError, parse_scenario
from stpik_motion_planner.model.grasp import PALM_GAP, PALM_REACH, WorkspaceError
from stpik_motion_planner.planning import home as way_home
from stpik_motion_planner.planning.params import PlannerParams
from stpik_motion_planner.planning.planner import MotionPlanner
from stpik_motion_planner.planning.results import PlanningError

SHELF = {"x_front": 0.62, "depth": 0.36, "width": 0.8, "board_thickness": 0.02, "top_z": 0.02,
         "ceiling_z": 0.28, "bottom_z": -0.18}
MARKER = {"id": 7, "size": 0.07, "position": [0.625, -0.345, 0.09], "rpy": [1.5708, 0, -1.5708]}


def scene(objects, target, **shelf):
    return parse_scenario({"shelf": {**SHELF, **shelf}, "objects": objects, "target": target, "marker": MARKER,
                           "slots": [[0.76, -0.06 + 0.12 * k] for k in range(3)]})


# front: F in the open, B directly behind A; target B
SMALL = scene([{"id": "A", "weight": 0.3, "xy": [0.69, 0.0]}, {"id": "B", "xy": [0.80, 0.0]},
               {"id": "C", "weight": 0.5, "xy": [0.69, 0.25]}], "B")


@pytest.fixture(scope="module")
def planner():
    # answers must not depend on machine load: 5 s per query instead of the 0.5 s default (feasible ones take ~0.1 s)
    return MotionPlanner(SMALL, dataclasses.replace(PlannerParams.load(), timeout=5.0))


# ------------------------------------------------------------------ independent verification
def world_shapes(scenario, removed):
    """Boards and bottles as coal shapes with their transforms, built from the scenario alone."""
    s, t = scenario.shelf, scenario.shelf.board_thickness
    boxes = [((s.x_front, s.y_min, s.top_z - t), (s.x_back, s.y_max, s.top_z)),
             ((s.x_front, s.y_min, s.ceiling_z), (s.x_back, s.y_max, s.ceiling_z + t)),
             ((s.x_front, s.y_min, s.bottom_z - t), (s.x_back, s.y_max, s.bottom_z)),
             ((s.x_front, s.y_min - t, s.bottom_z - t), (s.x_back, s.y_min, s.ceiling_z + t)),
             ((s.x_front, s.y_max, s.bottom_z - t), (s.x_back, s.y_max + t, s.ceiling_z + t)),
             ((s.x_back, s.y_min - t, s.bottom_z - t), (s.x_back + t, s.y_max + t, s.ceiling_z + t))]
    out = [(None, coal.Box(*(np.subtract(hi, lo))), coal.Transform3s(np.eye(3), (np.add(lo, hi)) / 2))
           for lo, hi in boxes]
    for b in scenario.objects:
        if b.id not in removed:
            out.append((b.id, coal.Cylinder(b.radius, b.height),
                        coal.Transform3s(np.eye(3), np.array([b.x, b.y, s.top_z + b.height / 2]))))
    return out


def arm_capsules(model, data, q):
    pin.framesForwardKinematics(model, data, q)
    for c in rd.CAPSULES:
        if c.name in ("base", "shoulder"):
            continue
        m = data.oMf[model.getFrameId(c.link)]
        a, b = m.act(np.array(c.p0, float)), m.act(np.array(c.p1, float))
        z = (b - a) / np.linalg.norm(b - a)
        x = np.cross(z, [1.0, 0, 0]) if abs(z[0]) < 0.9 else np.cross(z, [0, 1.0, 0])
        x /= np.linalg.norm(x)
        r = np.column_stack([x, np.cross(z, x), z])
        yield c.name, coal.Capsule(c.radius, float(np.linalg.norm(b - a))), coal.Transform3s(r, (a + b) / 2)


def verify(traj, scenario, removed, grasped=None, approach_from=math.inf, clearance=None):
    """Limits, velocity limits, 100 Hz sampling, velocity integration and clearance (coal) along traj."""
    p = PlannerParams.load().stpik
    clearance = p.clearance if clearance is None else clearance
    assert np.allclose(np.diff(traj.times), 0.01, atol=1e-9) or np.all(np.diff(traj.times)[:-1] == pytest.approx(0.01))
    assert np.all(traj.positions >= rd.Q_LOWER - 1e-9) and np.all(traj.positions <= rd.Q_UPPER + 1e-9)
    assert np.all(np.abs(traj.velocities) <= rd.QDOT_MAX + 1e-9)
    integrated = traj.positions[0] + np.vstack([np.zeros(7), np.cumsum(
        traj.velocities[:-1] * np.diff(traj.times)[:, None], axis=0)])
    np.testing.assert_allclose(integrated, traj.positions, atol=1e-6)
    model = pin.buildModelFromXML(rd.urdf())
    data = model.createData()
    world = world_shapes(scenario, removed)
    worst = math.inf
    for t, q in zip(traj.times, traj.positions):
        for name, cap, tf in arm_capsules(model, data, q):
            for oid, shape, tfo in world:
                if oid is not None and oid == grasped and t >= approach_from and name in (
                        "palm", "finger_1", "finger_2", "finger_3"):
                    continue
                d = coal.distance(cap, tf, shape, tfo, coal.DistanceRequest(), coal.DistanceResult())
                worst = min(worst, d)
    assert worst >= clearance - 2e-3, f"clearance {worst:.4f} below the bound {clearance}"
    return worst


def approach_start(traj):
    return dict(traj.phases)["approach"]


# ------------------------------------------------------------------ feasibility
def test_bottle_in_the_open_is_feasible_obstacle(planner):
    ans = planner.feasibility("C", frozenset())
    assert ans.label == Label.OBSTACLE, ans.message
    assert ans.attempts >= 1 and ans.planning_time > 0
    verify(ans.trajectory, SMALL, set(), "C", approach_start(ans.trajectory))
    np.testing.assert_allclose(ans.trajectory.positions[0], rd.Q_HOME)
    # the trajectory ends at the grasp: tool at mid-height, short of the bottle axis by the palm standoff (the
    # palm stays PALM_GAP from the bottle), hand horizontal
    t = rd.dh_fk(ans.trajectory.positions[-1])[-1]
    standoff = 0.033 + PALM_GAP - PALM_REACH
    assert 0.01 < standoff < GRASP_RADIAL_TOL  # the bottle is still between the fingers for the driver
    np.testing.assert_allclose(t[:3, 3], [0.69 - standoff, 0.25, SHELF["top_z"] + 0.08], atol=5e-3)
    assert abs(t[2, 1] - 1.0) < 0.01 and abs(t[2, 2]) < 0.02  # tool y up, tool z horizontal


def test_bottle_behind_another_is_unfeasible_until_the_front_one_is_removed(planner):
    assert planner.feasibility("B", frozenset()).label == Label.UNFEASIBLE
    assert planner.feasibility("B", frozenset({"C"})).label == Label.UNFEASIBLE
    ans = planner.feasibility("B", frozenset({"A"}))
    assert ans.label == Label.TARGET, ans.message  # the target is g_T, not g_O
    verify(ans.trajectory, SMALL, {"A"}, "B", approach_start(ans.trajectory))
    assert planner.feasibility("A", frozenset()).label == Label.OBSTACLE


def test_timeout_is_a_safety_net_and_no_answer(planner):
    """The wall-clock timeout only stops a query (SafetyNetTimeout: no answer), it never makes it UNFEASIBLE."""
    from stpik_motion_planner.planning.budget import SafetyNetTimeout
    planner.set_scenario(planner.scenario)  # the STPIK checks of earlier questions dropped: this one plans its own
    t = time.perf_counter()
    with pytest.raises(SafetyNetTimeout):
        planner.feasibility("A", frozenset(), timeout=0.005)
    wall = time.perf_counter() - t
    assert wall < 0.005 + 0.25  # one IK step or validity check past the deadline at most, with slack
    assert planner.feasibility("A", frozenset()).label == Label.OBSTACLE


def test_bad_input_gets_a_clear_error(planner):
    with pytest.raises(UnknownObjectError, match="nope"):
        planner.feasibility("nope", frozenset())
    with pytest.raises(UnknownObjectError, match="ghost"):
        planner.feasibility("A", frozenset({"ghost"}))
    with pytest.raises(ValueError, match="removed"):
        planner.feasibility("A", frozenset({"A"}))
    with pytest.raises(ValueError, match="timeout"):
        planner.feasibility("A", frozenset(), timeout=float("nan"))
    with pytest.raises(WorkspaceError, match="finite"):
        planner.update_object("A", float("nan"), 0.0)
    with pytest.raises(ValueError, match="finite"):
        planner.plan_home([math.nan] * 7)


def test_an_obstacle_out_of_reach_is_answered_no_grasp_not_refused():
    """world/crowd_30 with perception: an obstacle at the back corner, (0.885, -0.354), beyond the arm's reach; the
    Q-Tree's first question about it was refused as bad input ("outside the arm's workspace") and the training was
    aborted. An obstacle on the shelf the hand cannot reach is a fact: g_U, "no grasp" with the reach, no attempt
    (the target too: test_a_target_out_of_reach_is_answered_no_grasp_not_refused)."""
    far = MotionPlanner(scene([{"id": "A", "weight": 0.3, "xy": [0.69, 0.0]}, {"id": "B", "xy": [0.80, 0.0]},
                               {"id": "Z", "weight": 0.4, "xy": [0.93, -0.354]}], "B"))
    a = far.feasibility("Z", frozenset())
    assert a.label == Label.UNFEASIBLE and a.attempts == 0 and a.blockers == (), a
    assert a.message.startswith(f"{NO_GRASP}Z stands out of the arm's reach") and "workspace" in a.message, a.message
    assert far.feasibility("A", frozenset()).label == Label.OBSTACLE


def test_a_target_out_of_reach_is_answered_no_grasp_not_refused():
    """The target too (it was a refused question, WorkspaceError): in the closed-loop grid a disturbance moved T of
    random5_08 464 mm, out of the arm's reach; the re-plan's question about it was refused and the task planner ended
    "training aborted: motion planner refused the query for 'T'" instead of proving that no retrieval is left."""
    far = MotionPlanner(scene([{"id": "X", "xy": [1.30, 0.0]}], "X", x_front=1.2, depth=0.3))
    a = far.feasibility("X", frozenset())
    assert a.label == Label.UNFEASIBLE and a.attempts == 0 and a.blockers == (), a
    assert a.message.startswith(f"{NO_GRASP}X stands out of the arm's reach") and "workspace" in a.message, a.message


def test_trajectory_resampling_keeps_the_stream_consistent(planner):
    traj = planner.feasibility("C", frozenset()).trajectory
    again = traj.resample(100.0)
    np.testing.assert_allclose(again.positions, traj.positions, atol=1e-9)
    assert traj.joint_names == rd.JOINT_NAMES


@pytest.mark.slow
def test_pick_carry_home_relocate_for_real(planner):
    pick = planner.plan_pick("C", frozenset())
    assert pick[0].gripper_after == "close"
    segs = planner.plan_carry("C", frozenset(), 0)
    assert [s.gripper_after for s in segs] == ["open", None]
    carry, retreat = segs[0].trajectory, segs[1].trajectory
    np.testing.assert_allclose(carry.positions[0], pick[0].trajectory.positions[-1], atol=1e-9)
    for seg in segs:  # limits, velocities, arm clearance to boards and the bottles left on the top shelf
        verify(seg.trajectory, SMALL, {"C"})
    t = rd.dh_fk(carry.positions[-1])[-1]
    slot = SMALL.slot(0)
    standoff = 0.033 + PALM_GAP - PALM_REACH  # the bottle axis is this far beyond the tool: on the slot
    np.testing.assert_allclose(t[:3, 3], [slot[0] - standoff, slot[1], SHELF["bottom_z"] + planner.params.drop + 0.08],
                               atol=5e-3)
    home = planner.plan_home(retreat.positions[-1], frozenset({"C"}), placed=[("C", slot)])
    np.testing.assert_allclose(home.positions[-1], rd.Q_HOME, atol=1e-9)
    verify(home, SMALL, {"C"})
    with pytest.raises(PlanningError):
        planner.plan_pick("B", frozenset())


def test_the_way_home_from_a_retreat_needs_no_sampling(planner, monkeypatch):
    """A retreat ends at the staging pose in front of its slot: the way home is the straight joint motion to that
    pose's reference configuration and the reference track (home -> staging pose) reversed, no RRT-Connect
    (docs/motion_planner.md, "Execution"); anywhere else the joint-space RRT-Connect plans it."""
    planner.plan_pick("C", frozenset())
    retreat = planner.plan_carry("C", frozenset(), 1)[1].trajectory
    slot = SMALL.slot(1)
    sampled = []
    real = way_home.plan_joint  # the joint-space RRT-Connect of home.plan_home
    monkeypatch.setattr(way_home, "plan_joint", lambda *a, **k: sampled.append(1) or real(*a, **k))
    home = planner.plan_home(retreat.positions[-1], frozenset({"C"}), placed=[("C", slot)])
    assert not sampled
    np.testing.assert_allclose(home.positions[0], retreat.positions[-1], atol=1e-9)
    np.testing.assert_allclose(home.positions[-1], rd.Q_HOME, atol=1e-9)
    verify(home, SMALL, {"C"})
    away = home.positions[len(home.positions) // 2]  # on the way, at no staging pose
    verify(planner.plan_home(away, frozenset({"C"}), placed=[("C", slot)]), SMALL, {"C"})
    assert sampled


def test_default_scenario_target_is_blocked_and_freed_by_o2_o6():
    """With the shipped grasp set (config/motion_planner.yaml: 5 yaws up to 0.5 rad, the second tier up to 0.8):
    T is blocked until o2 and o6 are gone, and o6 until o2 is (the demo's learned o2 -> o6 -> T, README). The
    first tier alone (3 yaws up to 0.35 rad) needed o3 gone as well: o6 stayed blocked with o2 gone."""
    from relocation_common.paths import default_scenario
    from relocation_common.scenario import load_scenario
    sc = load_scenario(default_scenario())
    mp = MotionPlanner(sc)  # the shipped parameters
    assert mp.feasibility("T", frozenset()).label == Label.UNFEASIBLE
    assert mp.feasibility("T", frozenset({"o2", "o3"})).label == Label.UNFEASIBLE
    assert mp.feasibility("o6", frozenset()).label == Label.UNFEASIBLE
    ans = mp.feasibility("o6", frozenset({"o2"}))
    assert ans.label == Label.OBSTACLE, ans.message
    verify(ans.trajectory, sc, {"o2"}, "o6", approach_start(ans.trajectory))
    for removed in ({"o2", "o6"}, {"o2", "o3", "o6"}):
        ans = mp.feasibility("T", frozenset(removed))
        assert ans.label == Label.TARGET, ans.message
        verify(ans.trajectory, sc, removed, "T", approach_start(ans.trajectory))
    narrow = dataclasses.replace(mp.params, n_yaws=3, max_yaw=0.35, wide_yaws=0)  # the grasp set this is about
    assert MotionPlanner(sc, narrow).feasibility("o6", frozenset({"o2"})).label == Label.UNFEASIBLE
