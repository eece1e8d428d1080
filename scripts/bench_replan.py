"""Benchmark of re-planning with the geometry-keyed cache (qtree_task_planner.executive.replan) on the real motion
planner.

For every shipped scene, with the motion planner core in-process (no ROS) as the oracle:
1. cold: the exact optimum of the whole scene (the blocker A* over a fresh GeometryCache): planner calls, seconds;
2. after the first relocation of that optimum, done as planned: the re-plan's planner calls with the cache kept
   and with a fresh one (what a set-keyed cache that must be dropped on any change would cost);
3. one at a time, every other obstacle that has room nudged by 2 cm sideways (the planner's scene updated as the
   motion planner node does from perception): the re-plan's calls with the cache kept and fresh, how often the
   optimum changed, and whether both gave the same weight (they must: the cache keeps only answers whose
   geometry did not change).

    .venv/bin/python scripts/bench_replan.py [--scenes name ...] [--push 0.02]
"""
from __future__ import annotations

import argparse
import copy
import math
import statistics
import time

from qtree_task_planner.executive.replan import GeometryCache, replan
from qtree_task_planner.executive.world import SeenObject, remaining_problem, scene_from_scenario
from relocation_common.paths import scenarios_dir
from relocation_common.scenario import load_scenario
from stpik_motion_planner.planning.params import PlannerParams
from stpik_motion_planner.planning.planner import MotionPlanner


def shipped_scenes() -> list[str]:
    root = scenarios_dir()
    names = [p.stem for p in sorted(root.glob("*.yaml")) if load_scenario(p).blocking is None]
    return names + [f"random5/{p.stem}" for p in sorted((root / "random5").glob("*.yaml"))]


class Patient:
    """The motion planner with a long wall-clock safety net (its work budget decides the answer; a loaded
    machine must not turn into a missing answer)."""

    def __init__(self, mp: MotionPlanner) -> None:
        self.mp = mp

    def feasibility(self, object_id, removed):
        return self.mp.feasibility(object_id, removed, timeout=120.0)

    def lane_blockers(self, removed):
        return self.mp.lane_blockers(removed)


def fork(cache: GeometryCache) -> GeometryCache:
    """An independent copy of the cache's knowledge over the same oracle."""
    oracle, cache.oracle = cache.oracle, None
    try:
        twin = copy.deepcopy(cache)
    finally:
        cache.oracle = oracle
    twin.oracle, twin.calls, twin.hits = oracle, 0, 0
    return twin


def room(scene: dict, oid: str, x: float, y: float, sc) -> bool:
    o, sh = scene[oid], sc.shelf
    if not (sh.x_front + o.radius <= x <= sh.x_back - o.radius and sh.y_min + o.radius <= y <= sh.y_max - o.radius):
        return False
    return all(math.hypot(p.x - x, p.y - y) >= p.radius + o.radius + 0.003 for k, p in scene.items()
               if k != oid and abs(p.z - o.z) < 0.05)


def bench(name: str, push: float) -> dict:
    sc = load_scenario(name)
    mp = MotionPlanner(sc, PlannerParams.load())
    oracle = Patient(mp)
    cache = GeometryCache(oracle)
    scene = scene_from_scenario(sc)
    t0 = time.perf_counter()
    first = replan(remaining_problem(sc, scene, ()), (), cache)
    cold_s = time.perf_counter() - t0
    if isinstance(first, str):
        return {"scene": name, "error": first}
    seq, weight, cold = first
    moved = seq[0]
    x, y = sc.slots[0]
    scene = dict(scene, **{moved: SeenObject(moved, x, y, sc.shelf.bottom_z, sc.object(moved).weight)})
    rp = remaining_problem(sc, scene, [moved])
    kept, fresh = fork(cache), GeometryCache(oracle)
    a, b = replan(rp, (), kept), replan(rp, (), fresh)
    assert not isinstance(a, str) and not isinstance(b, str) and a[1] == b[1], (a, b)
    after = (kept.calls, fresh.calls)
    nudges = []
    for oid in rp.problem.obstacles:
        o = scene[oid]
        spot = next(((o.x, o.y + d) for d in (push, -push) if room(scene, oid, o.x, o.y + d, sc)), None)
        if spot is None:
            continue
        mp.update_object(oid, *spot)
        nudged = dict(scene, **{oid: SeenObject(oid, *spot, o.z, o.weight, o.is_target)})
        rp2 = remaining_problem(sc, nudged, [moved])
        kept2, fresh2 = fork(cache), GeometryCache(oracle)
        a2, b2 = replan(rp2, (), kept2), replan(rp2, (), fresh2)
        mp.update_object(oid, o.x, o.y)
        same = (a2 == b2) if isinstance(a2, str) else (not isinstance(b2, str) and abs(a2[1] - b2[1]) < 1e-9)
        changed = isinstance(a2, str) or tuple(a2[0]) != tuple(a[0])
        nudges.append((kept2.calls, fresh2.calls, changed, same))
    return {"scene": name, "sequence": " ".join(seq), "weight": round(weight, 2), "cold": cold,
            "cold_s": cold_s, "after": after, "nudges": nudges}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", nargs="*", default=None)
    ap.add_argument("--push", type=float, default=0.02, help="m, sideways")
    args = ap.parse_args()
    print("| scene | optimum | cold calls | cold s | after relocation 1: calls kept / fresh | nudges | "
          "re-plan calls kept / fresh (mean) | optimum changed | same weight |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name in args.scenes or shipped_scenes():
        r = bench(name, args.push)
        if "error" in r:
            print(f"| {name} | {r['error']} | | | | | | | |")
            continue
        n = r["nudges"]
        mean = (f"{statistics.mean(k for k, *_ in n):.1f} / {statistics.mean(f for _, f, *_ in n):.1f}"
                if n else "-")
        print(f"| {name} | {r['sequence']} ({r['weight']}) | {r['cold']} | {r['cold_s']:.2f} | "
              f"{r['after'][0]} / {r['after'][1]} | {len(n)} | {mean} | {sum(c for *_, c, _ in n)} | "
              f"{sum(s for *_, s in n)}/{len(n)} |", flush=True)


if __name__ == "__main__":
    main()
