"""A motion planner that hears no joint state (motion_planner_node._check_first_state; docs/reliability.md, "A node
that hears nothing"). In one of ten full test runs, a planner respawned after a SIGKILL mid-carry heard nothing over
DDS (Fast DDS's shared-memory port errors in its log): its recovery waited 30 s for a joint state, failed, and the
run's goal ran out. Now the process exits 75 after first_state_wait when a joint state is needed (an interrupted
relocation in its journal, or the driver's publisher in the graph), its journal kept for the next process; a planner
without a driver and nothing to recover stays (it answers feasibility questions). The real node here; the probe's
publisher that never publishes stands for a driver whose states do not arrive. On the old code no planner exits."""
import time

import numpy as np
import pytest
from ros_procs import REPO, RosGraph
from sensor_msgs.msg import JointState

from relocation_common import robot_description as rd
from relocation_common.arm_interface import ArmInterface
from stpik_motion_planner.execution.journal import Journal, Running
from stpik_motion_planner.execution.relocation import Progress
from stpik_motion_planner.planning.trajectory import Trajectory

pytestmark = [pytest.mark.graph]

WAIT = 3.0  # s: first_state_wait here


def _planner(g: RosGraph, name: str, **params):
    return g.start("stpik_motion_planner.motion_planner_node", name=name,
                   params_file=REPO / "config" / "motion_planner.yaml", params={"first_state_wait": WAIT, **params})


def _ready(p, timeout: float = 90.0) -> None:
    deadline = time.monotonic() + timeout
    while "ready: scenario" not in p.log():
        assert p.alive() and time.monotonic() < deadline, p.log()[-3000:]
        time.sleep(0.1)


def _exit_code(p, timeout: float = 90.0) -> int:
    deadline = time.monotonic() + timeout
    while p.alive():
        assert time.monotonic() < deadline, p.log()[-3000:]
        time.sleep(0.1)
    return p.popen.returncode


def test_a_planner_that_needs_joint_states_and_hears_none_exits_for_a_restart(tmp_path):
    journal = tmp_path / "journal.json"
    home = np.tile(np.asarray(rd.Q_HOME, float), (2, 1))
    pick = Trajectory(np.array([0.0, 0.5]), home, np.zeros((2, 7)))  # a pick begun at home, then the process died
    Journal(journal).write({}, Running(Progress("o1", [], [], [("pick", pick)], False, False), 0, [], None))
    with RosGraph(tmp_path) as g:
        alone = _planner(g, "alone")  # no driver, nothing to recover: stays
        _ready(alone)
        time.sleep(WAIT + 2.0)
        assert alone.alive(), alone.log()[-3000:]
        assert alone.stop() == 0
        recovering = _planner(g, "recovering", journal_path=str(journal))  # a journal to recover, no driver seen
        assert _exit_code(recovering) == 75, recovering.log()[-3000:]
        assert "an interrupted relocation to recover: this process hears nothing" in recovering.log()
        assert Journal(journal).load()[1] is not None  # kept for the next process
        pub = g.probe.publisher(JointState, ArmInterface.load().state_topic)  # a driver whose states never arrive
        deaf = _planner(g, "deaf")
        g.probe.wait_for_subscribers(pub, timeout=60.0)
        assert _exit_code(deaf) == 75, deaf.log()[-3000:]
        assert "the driver publishes them: this process hears nothing" in deaf.log()
