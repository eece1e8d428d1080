"""The motion planner's budget is work, not wall time (docs/reliability.md): the same question gets the same answer on
an idle and on a loaded machine, and the wall-clock safety net, when it runs out, is no answer (never UNFEASIBLE).

The load is simulated inside the planner's own process: every hand-proxy validity check (RRT-Connect's unit of
work) busy-waits LOAD_FACTOR times its idle cost more (measured in the idle run), about 8x slower, as on a machine
shared with other jobs. Each run is a fresh process
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
LOAD_FACTOR = 7.0  # every validity check busy-waits this many times its idle cost more: about 8x slower

WORKER = r"""
import hashlib, json, sys, time
sys.path.insert(0, {repo!r})
from relocation_common.paths import resolve_scenario
from relocation_common.scenario import load_scenario
from stpik_motion_planner.model import collision
from stpik_motion_planner.planning.params import PlannerParams
from stpik_motion_planner.planning.planner import MotionPlanner

load = {load!r}
collides = collision.HandProxy.collides
checks = [0, 0.0]  # hand-proxy validity checks, their own seconds (the idle run's cost per check)
def timed(self, *a, **k):
    t0 = time.perf_counter()
    end = t0 + load * 1e-6
    while time.perf_counter() < end:
        pass
    t1 = time.perf_counter()
    r = collides(self, *a, **k)
    checks[0] += 1
    checks[1] += time.perf_counter() - t1
    return r
collision.HandProxy.collides = timed
mp = MotionPlanner(load_scenario(resolve_scenario("scenario3_15")), PlannerParams.load())
out = []
for obj, removed in {queries!r}:
    t = time.perf_counter()
    a = mp.feasibility(obj, frozenset(removed))
    traj = "" if a.trajectory is None else hashlib.sha256(a.trajectory.positions.tobytes()).hexdigest()[:16]
    out.append(dict(label=a.label.name, attempts=a.attempts, rrt=mp.last_stats.rrt_calls, traj=traj,
                    wall=time.perf_counter() - t, message=a.message))
print(json.dumps(dict(queries=out, check_us=1e6 * checks[1] / max(1, checks[0]))))
"""


def _run(load_us: float) -> dict:
    code = WORKER.format(repo=str(REPO), load=load_us, queries=QUERIES)
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr[-3000:]
    return json.loads(p.stdout.strip().splitlines()[-1])


def test_same_answers_and_paths_idle_and_loaded():
    first = _run(0.0)
    idle = first["queries"]
    # each check made LOAD_FACTOR x slower than this machine's own cost of one (a fixed 150 us was 7.5x on one
    # machine and 2.5x on a 3x slower one, where the load no longer doubled the wall time)
    loaded = _run(LOAD_FACTOR * first["check_us"])["queries"]
    print("\nidle  ", [(r["label"], r["attempts"], round(r["wall"], 3)) for r in idle])
    print("loaded", [(r["label"], r["attempts"], round(r["wall"], 3)) for r in loaded])
    assert all(r["rrt"] > 0 for r in idle)  # the queries exercise RRT-Connect
    assert sum(r["label"] != "UNFEASIBLE" for r in idle) >= 3
    key = [(r["label"], r["attempts"], r["rrt"], r["traj"]) for r in idle]
    assert [(r["label"], r["attempts"], r["rrt"], r["traj"]) for r in loaded] == key, (idle, loaded)
    assert sum(r["wall"] for r in loaded) > 2 * sum(r["wall"] for r in idle)  # the load was real


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
