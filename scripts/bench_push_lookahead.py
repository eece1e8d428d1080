"""Would one push have opened a retrieval that the picks alone cannot? The failed runs of a closed-loop grid
(bench_closed_loop.py's JSON lines), from each run's final simulator scene (`final_scene`, as its proof reads it).

For every pair of objects on the top shelf (X, C), X != C: the in-process motion planner's push of X out of C's
grasp lanes with nothing removed (MotionPlanner.push_feasibility, the closed loop's push question); for each feasible
one, the proof of bench_closed_loop.prove (the exact blocker A* over the picks, the bottom shelf's free slots as the
limit) on the scene with X at the push's predicted end. A run is "opened by one push" when one of them finds a
sequence. This bounds what choosing pushes by what follows them (a search over pushes and picks, not the closed
loop's cheapest push out of the proof's blocking cycle) could add on the grid: it tries no prep relocation before the
push. `--second`: after each feasible first push that opens nothing, every push of another object out of T's lanes,
then the proof again ("opened by two pushes").

    nice -n 10 .venv/bin/python scripts/bench_push_lookahead.py GRID.jsonl [--verbose] [--second]

(GRID: e.g. docs/bench/closed_loop_27scenes_k13_seeds100_651189f.jsonl)
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # this checkout's packages first

from bench_closed_loop import Patient, final_scene, retrieved  # scripts/ is sys.path[0]: the grid's own readers

from qtree_task_planner.executive.replan import GeometryCache, replan
from stpik_motion_planner.model.push import moved
from stpik_motion_planner.planning.planner import MotionPlanner


def one_push(row: dict, second: bool = False) -> tuple[str, list[str]]:
    """(the verdict on the run's final scene, one line per push tried): 'picks alone: ...' when a pick sequence
    exists there already, 'opened by one push: ...', 'no single push opens one (n feasible of m asked)', or why
    nothing was asked."""
    final = final_scene(row)
    if final is None:
        return "no final scene recorded", []
    sc, rp, base, m = final.scenario, final.problem, final.params, final.merged
    if rp.target_retrieved or rp.problem is None:
        return f"nothing to open: {rp.reason or 'the target is on the bottom shelf'}", []
    world = sc.with_objects(m.bottles.values())

    def proof(scenario) -> tuple[str, ...] | str:
        mp = MotionPlanner(scenario, dataclasses.replace(base))
        mp.set_scenario(mp.scenario, m.lying, m.gone)
        answer = replan(rp, (), GeometryCache(Patient(mp)))
        return answer if isinstance(answer, str) else tuple(answer[0])

    now = proof(world)
    if not isinstance(now, str):
        return f"picks alone: {' '.join(now)}", []
    mp = MotionPlanner(world, base)
    mp.set_scenario(mp.scenario, m.lying, m.gone)
    ids = [i for i in rp.problem.ids if i not in m.gone]
    lines, feasible, opened, twice = [], 0, [], []
    for x in ids:
        for c in ids:
            if x == c:
                continue
            answer, plan = mp.push_feasibility(x, c, [])
            if plan is None:
                lines.append(f"push {x} out of {c}'s lanes: refused: {answer.message}")
                continue
            feasible += 1
            pushed = moved(world, x, plan.end[0], plan.end[1])
            after = proof(pushed)
            lines.append(f"push {x} out of {c}'s lanes: {answer.message} -> "
                         f"{after if isinstance(after, str) else ' '.join(after)}")
            if not isinstance(after, str):
                opened.append(f"push {x} out of {c}'s lanes, then {' '.join(after)}")
            elif second:
                then = second_push(pushed, m, rp.problem.target, ids, base, proof)
                lines += [f"    then {line}" for line in then]
                twice += [f"push {x} out of {c}'s lanes, then {line}" for line in then if " -> opens: " in line]
    asked = len(ids) * (len(ids) - 1)
    if opened:
        return f"opened by one push: {opened[0]} ({len(opened)} of {feasible} feasible pushes, {asked} asked)", lines
    if twice:
        return f"opened by two pushes: {twice[0]} ({len(twice)} pairs)", lines
    return f"no single push opens one ({feasible} feasible of {asked} asked)" + (
        "; nor a second push out of T's lanes" if second else ""), lines


def second_push(world, m, target: str, ids: list[str], base, proof) -> list[str]:
    """After a first push (`world`, the pushed object at its predicted end): every push of another object out of
    the target's lanes, each feasible one followed by the pick proof; one line per feasible push."""
    mp = MotionPlanner(world, base)
    mp.set_scenario(mp.scenario, m.lying, m.gone)
    lines = []
    for x in ids:
        if x == target:
            continue
        answer, plan = mp.push_feasibility(x, target, [])
        if plan is None:
            continue
        after = proof(moved(world, x, plan.end[0], plan.end[1]))
        lines.append(f"push {x} out of {target}'s lanes: {answer.message} -> "
                     + (after if isinstance(after, str) else f"opens: {' '.join(after)}"))
    return lines


def main() -> None:
    """Print the verdict of every failed run of the grid file, then the count."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("grid", type=Path, help="a bench_closed_loop.py JSON-lines file")
    p.add_argument("--verbose", action="store_true", help="also every push tried")
    p.add_argument("--second", action="store_true",
                   help="after each feasible first push that opens nothing, also every push out of T's lanes")
    a = p.parse_args()
    runs = [json.loads(line) for line in a.grid.read_text().splitlines() if line.strip()]
    verdicts = []
    for r in runs:
        if retrieved(r):
            continue
        verdict, lines = one_push(r, a.second)
        verdicts.append(verdict)
        print(f"{r['scene']} K={r['k']} seed {r['seed']}: {verdict}", flush=True)
        for line in lines if a.verbose else ():
            print(f"    {line}", flush=True)
    n = sum(v.startswith("opened by one push") for v in verdicts)
    print(f"failed runs: {len(verdicts)}; opened by one push: {n}; by two: "
          f"{sum(v.startswith('opened by two') for v in verdicts)}; picks alone: "
          f"{sum(v.startswith('picks alone') for v in verdicts)}")


if __name__ == "__main__":
    main()
