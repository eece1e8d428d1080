"""The motion planner's budget is work, not wall time (docs/reliability.md): the same question gets the same answer on
an idle and on a loaded machine, and the wall-clock safety net, when it runs out, is no answer (never UNFEASIBLE).

The load is simulated inside the planner's own process: every hand-proxy validity check (RRT-Connect's unit of
work) is followed by a busy wait of LOAD_FACTOR times that very check's CPU time, as on a machine shared with other
jobs. The wait scales with the check as it runs: calibrated once from the idle run's mean cost (in microseconds), a
loaded run at a busier moment of a shared machine than its idle run was only 1.8x slower, and the check that the
load was real failed (1 full test run in 10). Whether the load was real is decided inside the loaded run itself:
its busy waits took at least 3 times the CPU time of all the rest of its work. Each run is a fresh process
(OMPL's RNG is process-wide and seeded once), asking the same queries in the same order. With the old wall-clock
budget (rrt_timeout 0.08 s per attempt) the loaded run answered UNFEASIBLE where the idle one found a path."""
import json
import subprocess
import sys

import pytest
from ros_procs import REPO

# scenario3_15 queries whose answers need RRT-Connect (the direct path is blocked), found with the real planner
# (the committed cache's feasible answers with 2 attempts)
QUERIES = [("o7", ["o10", "o2", "o3", "o4", "o8", "o9"]),
           ("o9", ["o1", "o11", "o12", "o2", "o3", "o5", "o7", "o8"]),
           ("o13", ["o1", "o10", "o14", "o2", "o3", "o4", "o5", "o8", "o9"]),
           ("o12", ["o10", "o13", "o14", "o2", "o3", "o4", "o5", "o7", "o8", "o9"])]
LOAD_FACTOR = 25.0  # every validity check is followed by a busy wait this many times its own CPU time:
# the checks are about a quarter of the planner's work, so a run takes about 7x the CPU time

WORKER = r"""
import hashlib, json, sys, time
sys.path.insert(0, {repo!r})
from relocation_common.paths import resolve_scenario
from relocation_common.scenario import load_scenario
from stpik_motion_planner.model import collision
from stpik_motion_planner.planning.params import PlannerParams
from stpik_motion_planner.planning.planner import MotionPlanner

factor = {factor!r}
collides = collision.HandProxy.collides
waited = [0.0]  # CPU seconds of busy waiting
def timed(self, *a, **k):
    t0 = time.thread_time()  # CPU time: a check preempted by another process does not lengthen its wait
    r = collides(self, *a, **k)
    t1 = time.thread_time()
    end = t1 + factor * (t1 - t0)
    while time.thread_time() < end:
        pass
    waited[0] += time.thread_time() - t1
    return r
collision.HandProxy.collides = timed
mp = MotionPlanner(load_scenario(resolve_scenario("scenario3_15")), PlannerParams.load())
out = []
for obj, removed in {queries!r}:
    t, c = time.perf_counter(), time.thread_time()
    a = mp.feasibility(obj, frozenset(removed))
    traj = "" if a.trajectory is None else hashlib.sha256(a.trajectory.positions.tobytes()).hexdigest()[:16]
    out.append(dict(label=a.label.name, attempts=a.attempts, rrt=mp.last_stats.rrt_calls, traj=traj,
                    wall=time.perf_counter() - t, cpu=time.thread_time() - c, message=a.message))
print(json.dumps(dict(queries=out, waited=waited[0])))
"""


def _run(factor: float) -> dict:
    code = WORKER.format(repo=str(REPO), factor=factor, queries=QUERIES)
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr[-3000:]
    return json.loads(p.stdout.strip().splitlines()[-1])


def test_same_answers_and_paths_idle_and_loaded():
    idle = _run(0.0)["queries"]
    # each check followed by LOAD_FACTOR x its own CPU time (a fixed 150 us was 7.5x on one machine and 2.5x on a 3x
    # slower one; the idle run's mean cost, 1.8x when the loaded run met a busier machine: the module docstring)
    run = _run(LOAD_FACTOR)
    loaded = run["queries"]
    print("\nidle  ", [(r["label"], r["attempts"], round(r["wall"], 3)) for r in idle])
    print("loaded", [(r["label"], r["attempts"], round(r["wall"], 3)) for r in loaded])
    assert all(r["rrt"] > 0 for r in idle)  # the queries exercise RRT-Connect
    assert sum(r["label"] != "UNFEASIBLE" for r in idle) >= 3
    key = [(r["label"], r["attempts"], r["rrt"], r["traj"]) for r in idle]
    assert [(r["label"], r["attempts"], r["rrt"], r["traj"]) for r in loaded] == key, (idle, loaded)
    cpu = sum(r["cpu"] for r in loaded)
    assert run["waited"] > 3 * (cpu - run["waited"]), (run["waited"], cpu)  # the load was real: at least 4x


def test_safety_net_is_no_answer_never_unfeasible():
    from relocation_common.paths import resolve_scenario
    from relocation_common.scenario import load_scenario
    from stpik_motion_planner.planning.budget import SafetyNetTimeout
    from stpik_motion_planner.planning.params import PlannerParams
    from stpik_motion_planner.planning.planner import MotionPlanner

    mp = MotionPlanner(load_scenario(resolve_scenario("scenario3_15")), PlannerParams.load())
    obj, removed = QUERIES[0]
    with pytest.raises(SafetyNetTimeout, match="safety net"):
        mp.feasibility(obj, frozenset(removed), timeout=1e-4)
    assert mp.feasibility(obj, frozenset(removed)).label.name == "OBSTACLE"  # asked again: answered
