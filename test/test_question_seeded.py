"""Same question, same answer (docs/motion_planner.md, "Determinism"): with `seed_per_query` every random draw of a
query (RRT-Connect's samples for the pick, the carry and the way home) is seeded from the question, so labels and
trajectories do not depend on the order of the queries or on the process. `direct_first: false` sends every pick
through RRT-Connect. The 300-query version over several scenes: scripts/check_same_answer.py."""
from __future__ import annotations

import dataclasses
import hashlib
import json
import random
import subprocess
import sys
from pathlib import Path

from relocation_common.paths import resolve_scenario
from relocation_common.scenario import load_scenario
from stpik_motion_planner.execution.relocation import plan_relocation
from stpik_motion_planner.planning.params import PlannerParams
from stpik_motion_planner.planning.planner import MotionPlanner

ROOT = Path(__file__).resolve().parents[1]
SCENE = "paper_experiment_10"
QUERIES = [("o1", ()), ("o2", ()), ("o3", ()), ("o4", ()), ("o6", ("o2", "o3")), ("o2", ("o1",)),
           ("T", ("o2", "o3", "o6")), ("o5", ("o1", "o2")), ("T", ())]


def params(seed_per_query: bool = True) -> PlannerParams:
    return dataclasses.replace(PlannerParams.load(), seed_per_query=seed_per_query, direct_first=False,
                               timeout=120.0, carry_timeout=120.0)


def digest(answer) -> str:
    """Label and trajectory (bit for bit) of one answer."""
    traj = answer.trajectory
    blob = b"" if traj is None else traj.positions.tobytes() + traj.velocities.tobytes()
    return f"{int(answer.label)}:{hashlib.sha256(blob).hexdigest()[:16]}"


def answers(scene: str, queries, seed_per_query: bool = True, order_seed: int | None = None) -> dict:
    """(object, removed) -> digest, the queries asked in the given order (or shuffled by order_seed) by one planner."""
    planner = MotionPlanner(load_scenario(resolve_scenario(scene)), params(seed_per_query))
    qs = list(queries)
    if order_seed is not None:
        random.Random(order_seed).shuffle(qs)
    return {f"{o}|{','.join(sorted(r))}": digest(planner.feasibility(o, frozenset(r))) for o, r in qs}


def test_the_same_questions_in_two_orders_and_two_processes_get_the_same_answers():
    first = answers(SCENE, QUERIES)
    assert answers(SCENE, QUERIES[::-1]) == first
    code = (f"import json, sys; sys.path[:0] = [{str(ROOT)!r}, {str(ROOT / 'test')!r}]\n"
            f"from test_question_seeded import answers, QUERIES\n"
            f"print(json.dumps(answers({SCENE!r}, QUERIES, order_seed=3)))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, check=True)
    assert json.loads(out.stdout.strip().splitlines()[-1]) == first
    assert sum(not d.startswith("0:") for d in first.values()) >= 6  # feasible answers, through RRT-Connect


def test_a_relocation_is_planned_the_same_after_other_queries():
    sc = load_scenario(resolve_scenario(SCENE))
    fresh = plan_relocation(MotionPlanner(sc, params()), "o3", ["o2"])
    busy = MotionPlanner(sc, params())
    for o, r in QUERIES[:4]:
        busy.feasibility(o, frozenset(r))
    plan_relocation(busy, "o1", [])
    again = plan_relocation(busy, "o3", ["o2"])
    for name in ("pick", "carry", "retreat", "home"):
        assert getattr(again, name).positions.tobytes() == getattr(fresh, name).positions.tobytes(), name
