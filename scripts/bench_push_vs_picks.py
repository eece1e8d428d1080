"""Would a push ever beat the picks where a pick sequence exists? For each scene: the picks' proven optimum (the A*
with the action costs, in process) and, for each object X in the target's lanes whose push alone costs less
(weight x the push factor), the push of X out of T's lanes with nothing removed and the picks' optimum after it on
the scene with X at its predicted end (MotionPlanner.what_if). Prints one block per scene and a summary line:
the scenes where a push followed by picks costs less than the picks alone.

    python scripts/bench_push_vs_picks.py config/scenarios/*.yaml config/scenarios/random5/*.yaml
"""
from __future__ import annotations

import argparse
import sys

from qtree_task_planner.problem import ActionCosts, RelocationProblem
from qtree_task_planner.search import astar
from relocation_common.scenario import load_scenario
from stpik_motion_planner.planning.params import PlannerParams
from stpik_motion_planner.planning.planner import MotionPlanner


def one(path: str, costs: ActionCosts) -> tuple[str, list[str]]:
    """('none' | 'picks' | 'push cheaper', lines) for the scene at `path`."""
    sc = load_scenario(path)
    mp = MotionPlanner(sc, PlannerParams.load())
    problem = RelocationProblem.from_scenario(sc, costs)
    picks = astar.solve(problem, mp)
    if picks.sequence is None:
        return "none", [f"{sc.name}: no pick sequence ({picks.reason[:80]})"]
    best = problem.cost(picks.sequence)
    lines = [f"{sc.name}: picks {' '.join(picks.sequence)} cost {best:.2f}"]
    t = sc.target_id
    blockers = sorted(set().union(*(b.objects for b in mp.lane_blockers([]).get(t, ()))))
    verdict = "picks"
    for x in blockers:
        push = problem.weights[x] * costs.push
        if push >= best:
            lines.append(f"  push {x} ({push:.2f}): not asked, costs no less than the picks")
            continue
        answer, plan = mp.push_feasibility(x, t, [])
        if plan is None:
            lines.append(f"  push {x} ({push:.2f}): refused: {answer.message[:100]}")
            continue
        after = astar.solve(problem, mp.what_if({x: plan.end[:2]}))
        if after.sequence is None:
            lines.append(f"  push {x} ({push:.2f}): feasible, no pick sequence after it")
            continue
        total = push + problem.cost(after.sequence)
        lines.append(f"  push {x} ({push:.2f}), then {' '.join(after.sequence)}: {total:.2f}")
        if total < best - 1e-9:
            verdict = "push cheaper"
    return verdict, lines


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scenes", nargs="+")
    a = p.parse_args()
    costs = ActionCosts.from_yaml()
    counts: dict[str, int] = {}
    for path in a.scenes:
        verdict, lines = one(path, costs)
        counts[verdict] = counts.get(verdict, 0) + 1
        print("\n".join(lines), flush=True)
    print(f"scenes: {len(a.scenes)}; no pick sequence: {counts.get('none', 0)}; picks cheapest: "
          f"{counts.get('picks', 0)}; a push then picks cheaper: {counts.get('push cheaper', 0)}")
    sys.exit(0)


if __name__ == "__main__":
    main()
