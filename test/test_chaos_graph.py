"""The chaos benchmark's small version (scripts/bench_chaos.py; docs/reliability.md, "A node that dies"): the demo
on scenario1_5 (ground truth), its motion planner SIGKILLed during the first carry. The old demo ended 1 s later
with exit 1, "node motion_planner exited with -9", and no report.json. Now the planner is respawned, recovers the
arm from its journal (the bottle set down where it was picked), the task planner sends the goal again and re-plans,
and the target is retrieved: report.json says so with the respawn, the arm is home, nothing is left running. A new
process that hears no joint state (1 run in 10 once: Fast DDS shared-memory errors) exits 75 and comes back again.
"""

import pytest
from ros_procs import load_script

pytestmark = [pytest.mark.graph, pytest.mark.slow]


def _bench():
    return load_script("bench_chaos")


def test_a_motion_planner_killed_during_a_carry_is_respawned_and_the_target_retrieved(tmp_path):
    bench = _bench()
    rec = bench.one_run(bench.Spec("motion_planner", "carry", 0), "scenario1_5", tmp_path, 600.0,
                        ["--scene-source", "ground_truth"])
    log = (tmp_path / "motion_planner_carry_0" / "demo.log").read_text()[-4000:]
    assert rec["killed"] is not None, log
    assert rec["report"] and rec["truthful"] and not rec["false_success"], (rec, log)
    assert rec["success"] and rec["target_on_bottom"] and rec["exit"] == 0, (rec, log)
    # the SIGKILL (-9); a new process that heard no joint state exits 75 and is started again (test_first_state.py)
    assert rec["deaths"][0] == -9 and set(rec["deaths"][1:]) <= {75}, rec
    assert rec["respawns"] == len(rec["deaths"]) and rec["orphans"] == 0, rec
    assert rec["arm_home"] and rec["gripper_empty"], rec
