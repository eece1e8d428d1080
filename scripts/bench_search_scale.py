#!/usr/bin/env python3
"""Scale benchmark of the blocker A* (qtree_task_planner.search.astar), the search itself, against the A* as it was
before its bounds (knowledge.py's forced objects and objects worth removing), side by side in one run.

1. Random layered relations (the `BlockingOracle` test double, its lane blockers known): n obstacles in LAYERS
   rows, each row behind the one in front: an object of row k > 0 is blocked by 1-2 objects of row k-1 (one lane),
   the target sits behind the last row. The optimum is the transitive closure of the target's blockers, checked.
   n = 5 .. 100, 5 instances each, seeds 0-4 (fixed before any result). Per instance: wall time, oracle calls, sets
   expanded, optimistic searches, new and old (old stopped after --old-timeout s).
2. The same relations with the lane blockers hidden (the A* learns them from its answers only, a claim then
   holding only at supersets of the set asked), and with 1-3 alternative lanes per object (`--families`): where
   the bounds are weaker. The new A* is stopped after --timeout s.
3. Every shipped scene without a `blocking:` section on the real motion planner (in-process): the planner calls of
   the new and the old A* over one shared answer cache (the same answers for both), and their optimum.

    .venv/bin/python scripts/bench_search_scale.py [--sizes 5 10 ...] [--instances 5] [--old-timeout 60]
        [--families layered answers alternatives] [--timeout 120] [--skip-scenes] [--plot docs/figures/astar_scale.png]
        [--replot SAVED_OUTPUT.txt --plot PNG]   (redraw a plot from the printed tables)

The baseline (`OldKnowledge`, `old_solve`) is the A* of the commit before the bounds, copied here as a benchmark
reference only; the product has one implementation, qtree_task_planner/search/astar.py.
"""
from __future__ import annotations

import argparse
import heapq
import itertools
import math
import platform
import random
import signal
import statistics
import sys
import time
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from qtree_task_planner.oracles import BlockingOracle, CachedOracle
from qtree_task_planner.problem import RelocationProblem
from qtree_task_planner.search import astar
from qtree_task_planner.search.exact import Claim, why_none
from relocation_common.feasibility import BlockerSet, FeasibilityAnswer, Label, Query, claims
from relocation_common.paths import scenarios_dir
from relocation_common.scenario import load_scenario

WEIGHTS = (0.05, 0.1, 0.25, 0.3, 0.5, 0.7, 1.0)
LAYERS = 5
SIZES = (5, 10, 15, 20, 30, 60, 100)


# ------------------------------------------------------------------------------------------------------ instances
def layered(seed: int, n: int, alternatives: bool = False) -> tuple[RelocationProblem, Any, set[str]]:
    """A random layered relation (module doc): the problem, its oracle and the target's closure (one lane per
    object; with `alternatives` 1-3 lanes, the closure then only an upper bound)."""
    rnd = random.Random(seed)
    obstacles = tuple(f"o{i}" for i in range(n))
    problem = RelocationProblem(obstacles, {o: rnd.choice(WEIGHTS) for o in obstacles}, "T")
    row = {o: rnd.randrange(LAYERS) for o in obstacles}
    rows = [[o for o in obstacles if row[o] == k] for k in range(LAYERS)] + [["T"]]
    row["T"] = LAYERS
    lanes: dict[str, list[frozenset[str]]] = {}
    for o in obstacles + ("T",):
        front = rows[row[o] - 1] if row[o] else []
        if front:
            count = rnd.randint(1, 3) if alternatives else 1
            lanes[o] = [frozenset(rnd.sample(front, min(len(front), rnd.randint(1, 2)))) for _ in range(count)]
    oracle = LaneRelation(lanes, "T", obstacles) if alternatives else \
        BlockingOracle.from_relation({o: ls[0] for o, ls in lanes.items()}, "T", obstacles + ("T",))
    closure: set[str] = set()
    todo = ["T"]
    while todo:  # the first lane of each object, transitively
        first = lanes.get(todo.pop(), [frozenset()])[0]
        todo.extend(first - closure)
        closure |= first
    return problem, oracle, closure


class LaneRelation:
    """A declared relation with alternative lanes (an object is free once every object of one lane is removed),
    answering as the BlockingOracle does: certain lane blockers in g_U answers and from lane_blockers."""

    def __init__(self, lanes: Mapping[str, list[frozenset[str]]], target: str, obstacles: Sequence[str]) -> None:
        self.lanes, self.target, self.ids = lanes, target, tuple(obstacles) + (target,)

    def feasibility(self, o: str, removed: frozenset[str]) -> FeasibilityAnswer:
        ls = self.lanes.get(o, [frozenset()])
        if any(b <= removed for b in ls):
            return FeasibilityAnswer(Label.TARGET if o == self.target else Label.OBSTACLE)
        return FeasibilityAnswer(Label.UNFEASIBLE, blockers=tuple(BlockerSet(b - removed) for b in ls))

    def lane_blockers(self, removed: frozenset[str]) -> dict[str, tuple[BlockerSet, ...]]:
        return {o: tuple(BlockerSet(b - removed) for b in self.lanes.get(o, [frozenset()]))
                for o in self.ids if o not in removed}


class AnswersOnly:
    """The oracle without lane_blockers: the A* learns blockers from its unfeasible answers only."""

    def __init__(self, oracle: Any) -> None:
        self.oracle = oracle

    def feasibility(self, object_id: str, removed: frozenset[str]) -> FeasibilityAnswer:
        return self.oracle.feasibility(object_id, removed)


# ------------------------------------------------------------------------- baseline: the A* before its bounds
class OldKnowledge:
    """The old astar.Knowledge: claims, answers and the depth-2 `need` heuristic (benchmark reference only)."""

    def __init__(self, weights: Mapping[str, float], target: str, depth: int = 2) -> None:
        self.weights, self.target, self.depth = weights, target, depth
        self.answers: dict[Query, bool] = {}
        self.claims: dict[str, list[Claim]] = {}
        self._h: dict[frozenset[str], float] = {}

    def claim(self, obj: str, removed: frozenset[str], blockers: Sequence[BlockerSet]) -> None:
        if claims(blockers):
            entry = (frozenset(removed), tuple(b.objects for b in blockers))
            if entry not in self.claims.setdefault(obj, []):
                self.claims[obj].append(entry)
                self._h.clear()

    def lanes_known(self, obj: str, removed: frozenset[str], lanes: tuple[BlockerSet, ...]) -> None:
        if lanes == ():
            self.claims.setdefault(obj, []).append((frozenset(removed), ()))
            self._h.clear()
        else:
            self.claim(obj, removed, lanes)

    def record(self, obj: str, removed: frozenset[str], answer: FeasibilityAnswer) -> bool:
        ok = Label(answer.label) != Label.UNFEASIBLE
        self.answers[(obj, removed)] = ok
        if not ok:
            self.claim(obj, removed, answer.blockers)
        return ok

    def possible(self, obj: str, removed: frozenset[str]) -> bool:
        if self.answers.get((obj, removed)) is False:
            return False
        return all(any(b <= removed for b in lanes) for s, lanes in self.claims.get(obj, ()) if s <= removed)

    def verified(self, obj: str, removed: frozenset[str]) -> bool:
        return self.answers.get((obj, removed)) is True

    def h(self, removed: frozenset[str]) -> float:
        got = self._h.get(removed)
        if got is None:
            got = self._h[removed] = self.need(self.target, removed, removed, frozenset(), self.depth)
        return got

    def need(self, obj: str, removed: frozenset[str], free: frozenset[str], chain: frozenset[str], depth: int) -> float:
        best = 0.0
        for s, lanes in self.claims.get(obj, ()):
            if not s <= removed:
                continue
            low = math.inf
            for b in lanes:
                if b & chain or obj in b:
                    continue
                rest = b - free
                v = math.fsum(self.weights.get(y, math.inf) for y in rest)
                if depth and rest and v < low:
                    v += max(self.need(y, removed, free | b, chain | {obj}, depth - 1) for y in rest)
                low = min(low, v)
            best = max(best, low)
        return best


def old_optimistic(obstacles: Sequence[str], phi: Mapping[str, float], target: str,
                   kb: OldKnowledge) -> tuple[list[Query] | None, int]:
    """The old A* on the optimistic graph: every obstacle branched on, ties to fewer unverified edges."""
    tie = itertools.count()
    start: frozenset[str] = frozenset()
    if math.isinf(kb.h(start)):
        return None, 0
    heap: list[Any] = [(kb.h(start), 0, 0, next(tie), start, None, None)]
    closed: dict[frozenset[str], tuple[Any, Any]] = {}
    while heap:
        f, unv, _, _, state, parent, obj = heapq.heappop(heap)
        if obj == target and parent is not None:
            path: list[Query] = [(target, parent)]
            grand, o = closed[parent]
            while grand is not None and o is not None:
                path.append((o, grand))
                grand, o = closed[grand]
            return path[::-1], len(closed)
        if state in closed:
            continue
        closed[state] = (parent, obj)
        g = math.fsum(phi[o] for o in state)
        if kb.possible(target, state):
            heapq.heappush(heap, (g, unv + (not kb.verified(target, state)), -len(state), next(tie), state, state,
                                  target))
        for o in obstacles:
            nxt = state | {o}
            if o in state or nxt in closed or not kb.possible(o, state):
                continue
            h = kb.h(nxt)
            if not math.isinf(h):
                heapq.heappush(heap, (g + phi[o] + h, unv + (not kb.verified(o, state)), -len(nxt), next(tie), nxt,
                                      state, o))
    return None, len(closed)


def old_solve(problem: RelocationProblem, oracle: Any) -> astar.AStarResult:
    """The old astar.solve (one question at a time; its replica batching left out: these oracles have none)."""
    kb = OldKnowledge(problem.weights, problem.target)
    for o, sets in (getattr(oracle, "lane_blockers", lambda r: None)(frozenset()) or {}).items():
        kb.lanes_known(o, frozenset(), tuple(sets))
    calls = searches = expanded = 0
    answers: dict[Query, FeasibilityAnswer] = {}
    while True:
        path, n = old_optimistic(problem.obstacles, problem.weights, problem.target, kb)
        searches, expanded = searches + 1, expanded + n
        if path is None:
            return astar.AStarResult(None, None, calls, expanded, why_none(problem.target, answers, kb.claims),
                                     blocker_calls=1, searches=searches)
        ok = True
        for o, s in path:  # the unasked edges in order, up to the first g_U
            if (o, s) not in kb.answers:
                answers[(o, s)] = a = oracle.feasibility(o, s)
                calls += 1
                if not kb.record(o, s, a):
                    ok = False
                    break
        if ok:
            seq = tuple(o for o, _ in path)
            return astar.AStarResult(seq, problem.weight(seq), calls, expanded, "", blocker_calls=1, searches=searches)


# ------------------------------------------------------------------------------------------------------ running
class TimeUp(Exception):
    """A solver ran past its time limit."""


def _alarm(signum: int, frame: Any) -> None:
    raise TimeUp()


def timed(solve: Callable[[RelocationProblem, Any], astar.AStarResult], problem: RelocationProblem, oracle: Any,
          limit: float) -> dict[str, Any]:
    """One solve behind a fresh set-keyed cache, stopped after `limit` s: time, calls, expanded, searches, weight."""
    cache = CachedOracle(oracle)
    signal.signal(signal.SIGALRM, _alarm)
    signal.setitimer(signal.ITIMER_REAL, limit)
    t0 = time.perf_counter()
    try:
        r = solve(problem, cache)
    except TimeUp:
        return {"s": None, "calls": cache.calls}
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
    return {"s": time.perf_counter() - t0, "calls": r.oracle_calls, "expanded": r.sets_settled,
            "searches": r.searches, "weight": r.total_weight}


def _ms(r: dict[str, Any], limit: float) -> str:
    return f"> {limit * 1e3:.0f}" if r["s"] is None else f"{r['s'] * 1e3:.3g}"


def family_table(family: str, sizes: Sequence[int], instances: int, limit_new: float, limit_old: float) -> list[dict]:
    """Rows of one family (module doc), printed as a Markdown table as they come."""
    print(f"\n### {family}\n")
    print("| n | seed | closure | optimum | new ms | new calls | new expanded | new searches | old ms | old calls | "
          "old expanded |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    rows = []
    for n in sizes:
        for seed in range(instances):
            problem, oracle, closure = layered(seed, n, alternatives=family == "alternatives")
            if family == "answers":
                oracle = AnswersOnly(oracle)
            new = timed(astar.solve, problem, oracle, limit_new)
            old = timed(old_solve, problem, oracle, limit_old)
            want = math.fsum(problem.weights[o] for o in closure)
            for r in (new, old):  # the closure is the optimum with one lane; with several an upper bound
                assert r["s"] is None or (r["weight"] <= want + 1e-9 if family == "alternatives"
                                          else abs(r["weight"] - want) < 1e-9), (family, n, seed, r, want)
            if new["s"] is not None and old["s"] is not None:
                assert abs(new["weight"] - old["weight"]) < 1e-9, (family, n, seed, new, old)
            rows.append({"family": family, "n": n, "seed": seed, "new": new, "old": old})
            opt = new["weight"] if new["s"] is not None else old.get("weight")
            print(f"| {n} | {seed} | {len(closure)} | {'?' if opt is None else f'{opt:.2f}'} | "
                  f"{_ms(new, limit_new)} | {new['calls']} | {new.get('expanded', '')} | {new.get('searches', '')} | "
                  f"{_ms(old, limit_old)} | {old['calls']} | {old.get('expanded', '')} |", flush=True)
    return rows


def summary(rows: list[dict], limit_new: float, limit_old: float) -> None:
    """Per family and n: the new search's median and largest time, calls and expansions; the old one's."""
    print("\n| family | n | new s median / max | new calls max | new expanded max | old finished | "
          "old s max (finished) |")
    print("|---|---|---|---|---|---|---|")
    for (family, n), group in itertools.groupby(rows, key=lambda r: (r["family"], r["n"])):
        g = list(group)
        done = [r["new"] for r in g if r["new"]["s"] is not None]
        old = [r["old"]["s"] for r in g if r["old"]["s"] is not None]
        new_s = f"{statistics.median(r['s'] for r in done):.4f} / {max(r['s'] for r in done):.4f}" if done else \
            f"> {limit_new:.0f}"
        print(f"| {family} | {n} | {new_s} ({len(done)}/{len(g)} done) | {max((r['calls'] for r in done), default='-')}"
              f" | {max((r['expanded'] for r in done), default='-')} | {len(old)}/{len(g)} | "
              f"{f'{max(old):.3f}' if old else f'> {limit_old:.0f}'} |")


def shipped_scenes() -> None:
    """Planner calls of the new and the old A* on every shipped scene, real planner, one answer cache shared."""
    from stpik_motion_planner.planning.planner import MotionPlanner, PlannerParams  # the planner only here
    root = scenarios_dir()
    params = PlannerParams.load()
    print("\n### Shipped scenes, real motion planner\n")
    print("| scene | obstacles | new calls | old calls | new expanded | old expanded | weight (new / old) | "
          "same sequence |")
    print("|---|---|---|---|---|---|---|---|")
    for path in sorted(root.rglob("*.yaml")):
        sc = load_scenario(path)
        if sc.blocking is not None:
            continue
        truth = CachedOracle(MotionPlanner(sc, params))
        problem = RelocationProblem.from_scenario(sc)
        got = []
        for solve in (astar.solve, old_solve):
            cache = CachedOracle(truth)
            got.append((solve(problem, cache), cache.calls))
        (new, nc), (old, oc) = got
        w = " / ".join("none" if r.total_weight is None else f"{r.total_weight:.2f}" for r in (new, old))
        print(f"| {path.relative_to(root).with_suffix('')} | {problem.n} | {nc} | {oc} | {new.sets_settled} | "
              f"{old.sets_settled} | {w} | {'yes' if new.sequence == old.sequence else 'no'} |", flush=True)


def parse_rows(text: str) -> list[dict]:
    """The per-instance rows back from this script's printed tables (so a pasted output redraws its plot)."""
    rows, family = [], ""
    for line in text.splitlines():
        if line.startswith("### "):
            family = line[4:].strip()
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if family in ("layered", "answers", "alternatives") and len(cells) == 11 and cells[0].isdigit():
            def run(s: str, calls: str, expanded: str) -> dict[str, Any]:
                return {"s": None if s.startswith(">") else float(s) / 1e3, "calls": int(calls),
                        "expanded": int(expanded) if expanded else None}
            rows.append({"family": family, "n": int(cells[0]), "seed": int(cells[1]),
                         "new": run(cells[4], cells[5], cells[6]), "old": run(cells[8], cells[9], cells[10])})
    return rows


def plot(rows: list[dict], out: Path, limits: dict[str, float]) -> None:
    """Time, oracle calls and sets expanded against n, new (left of n) and old (right of n), one point per instance,
    the medians joined by a line where every instance finished."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fams = sorted({r["family"] for r in rows}, key=["layered", "answers", "alternatives"].index)
    fig, axes = plt.subplots(3, len(fams), figsize=(5.5 * len(fams), 10), squeeze=False)
    for col, fam in enumerate(fams):
        g = [r for r in rows if r["family"] == fam]
        sizes = sorted({r["n"] for r in g})
        for which, colour, dx in (("new", "tab:blue", -0.012), ("old", "tab:red", 0.012)):
            for ax, key in zip(axes[:, col], ("s", "calls", "expanded")):
                done = [r for r in g if r[which]["s"] is not None]
                ax.scatter([r["n"] * (1 + dx) for r in done], [r[which][key] for r in done], c=colour, s=14,
                           label=f"{which} A*")
                med = [(n, statistics.median(r[which][key] for r in done if r["n"] == n)) for n in sizes
                       if all(r[which]["s"] is not None for r in g if r["n"] == n)]  # where all finished
                ax.plot([n for n, _ in med], [m for _, m in med], c=colour, lw=1, alpha=0.6)
                late = [r for r in g if r[which]["s"] is None]
                if late and key == "s":
                    ax.scatter([r["n"] * (1 + dx) for r in late], [limits[which]] * len(late), c=colour,
                               marker="^", s=36, label=f"{which}: stopped at {limits[which]:.0f} s")
        for ax, what in zip(axes[:, col], ("wall time (s)", "oracle calls", "sets expanded")):
            ax.set(title=f"{fam}: {what}", xlabel="obstacles n", xscale="log", yscale="log")
            ax.set_xticks(sizes, [str(n) for n in sizes])
            ax.grid(alpha=0.3)
            ax.legend(fontsize=7)
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=100)
    print(f"\nplot: {out}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=list(SIZES))
    ap.add_argument("--instances", type=int, default=5)
    ap.add_argument("--families", nargs="+", default=["layered"], choices=["layered", "answers", "alternatives"])
    ap.add_argument("--timeout", type=float, default=120.0, help="s before the new A* is stopped")
    ap.add_argument("--old-timeout", type=float, default=60.0, help="s before the old A* is stopped")
    ap.add_argument("--skip-scenes", action="store_true")
    ap.add_argument("--plot", type=Path)
    ap.add_argument("--replot", type=Path, help="redraw --plot from a saved output of this script, run nothing")
    args = ap.parse_args()
    if args.replot:
        plot(parse_rows(args.replot.read_text()), args.plot, {"new": args.timeout, "old": args.old_timeout})
        return
    print(f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, {platform.python_implementation()} "
          f"{platform.python_version()}, load average {' '.join(f'{x:.2f}' for x in __import__('os').getloadavg())}")
    rows: list[dict] = []
    for fam in args.families:
        rows += family_table(fam, args.sizes, args.instances, args.timeout, args.old_timeout)
    summary(rows, args.timeout, args.old_timeout)
    if args.plot:
        plot(rows, args.plot, {"new": args.timeout, "old": args.old_timeout})
    if not args.skip_scenes:
        shipped_scenes()


if __name__ == "__main__":
    main()
