"""The motion planner node's behaviour without ROS: stpik_motion_planner/execution/streaming.py (streaming a motion
from the
joint states, holding the arm while they are late, the gripper protocol on either surface) over a fake arm link,
and stpik_motion_planner/service.py (scene updates, goal checks, a relocation's outcome and recovery) on the real
planner. The node over DDS: test_motion_planner_node.py, test_planner_on_fake_arm.py."""
import dataclasses
import time
from dataclasses import replace

import numpy as np
import pytest
import yaml

from jaco2_sim_driver.params import DriverParams
from relocation_common import robot_description as rd
from relocation_common.kinova import joint_to_turns, turns_to_joint
from relocation_common.paths import config_file, default_scenario
from relocation_common.scenario import load_scenario
from stpik_motion_planner.execution.streaming import Aborted, Cancelled, StreamedArm, StreamParams, progress
from stpik_motion_planner.planning.params import PlannerParams
from stpik_motion_planner.planning.trajectory import Trajectory
from stpik_motion_planner.service import MotionPlannerService

WATCHDOG = DriverParams.load().watchdog_timeout
FAST = dict(gripper_settle=0.0, finger_stall_interval=0.1, state_timeout=0.5)


class FakeLink:
    """An arm that moves exactly at the commanded velocity until the driver's watchdog stops it (`watchdog_timeout`
    without a command, as the simulator and Kinova's driver do: without it, a test thread starved between two commands
    at a load of 20 left the fake arm running, "tracking error 0.303 rad", a recovery 10 rad off), fingers that move
    at `finger_speed` rad/s toward their position command and stop at `block` (a bottle), joint states that go silent
    between `silent` (t0, t1): seconds after the first one asked for (counted from the link's creation, a test thread
    starved for 0.1 s before its first look found the silence begun and no state at all: "no joint state from the
    driver for inf s")."""

    def __init__(self, kinova=False, block=None, finger_speed=4.0, silent=(0.0, 0.0), goal_result=None):
        self.kinova, self.block, self.finger_speed, self.silent = kinova, block, finger_speed, silent
        self.goal_result = goal_result
        self.q, self.v, self.t = np.array(rd.Q_HOME, float), np.zeros(rd.N_JOINTS), time.monotonic()
        self.commanded = self.t  # the last command's time
        self.t0 = None  # the first joint state's time
        self.fingers, self.target = np.zeros(3), 0.0
        self.sent, self.paths, self.alive = [], [], True

    def _advance(self):
        now = time.monotonic()
        dt, moving = now - self.t, max(0.0, min(now, self.commanded + WATCHDOG) - self.t)
        self.t = now
        self.q = self.q + self.v * moving
        step = np.clip(self.target - self.fingers, -self.finger_speed * dt, self.finger_speed * dt)
        self.fingers = self.fingers + step
        if self.block is not None:
            self.fingers = np.minimum(self.fingers, self.block)
        return now

    def send(self, qdot):
        self.commanded = self._advance()
        self.v = np.asarray(qdot, float)
        self.sent.append(self.v.copy())

    def joint_state(self):  # as the node keeps it: the last one received (None before the first)
        now = self._advance()
        self.t0 = now if self.t0 is None else self.t0
        if not self.silent[0] <= now - self.t0 < self.silent[1]:
            self.last = self.q.copy(), now
        return getattr(self, "last", None)

    def finger_state(self):
        return self.fingers.copy(), self._advance()

    def send_fingers(self, angle):
        self.target = angle

    def finger_goal(self, turns, deadline, cancelled):
        return np.full(3, turns if self.goal_result is None else self.goal_result)

    def show_path(self, trajectory, phase):
        self.paths.append(phase)

    def ok(self):
        return self.alive

    def driver_present(self):
        return True


def line(duration=0.3, speed=0.5):
    t = np.arange(0, duration + 1e-9, 0.01)
    v = np.zeros((len(t), rd.N_JOINTS))
    v[:-1, 1] = speed
    return Trajectory(t, rd.Q_HOME + np.outer(t, [0, speed, 0, 0, 0, 0, 0]), v)


def arm(link, cancelled=lambda: False, **params):
    feedback, log = [], []
    a = StreamedArm(link, dataclasses.replace(StreamParams.load(), **{**FAST, **params}), cancelled,
                    lambda *f: feedback.append(f), lambda *m: log.append(m))
    return a, feedback, log


def test_a_streamed_motion_settles_at_its_end_and_stops_the_arm():
    link = FakeLink()
    a, feedback, _ = arm(link)
    traj = line()
    a.follow(traj, "approach")
    np.testing.assert_allclose(a.measured(), traj.positions[-1], atol=0.005)
    assert link.paths == ["approach"] and np.all(link.sent[-1] == 0.0)
    assert feedback[0] == ("approach", pytest.approx(progress("approach"), abs=0.01))
    assert all(progress("approach") <= p <= progress("grasp") for _, p in feedback)


def test_late_joint_states_hold_the_arm_until_they_return():
    link = FakeLink(silent=(0.1, 0.35))
    a, _, log = arm(link)
    traj = line(0.5)
    a.follow(traj, "carry")
    np.testing.assert_allclose(a.measured(), traj.positions[-1], atol=0.005)
    assert any(np.all(v == 0.0) for v in link.sent[:-3])  # held (zero velocity) while silent
    assert any(level == "warning" and "joint states back after" in text for level, text in log)


def test_silence_longer_than_state_timeout_aborts_and_cancel_is_seen():
    a, _, _ = arm(FakeLink(silent=(0.0, 10.0)))
    with pytest.raises(Aborted, match="no joint state from the driver"):
        a.follow(line(), "approach")
    a, _, _ = arm(FakeLink(), cancelled=lambda: True)
    with pytest.raises(Cancelled):
        a.follow(line(), "approach")
    a.uncancellable().follow(line(0.05), "recover")  # the recovery runs to its end
    link = FakeLink()
    link.alive = False
    with pytest.raises(Aborted, match="node shutting down"):
        arm(link)[0].follow(line(), "approach")


def test_ros2_control_gripper_closes_on_a_bottle_and_refuses_empty_or_stuck_fingers():
    closed = StreamParams.load().finger_closed
    a, _, log = arm(FakeLink(block=float(turns_to_joint(0.5 * closed))))
    a.gripper("close", "grasp")  # stalled half-way: a bottle between the fingers
    assert log[-1] == ("info", "gripper close: fingers stopped 50% closed")
    with pytest.raises(Aborted, match="closed on nothing"):
        arm(FakeLink())[0].gripper("close", "grasp")
    stuck = FakeLink(block=float(turns_to_joint(0.5 * closed)))
    stuck.fingers[:] = stuck.block
    stuck.finger_speed = 0.0
    with pytest.raises(Aborted, match="gripper open: the fingers stopped 50% closed"):
        arm(stuck)[0].gripper("open", "release")
    assert joint_to_turns(stuck.fingers)[0] == pytest.approx(0.5 * closed)


def test_kinova_gripper_takes_the_fingers_action_result():
    closed = StreamParams.load().finger_closed
    arm(FakeLink(kinova=True, goal_result=0.6 * closed))[0].gripper("close", "grasp")
    with pytest.raises(Aborted, match="did not move"):
        arm(FakeLink(kinova=True, goal_result=0.0))[0].gripper("close", "grasp")
    arm(FakeLink(kinova=True))[0].gripper("open", "release")


def test_stream_parameters_come_from_the_node_yaml_and_are_checked():
    params = yaml.safe_load(config_file("motion_planner.yaml").read_text())["motion_planner"]["ros__parameters"]
    params.update(yaml.safe_load(config_file("arm_interface.yaml").read_text())["/**"]["ros__parameters"])
    p = StreamParams.from_mapping(params)
    assert p.stream_rate == 100.0 and p.follower.k_track == params["follower.k_track"]
    assert p.finger_stall_interval == params["finger_stall_interval"]  # the arm interface's, one source
    with pytest.raises(ValueError, match="0 < state_hold < state_timeout"):
        StreamParams.from_mapping({**params, "state_hold": 3.0})
    assert progress("plan_pick") == 0.0 and progress("done") == 1.0


@pytest.fixture(scope="module")
def service():
    return MotionPlannerService(load_scenario(default_scenario()), PlannerParams.load())


def test_goal_checks_name_the_problem(service):
    target = service.base.target_id
    with pytest.raises(ValueError, match="unknown object id 'nope'"):
        service.check_goal("nope", [])
    with pytest.raises(ValueError, match="own removed set"):
        service.check_goal(target, [target])
    service.relocated["o1"] = 0
    try:
        with pytest.raises(ValueError, match="already relocated"):
            service.check_goal("o1", [])
    finally:
        service.relocated.clear()
    with pytest.raises(ValueError, match="finite"):
        service.feasibility(target, [], float("nan"))


def test_scene_updates_replace_moved_bottles_and_free_a_relocated_one_seen_back(service):
    b = service.bottles["o1"]
    z = service.base.shelf.top_z
    service.relocated["o1"] = 0
    moved = replace(b, y=b.y + 0.01, support_z=z)
    try:
        assert service.update_scene([moved]) == ["o1"]
        assert service.planner.scenario.object("o1").y == pytest.approx(b.y + 0.01)
        assert "o1" not in service.relocated
        assert service.update_scene([replace(moved, support_z=z + 0.2)]) == []  # lifted: not on the top shelf
    finally:
        service.update_scene([replace(b, support_z=z)])


def test_a_relocation_cancelled_at_the_approach_recovers_and_reports_it(service):
    obj = service.base.objects[0].id
    link = FakeLink(kinova=True)
    a, feedback, _ = arm(link, cancelled=lambda: bool(link.paths))  # cancelled once the approach starts
    out = service.relocate(a, obj, [])
    assert out.status == "canceled" and out.message.startswith("cancelled: arm stopped; recovered: "), out
    assert link.paths[0] == "approach" and "recover" in link.paths
    assert service.check_goal(obj, []) is None  # not relocated: it can be asked again
