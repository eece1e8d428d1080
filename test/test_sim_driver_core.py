"""The driver's behaviour without ROS (jaco2_sim_driver/driver.py): the loop's pacing and what it publishes when,
commands, Kinova's stop/start and home, the fingers protocol of kinova_fingers_action.cpp, the surfaces' joint
states, the parameter check, the camera loop. The node over DDS: test_driver_node.py, test_kinova_surface.py."""
import threading
import time
import types

import numpy as np
import pytest

import jaco2_sim_driver  # noqa: F401  (MUJOCO_GL=egl before mujoco)
from jaco2_sim_driver.driver import (
    FINGER_TIP_NAMES,
    HOMED,
    SimDriver,
    Snapshot,
    joint_names,
    joint_state,
)
from jaco2_sim_driver.params import DriverParams
from jaco2_sim_driver.sim import BadCommandError, Jaco2Sim
from relocation_common.arm_interface import ArmInterface
from relocation_common.kinova import FINGER_MAX_TURN, turns_to_joint
from relocation_common.paths import config_file, default_scenario
from relocation_common.robot_description import FINGER_JOINT_NAMES, JOINT_NAMES, N_JOINTS, Q_HOME
from relocation_common.scenario import load_scenario

SCENARIO = load_scenario(default_scenario())
PARAMS, ARM = DriverParams.load(), ArmInterface.load()


@pytest.fixture(scope="module")
def sim():
    return Jaco2Sim(SCENARIO)


def driver(sim, **params) -> SimDriver:
    """The loop unpaced (one step a tick), no extra state after a command unless asked."""
    sim.reset()
    sim.q_home = np.asarray(Q_HOME, float)
    return SimDriver(sim, PARAMS.replace(**{"real_time_factor": 0.0, "state_on_command": False, **params}), ARM)


class Loop:
    """The node's simulation thread without publishing: SimDriver.tick until stopped."""

    def __init__(self, core: SimDriver):
        self.core, self.stop = core, threading.Event()
        self.thread = threading.Thread(target=self.run, daemon=True)

    def run(self):
        while not self.stop.is_set():
            self.core.tick()

    def __enter__(self):
        self.thread.start()
        return self

    def __exit__(self, *exc):
        self.stop.set()
        self.thread.join(5.0)


def test_unpaced_loop_steps_once_per_tick_and_publishes_at_the_rates(sim):
    core = driver(sim, joint_state_rate=100.0, tf_rate=0.0, objects_rate=10.0)
    ticks = [core.tick() for _ in range(200)]
    assert [t.steps for t in ticks] == [1] * 200
    states = [t.time for t in ticks if t.state is not None]
    assert states[0] == pytest.approx(0.001) and len(states) == 21  # due at once, then every 10 ms
    assert np.allclose(np.diff(states[1:]), 0.01)
    assert sum(t.tf is not None for t in ticks) == 1  # tf_rate 0: once (the start)
    assert sum(t.objects is not None for t in ticks) == 2
    tf = next(t.tf for t in ticks if t.tf is not None)
    assert len(tf[3]) == len(SCENARIO.objects) and np.allclose(tf[1], Q_HOME, atol=1e-3)


def test_health_reports_the_joint_states_and_their_rate_per_simulated_second(sim):
    """The rate is over the simulated time since the last report: joint_state_rate when every step is its own tick
    (one state every 10 ms), fewer when a late loop steps MAX_BATCH (20) at once (one state per tick)."""
    from jaco2_sim_driver.driver import MAX_BATCH

    core = driver(sim, joint_state_rate=100.0)
    core.health()
    for _ in range(1000):
        core.tick()
    values = core.health()[2]
    assert values["joint states"] == "101" and float(values["joint state rate (per simulated s)"]) == \
        pytest.approx(101.0)  # the first due at once, then every 10 ms of the 1 s
    core._steps_due = lambda t: MAX_BATCH  # a loop behind: MAX_BATCH steps a tick
    for _ in range(50):
        core.tick()
    assert float(core.health()[2]["joint state rate (per simulated s)"]) == pytest.approx(1 / (MAX_BATCH * 0.001))


def test_state_on_command_publishes_after_the_step_that_applied_it(sim):
    core = driver(sim, joint_state_rate=10.0, state_on_command=True)
    core.tick()  # the first state is due at once
    assert core.tick().state is None
    core.command(np.full(N_JOINTS, 0.1))
    tick = core.tick()
    assert tick.state is not None and np.allclose(sim.command, 0.1)


def test_a_bad_command_raises_and_the_arm_holds(sim):
    core = driver(sim)
    core.command(np.full(N_JOINTS, 0.2))
    core.tick()
    assert np.allclose(sim.command, 0.2)
    for bad in ([float("nan")] * N_JOINTS, [0.1] * 3, "fast"):
        with pytest.raises(BadCommandError):
            core.command(bad)
        core.tick()
        assert np.allclose(sim.command, 0.0)


def test_the_gripper_command_grasps_nothing_and_refuses_bad_values(sim):
    core = driver(sim)
    assert core.gripper(turns_to_joint([FINGER_MAX_TURN] * 3)) is None  # nothing between the fingers at home
    with pytest.raises(BadCommandError):
        core.gripper([0.1, float("nan"), 0.1])


def test_home_brings_the_arm_back_and_opens_the_fingers(sim):
    core = driver(sim)  # real_time_factor 0: one physics step (1 ms) a tick, whatever the machine's load
    for _ in range(200):  # 0.2 s of commands at 0.5 rad/s, each within the driver's 50 ms watchdog
        core.command(np.full(N_JOINTS, 0.5))
        core.tick()
    core.gripper(turns_to_joint([3000.0] * 3))
    for _ in range(300):
        core.tick()
    assert np.max(np.abs(sim.q - Q_HOME)) > 0.02
    with Loop(core):
        assert core.home() == HOMED
    assert np.max(np.abs(sim.q - Q_HOME)) < 1e-3 and np.max(np.abs(sim.finger_q)) < 0.02


def test_stop_refuses_home_and_finger_goals_until_start(sim):
    core = driver(sim)
    core.stop()
    assert core.home() == "Arm is stopped, cannot home"
    outcome, turns = core.fingers([FINGER_MAX_TURN] * 3)
    assert outcome == "abort" and np.allclose(turns, 0.0, atol=1.0)
    core.start()
    assert not core.stopped


def test_fingers_reach_a_goal_with_feedback(sim):
    core = driver(sim, real_time_factor=2.0)
    seen = []
    with Loop(core):
        outcome, turns = core.fingers([3000.0] * 3, feedback=seen.append)
    assert outcome == "succeed" and np.all(np.abs(turns - 3000.0) <= 64.0), turns
    assert seen and all(len(p) == 3 for p in seen)


def test_finger_goals_cancel_preempt_and_refuse_nonsense(sim):
    core = driver(sim, real_time_factor=2.0)
    assert core.fingers([float("nan"), 0.0, 0.0])[0] == "abort"
    with Loop(core):
        assert core.fingers([FINGER_MAX_TURN] * 3, cancelled=lambda: True)[0] == "canceled"
    # the simulation stands still (no loop) until the newer goal is in: the first goal stays in motion however late
    # its thread runs (with the loop on, a thread starved until the fingers had closed saw its goal reached at its
    # first look, before any feedback, and nothing was left to preempt)
    first: list = []
    moving = threading.Event()
    t = threading.Thread(target=lambda: first.append(core.fingers([FINGER_MAX_TURN] * 3,
                                                                  feedback=lambda _: moving.set())))
    t.start()
    assert moving.wait(30.0)
    second: list = []
    t2 = threading.Thread(target=lambda: second.append(core.fingers([0.0] * 3)))  # a newer goal
    t2.start()
    t.join(30.0)
    assert first and first[0][0] == "abort"  # the older one ends aborted
    with Loop(core):
        t2.join(30.0)
    assert second and second[0][0] == "succeed"


def test_reset_restarts_the_scenario_and_the_pacing(sim):
    core = driver(sim)
    core.stop()
    for _ in range(50):
        core.tick()
    assert core.reset() == SCENARIO.name and not core.stopped and sim.time == 0.0
    assert core.tick().state is not None  # a state is due at once after a reset


@pytest.mark.parametrize("surface", ["kinova", "ros2_control"])
def test_joint_states_of_each_surface(surface):
    s = Snapshot(1.0, np.arange(7.0), np.full(7, 0.1), np.full(7, 2.0), np.array([6800.0, 0.0, 3400.0]),
                 np.array([100.0, 0.0, 0.0]))
    names = joint_names(surface)
    position, velocity, effort = joint_state(surface, s)
    assert len(position) == len(velocity) == len(effort) == len(names)
    assert names[:N_JOINTS] == list(JOINT_NAMES) and names[N_JOINTS:N_JOINTS + 3] == list(FINGER_JOINT_NAMES)
    assert np.allclose(position[:N_JOINTS], s.q) and np.allclose(position[7:10], turns_to_joint(s.turns))
    assert np.allclose(position[7], np.radians(80.0))  # Kinova: 6800 turns = 80 deg
    assert effort[N_JOINTS:] == [0.0] * (len(names) - N_JOINTS)
    if surface == "kinova":  # no finger velocity; the finger tips listed, always 0
        assert names[10:] == list(FINGER_TIP_NAMES) and position[10:] == [0.0] * 3 and velocity[7:] == [0.0] * 6
    else:
        assert len(names) == 10 and np.allclose(velocity[7:], turns_to_joint(s.turns_dot))


def test_the_parameter_check_names_the_bad_parameter():
    import yaml

    params = yaml.safe_load(config_file("jaco2_sim_driver.yaml").read_text())["jaco2_sim_driver"]["ros__parameters"]
    assert DriverParams(**params) == PARAMS
    for key, value, words in (("joint_state_rate", 0.0, "joint_state_rate must be > 0"),
                              ("camera_fovy", 180.0, r"camera_fovy must be in \(0, 180\)"),
                              ("tf_rate", -1.0, "tf_rate must be >= 0"),
                              ("camera_height", float("nan"), "camera_height must be a finite number"),
                              ("camera_width", 640.5, "camera_width must be an integer"),
                              ("real_time_factor", "fast", "real_time_factor must be a finite number"),
                              ("sim_time_stamps", 1, "sim_time_stamps must be true or false"),
                              ("camera_model", "kinect", "camera_model must be one of")):
        with pytest.raises(ValueError, match=words):
            DriverParams(**{**params, key: value})
    arm = ArmInterface.load().to_dict()  # the settings shared with the planner (config/arm_interface.yaml)
    for key, value, words in (("finger_tolerance", float("nan"), "finger_tolerance"),
                              ("command_interface", "can", "command_interface must be one of kinova, ros2_control"),
                              ("driver_prefix", "/j2s7s300 driver", "driver_prefix must be a ROS namespace")):
        with pytest.raises(ValueError, match=words):
            ArmInterface(**{**arm, key: value})


def test_the_camera_loop_hands_over_frames_until_told_to_stop(sim):
    core = driver(sim)
    frames = []
    core.camera_loop(0.01, lambda f: frames.append(f) or len(frames) < 2, threading.Event())
    assert len(frames) == 2 and frames[0].rgb.shape == (sim.camera.height, sim.camera.width, 3)
    stop = threading.Event()
    stop.set()
    core.camera_loop(0.01, frames.append, stop)  # set before: no frame
    assert len(frames) == 2


def test_a_frame_carries_the_wall_time_of_the_state_it_shows_not_of_its_publishing(sim, monkeypatch):
    """Under load a render took far longer than its 75 ms, and frames stamped when published showed the arm where it
    had been before the stamp (perception's self-filter took the wrong joint states). The frame's `wall` is taken
    when the joint positions are copied: with a render of 0.3 s the frame is published 0.3 s after its `wall`."""
    import time

    import jaco2_sim_driver.driver as driver_module

    class SlowRenderer(driver_module.CameraRenderer):
        def render(self, data):
            time.sleep(0.3)
            return super().render(data)

    monkeypatch.setattr(driver_module, "CameraRenderer", SlowRenderer)
    core = driver(sim)
    lags = []
    core.camera_loop(0.01, lambda f: lags.append(time.time() - f.wall) or False, threading.Event())
    assert len(lags) == 1 and lags[0] >= 0.3, lags


@pytest.mark.parametrize("factor", [1.0, 2.0])
def test_the_simulation_never_runs_ahead_of_the_wall(sim, monkeypatch, factor):
    """The pacing (SimDriver._steps_due) on a wall clock the test moves: late ticks of 1-700 ms (a loaded machine).
    Simulated time since the pacing's origin stays at most `factor` times the wall's (a late loop drops its backlog
    beyond MAX_LAG instead of racing, which only moves the origin later)."""
    import jaco2_sim_driver.driver as driver_module

    wall = [1000.0]
    # the driver module's own clock only (not time.monotonic of every thread in this worker)
    clock = types.SimpleNamespace(**{k: getattr(time, k) for k in dir(time) if not k.startswith("_")})
    clock.monotonic = lambda: wall[0]
    monkeypatch.setattr(driver_module, "time", clock)
    core = driver(sim, real_time_factor=factor)
    core.tick()  # the pacing's origin
    wall0, sim0 = wall[0], sim.time
    rng = np.random.default_rng(7)
    for _ in range(300):
        wall[0] += float(rng.choice([0.001, 0.003, 0.02, 0.1, 0.7], p=[0.5, 0.3, 0.1, 0.07, 0.03]))
        core.tick()
        assert sim.time - sim0 <= factor * (wall[0] - wall0) + 1e-9
    assert sim.time - sim0 > 0.1 * factor * (wall[0] - wall0)  # it did run
