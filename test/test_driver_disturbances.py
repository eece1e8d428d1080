"""The driver's disturbance hook without ROS (jaco2_sim_driver/driver.py over the MuJoCo core; docs/closed_loop.md):
commands as the node's /sim/disturb transforms, a DisturbancePlan from the parameters, reset undoing them."""
import numpy as np
import pytest

import jaco2_sim_driver  # noqa: F401  (MUJOCO_GL=egl before mujoco)
from jaco2_sim_driver.disturbance import DisturbancePlan
from jaco2_sim_driver.driver import SimDriver
from jaco2_sim_driver.params import DriverParams
from jaco2_sim_driver.sim import Jaco2Sim
from relocation_app.final_state import HOME_TOL
from relocation_common.arm_interface import ArmInterface
from relocation_common.paths import default_scenario
from relocation_common.robot_description import BASE_LINK, Q_HOME
from relocation_common.scenario import load_scenario

SCENARIO = load_scenario(default_scenario())
PARAMS = DriverParams.load()


@pytest.fixture(scope="module")
def core():
    sim = Jaco2Sim(SCENARIO)
    sim.q_home = np.asarray(Q_HOME, float)
    return SimDriver(sim, PARAMS.replace(real_time_factor=0.0), ArmInterface.load())


def _xy(core, oid):
    return next(np.array(p.position[:2]) for p in core.sim.object_poses() if p.id == oid)


def test_commands_nudge_move_and_refuse_with_the_reason_then_reset_undoes_them(core):
    core.reset()
    before = _xy(core, "o5")
    core.disturb("bottle_o5", "bottle_o5", (0.0, 0.02, 0.0), (0.0, 0.0, 0.0, 1.0))  # relative: a nudge
    core.disturb(BASE_LINK, "grasped", (0, 0, 0), (0, 0, 0, 1))  # nothing in the hand
    core.disturb("world", "bottle_o5", (0, 0, 0), (0, 0, 0, 1))  # another bottle's frame: refused
    records = core.tick().disturbances
    assert [r.get("kind") for r in records] == ["nudge", None, None], records
    assert "nothing in the hand" in records[1]["skipped"] and "use base_link" in records[2]["skipped"].replace(
        BASE_LINK, "base_link")
    for _ in range(200):
        core.tick()
    moved = _xy(core, "o5") - before
    assert 0.0 < moved[1] <= 0.0201 and abs(moved[0]) < 0.003, moved
    core.reset()
    assert np.allclose(_xy(core, "o5"), before, atol=1e-6)
    assert core.tick().disturbances == []


def test_the_plan_and_drop_parameters_are_checked_and_taken():
    plan = DisturbancePlan.draw(2, seed=3, relocations=3)
    PARAMS.replace(disturbance_plan=plan.to_json(), drop_probability=0.5)
    with pytest.raises(ValueError, match="drop_probability"):
        PARAMS.replace(drop_probability=1.5)
    with pytest.raises(ValueError, match="disturbance_plan: not a disturbance plan"):
        PARAMS.replace(disturbance_plan="{nope")
    core = SimDriver.from_params(PARAMS.replace(disturbance_plan=plan.to_json(), real_time_factor=0.0),
                                 ArmInterface.load())
    assert core.schedule is not None and core.schedule.plan == plan and core.dropper.probability == 0.0


def test_a_relocation_ends_for_the_plan_with_the_arm_within_the_motion_planner_s_home_tol(core):
    """The schedule's "relocation i ended" (the arm back home after a release) is the motion planner's home_tol, read
    from config/motion_planner.yaml. Before, the schedule kept its own 0.05 rad (the planner's value when it was
    written; the planner's went down to 0.03): an arm 0.04 rad off home counted as home, while the planner still
    brought it there."""
    core.reset()
    core.disturbances(0.0, 0, DisturbancePlan.draw(1, seed=3, relocations=1))
    assert core.schedule is not None
    try:
        for off, home in ((HOME_TOL + 0.01, False), (HOME_TOL - 0.01, True)):
            core.sim.q_home = Q_HOME + np.eye(7)[3] * off
            core.sim.home()  # the arm at q_home: `off` from Q_HOME at the elbow
            core.sim.q_home = np.asarray(Q_HOME, float)
            assert core.schedule.at_home(core.sim) is home, off
    finally:
        core.sim.q_home = np.asarray(Q_HOME, float)
        core.disturbances(PARAMS.drop_probability, PARAMS.drop_seed, PARAMS.plan())
        core.reset()
