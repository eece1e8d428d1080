#!/usr/bin/env python3
"""Is a lane the pick skips as squeezed (model/approach.py) one STPIK stops on? On generated scenes.

For every scene (the shipped ones named, each also moved by `scenes jitter`: every bottle up to `--jitter` m, seeds
0..`--seeds`-1, fixed before any result), every object with a grasp and `--sets` removed sets drawn per object
(seeded by scene and object): every candidate lane (pick.candidates) whose approach the check calls squeezed is
planned and tracked as the pick would (its direct path or RRT-Connect to the pre-grasp, STPIK along it, then the
approach, up to max_attempts paths). Printed: lanes checked, squeezed lanes, and those STPIK tracked to the grasp
anyway (a lane the check would have wrongly skipped), each named. Not a timed test: numbers to read (docs/bench/).
Usage: .venv/bin/python scripts/bench_squeezed_lanes.py [--scenes scenario3_15 paper_experiment_10] [--seeds 3]
"""
from __future__ import annotations

import argparse
import random
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import yaml

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # this tree's packages first



def tracked(mp: Any, object_id: str, removed: frozenset[str], g: Any) -> bool:
    """The pick's steps on lane `g` alone (its direct path first, then RRT-Connect), up to max_attempts paths: True
    if STPIK reached the grasp on one."""
    from relocation_common import robot_description as rd
    from stpik_motion_planner.model.collision import approach_skip
    from stpik_motion_planner.planning.pick import cartesian_path
    from stpik_motion_planner.planning.results import QueryStats

    obs, p = mp.scene.obstacles(removed), mp.params
    skip = approach_skip(mp.scenario.object(object_id))
    rng = mp.question_rng("squeezed", object_id, removed, g.yaw)
    for k in range(p.max_attempts):
        deadline, stats = time.perf_counter() + 300.0, QueryStats()
        path = cartesian_path(mp, mp.home, g.pre_grasp, obs, mp.hand, p.rrt_max_checks, deadline, stats, k == 0, rng)
        if path is None:
            continue
        r1 = mp.track(rd.Q_HOME, path, obs, deadline, stats)
        if not r1.ok:
            continue
        r2 = mp.track(r1.q[-1], [np.array(g.pre_grasp), np.array(g.grasp)], obs, deadline, stats, skip,
                      speed=p.stpik.approach_speed, yaw_tol=p.stpik.grasp_yaw_tol)
        if r2.ok:
            return True
    return False


def main() -> None:
    from relocation_app.evaluation.scenes.jitter import jitter_scene
    from relocation_common.paths import resolve_scenario
    from relocation_common.scenario import load_scenario, parse_scenario
    from stpik_motion_planner.model.approach import squeezed_approach
    from stpik_motion_planner.model.collision import approach_skip
    from stpik_motion_planner.planning.params import PlannerParams
    from stpik_motion_planner.planning.pick import candidates
    from stpik_motion_planner.planning.planner import MotionPlanner

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scenes", nargs="*", default=["scenario3_15", "paper_experiment_10"])
    ap.add_argument("--seeds", type=int, default=3, help="jittered copies per scene (and the scene itself)")
    ap.add_argument("--jitter", type=float, default=0.012, help="m: bottles moved up to this far")
    ap.add_argument("--sets", type=int, default=8, help="removed sets drawn per object")
    a = ap.parse_args()
    params = PlannerParams.load()
    band = params.stpik.clearance + params.stpik.act
    lanes = squeezed = 0
    wrong: list[str] = []
    for name in a.scenes:
        data = yaml.safe_load(resolve_scenario(name).read_text())
        variants = [load_scenario(name)] + [parse_scenario(jitter_scene(data, a.jitter, s)) for s in range(a.seeds)]
        for sc in variants:
            mp = MotionPlanner(sc, params)
            ids = [o.id for o in sc.objects]
            for o in ids:
                rng = random.Random(f"{sc.name}:{o}")
                others = [x for x in ids if x != o and x != sc.target_id]
                for _ in range(a.sets):
                    removed = frozenset(rng.sample(others, rng.randint(0, len(others))))
                    if mp.not_graspable(o):
                        break
                    obs = mp.scene.obstacles(removed)
                    for g in candidates(mp, o, obs):
                        lanes += 1
                        why = squeezed_approach(g, obs, approach_skip(sc.object(o)), band, params.resolution,
                                                params.stpik.final_tol_pos)
                        if not why:
                            continue
                        squeezed += 1
                        if tracked(mp, o, removed, g):
                            wrong.append(f"{sc.name} {o} removed {sorted(removed)}: {why}")
            print(f"{sc.name}: {lanes} lanes so far, {squeezed} squeezed, {len(wrong)} of them tracked", flush=True)
    print(f"total: {lanes} candidate lanes, {squeezed} squeezed, {len(wrong)} squeezed lanes STPIK tracked to the "
          "grasp")
    for w in wrong:
        print("   ", w)


if __name__ == "__main__":
    main()
