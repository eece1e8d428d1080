"""Search for scenes of the paper's structure (Sect. 5.1) with the real motion planner
(docs/evaluation.md, "Complete trees").

The paper's scenarios 1-3 have complete Q-Trees (complete_tree.py) of 84 / about 622 / about 1,675 edges (their
LRND MP_q) with 10 / 20 / 20 target leaves and one optimum. A candidate is a cluttered layout on the shelf of
paper_experiment_10 (`clutter_scene`: the target in the back row, obstacles on a tight staggered lattice in front
of and beside it); its feasibility table is filled with the real planner (stopped early once the tree is too big:
the fill's questions are at most the tree's edges), then its complete tree is counted. Weights are drawn last
until exactly one target leaf has the least total weight (Eq. 8). `visible` checks that perception locates every
bottle in the camera's first frame (arm at home).
"""
from __future__ import annotations

import math
import random
from dataclasses import dataclass

from relocation_app.evaluation.scenes import complete_tree
from relocation_app.evaluation.scenes.scenarios_gen import MAX_REACH, RADIUS, scene_data
from relocation_common.scenario import parse_scenario

PAPER_TREES = {5: (84, 10), 10: (622, 20), 15: (1675, 20)}  # obstacles -> (complete-tree edges, target leaves)
WITHIN = 2.0  # accepted factor on the edges (docs/evaluation.md, "Complete trees")


@dataclass
class Candidate:
    """A scene drawn by the search, with its complete-tree size and the checks it passed."""

    data: dict
    size: complete_tree.TreeSize | None  # None: the fill stopped, the tree is larger than the cap
    queries: int
    seconds: float
    table: object = None  # its FeasibilityTable (real planner answers)
    weighted: dict | None = None  # the data with weights that give one optimum (None: no draw does)
    valid: bool | None = None  # strict search: one optimum and every bottle visible (None: not checked)

    def score(self, goal: tuple[int, int]) -> float:
        """0 is a perfect match: |log edge ratio| + |log leaf ratio| (inf when too big or no target leaf)."""
        if self.size is None or self.size.target_leaves == 0:
            return math.inf
        return abs(math.log(self.size.edges / goal[0])) + abs(math.log(self.size.target_leaves / goal[1]))

    def ok(self, goal: tuple[int, int], leaves_tol: float = 0.0) -> bool:
        """True when edges are within WITHIN x the goal's, target leaves within tolerance, one optimum."""
        s = self.size
        return (s is not None and goal[0] / WITHIN <= s.edges <= goal[0] * WITHIN
                and abs(s.target_leaves - goal[1]) <= leaves_tol * goal[1] and self.weighted is not None)


def clutter_scene(seed: int, n: int, name: str) -> dict:
    """n obstacles on a tight staggered lattice (row pitch dx, lateral pitch dy, both drawn per seed) around a
    back-row target: the n lattice points nearest to the target's approach fan, jittered."""
    rng = random.Random(seed)
    dx, dy = rng.uniform(0.07, 0.11), rng.uniform(0.085, 0.14)
    tx, ty = rng.uniform(0.88, 0.91), rng.uniform(-0.08, 0.08)
    rows = [tx - k * dx for k in range(0, 4) if tx - k * dx >= 0.62 + 0.04]
    pts = []
    for k, x in enumerate(rows):
        off = (k % 2) * dy / 2
        for j in range(-6, 7):
            y = ty + off + j * dy
            if (k, j) != (0, 0) and abs(y) <= 0.34 and math.hypot(x, y) <= MAX_REACH:
                pts.append((x, y))
    lateral = rng.uniform(1.0, 4.0)  # >1 prefers points in front over points beside
    pts.sort(key=lambda p: math.hypot((tx - p[0]), lateral * (p[1] - ty)) + rng.uniform(0.0, 0.06))
    chosen = pts[:n]
    jit = 0.006
    chosen = [(x + rng.uniform(-jit, jit), y + rng.uniform(-jit, jit)) for x, y in chosen]
    return scene_data(rng, seed, name, (tx, ty), chosen)


def evaluate(data: dict, params, directory, goal: tuple[int, int]) -> Candidate:
    """Fill the candidate's table with the real planner up to WITHIN x the goal's edges, count its tree."""
    import copy
    import time

    from relocation_app.evaluation.feasibility_cache import fill_reachable, open_table
    sc = parse_scenario(data, data["name"])
    table, path = open_table(sc, params, directory)
    cap = int(goal[0] * WITHIN) + 1
    t0 = time.perf_counter()
    st = fill_reachable(sc, params, table, workers=1, progress=False, save_to=None, max_queries=cap)
    size = None
    if st["real_calls"] < cap or _complete(table, sc):
        size = complete_tree.of_table(table, sc)
    weighted = one_optimum(copy.deepcopy(data), table, 30) if size is not None and size.target_leaves else None
    return Candidate(data, size, st["real_calls"], time.perf_counter() - t0, table, weighted)


def _complete(table, sc) -> bool:
    try:
        complete_tree.of_table(table, sc)
        return True
    except ValueError:
        return False


def one_optimum(data: dict, table, tries: int = 200, seed: int = 0) -> dict | None:
    """Redraw the obstacles' weights (from `seed`) until one target leaf has the least total weight; None if no
    draw does (the cheapest set has several feasible orders)."""
    rng = random.Random(seed)
    for _ in range(tries):
        for o in data["objects"]:
            if o["id"] != data["target"]:
                o["weight"] = round(rng.uniform(0.05, 0.95), 2)
        sc = parse_scenario(data, data["name"])
        if complete_tree.of_table(table, sc).optimal_leaves == 1:
            return data
    return None


def visible(data: dict) -> list[str]:
    """Bottles perception cannot locate in the first camera frame (arm at home): [] when all are visible."""
    from jaco2_sim_driver.camera import render_frame
    from perception_aruco.pipeline import Perception
    sc = parse_scenario(data, data["name"])
    f = render_frame(sc)
    return sorted(Perception(sc).process(f.rgb, f.depth, f.K).missing)


def perturb(data: dict, rng: random.Random, step: float = 0.015) -> dict | None:
    """A copy of `data` with one bottle (the target too) moved by a normal step; None if the layout is invalid
    (overlap, off the shelf, out of reach)."""
    import copy

    from relocation_common.scenario import ScenarioError
    d = copy.deepcopy(data)
    o = rng.choice(d["objects"])
    x, y = o["xy"]
    u = rng.random()
    if u < 0.15:  # a jump anywhere on the front part of the shelf
        o["xy"] = [round(rng.uniform(0.655, 0.93), 3), round(rng.uniform(-0.33, 0.33), 3)]
    else:
        s = step if u < 0.8 else 3 * step
        o["xy"] = [round(x + rng.gauss(0.0, s), 3), round(y + rng.gauss(0.0, s), 3)]
    if math.hypot(*o["xy"]) > MAX_REACH:
        return None
    try:
        parse_scenario(d, d["name"])
    except ScenarioError:
        return None
    return d


def score(c: Candidate, goal: tuple[int, int]) -> float:
    """Search objective (0: exact match): the leaf count first, edges only outside the WITHIN window (steeply: a
    tree within WITHIN x of the paper's edges beats a closer leaf count outside it) and a little inside it."""
    if c.size is None or c.size.target_leaves == 0:
        return math.inf
    e = abs(math.log(c.size.edges / goal[0]))
    return (2 * abs(math.log(c.size.target_leaves / goal[1])) + 6 * max(0.0, e - math.log(WITHIN)) + 0.1 * e
            + (0.0 if c.weighted is not None else 0.5))


def proposal(seed: int, n: int, name: str, goal: tuple[int, int], params, slack: float = 0.5,
              base: dict | None = None, radius: float = RADIUS) -> dict | None:
    """free_scene(seed, radius), or `base` extended to n obstacles (odd seeds, when given), if its screened tree is near
    the goal (leaves within `slack`, edges within WITHIN^2 x), else None: the real planner is asked only about
    promising layouts."""
    try:
        d = extend_scene(base, seed, n, name) if base is not None and seed % 2 else free_scene(seed, n, name, radius)
    except RuntimeError:
        return None
    if d is None:
        return None
    s = screen_size(d, params)
    near = (goal[0] / WITHIN ** 2 <= s.edges <= goal[0] * WITHIN ** 2
            and abs(s.target_leaves - goal[1]) <= slack * goal[1])
    return d if near else None


def search(n: int, name: str, params, directory, seeds, steps: int, log=print, deadline: float = math.inf,
           base: dict | None = None, start: dict | None = None, strict: bool = False, climb_seed: int | None = None,
           temperature: float = 0.0, on_best=None, radius: float = RADIUS):
    """Random clutter candidates (`seeds`), then `steps` of hill climbing (perturb, keep if not worse) from the
    best; candidates that match the goal (edges within WITHIN x, leaves exact) are checked for visibility and
    one optimum. `strict`: the climb keeps only valid scenes (weights with one optimum, every bottle visible,
    the optimum executable: `valid`); a start that is not valid is left for the first valid step within
    INVALID_SLACK of its score. `temperature` > 0: a worse step is also kept with probability
    exp(-(score increase) / temperature) (simulated annealing; one bottle at a time cannot otherwise leave a
    local optimum), the best scene seen is returned. `on_best(candidate)` is called on each new best. `radius`:
    of the proposals' bottles (a `base` of another radius is not extended).
    Returns (best candidate, its weights-fixed data or None, missing bottles); with `strict` the candidate is
    valid unless no valid scene was reached (then `best.valid` is False)."""
    import time
    goal = PAPER_TREES[n]
    if base is not None and base.get("defaults", {}).get("radius", RADIUS) != radius:
        base = None
    best, best_s = None, math.inf
    if start is not None:  # resume the climb from a scene found before
        best = evaluate(start, params, directory, goal)
        best_s = score(best, goal)
        if strict:
            best.valid = valid(best, params, log)
            if not best.valid:
                best_s += INVALID_SLACK
        log(f"start: {describe(best)} score {best_s:.2f}{'' if not strict or best.valid else ' (not valid)'}")
        seeds = ()
    climb_from = time.time() + 0.5 * (deadline - time.time())  # half the time for proposals, half for the climb
    for seed in seeds:
        d = proposal(seed, n, name, goal, params, base=base, radius=radius)
        if d is None:
            continue
        c = evaluate(d, params, directory, goal)
        if score(c, goal) < best_s:
            best, best_s = c, score(c, goal)
            log(f"seed {seed}: {describe(c)} score {best_s:.2f}")
        if time.time() > climb_from or (best is not None and best.ok(goal)):
            break
    rng = random.Random(n if climb_seed is None else climb_seed)
    tried_visible = set()
    cur, cur_s = best, best_s  # the climb's state (= best unless annealing kept a worse step)
    for k in range(steps):
        if best is not None and best.ok(goal) and id(best) not in tried_visible:
            tried_visible.add(id(best))
            done = _finish(best, params, directory, log)
            if done is not None:
                return best, done, []
            best_s += 0.5  # invisible or no single optimum: let the climb move on
            cur_s = min(cur_s, best_s)
        if time.time() > deadline or cur is None:
            break
        d = perturb(cur.data, rng)
        slack = 0.5 + 4 * temperature
        if d is None or score(Candidate(d, screen_size(d, params), 0, 0.0, None, {}), goal) > cur_s + slack:
            continue  # the lane screen says it is far off: no planner calls
        c = evaluate(d, params, directory, goal)
        s = score(c, goal)
        keep = s <= cur_s or (temperature > 0 and math.isfinite(s)
                              and rng.random() < math.exp(-(s - cur_s) / temperature))
        if keep and strict:
            c.valid = valid(c, params, log)
            keep = c.valid
        if not keep:
            continue
        if s < cur_s - 1e-9 or s > cur_s + 1e-9:
            log(f"step {k}: {describe(c)} score {s:.2f}" + (" (best)" if s < best_s else ""))
        cur, cur_s = c, s
        if s <= best_s:
            best, best_s = c, s
            if on_best is not None:
                on_best(c)
    return best, None, None


INVALID_SLACK = 1.0  # strict climb: how much worse than a start that is not valid its first valid step may be


def valid(c: Candidate, params=None, log=None) -> bool:
    """A scene the evaluation can ship: weights with one optimum (Eq. 8), every bottle seen by perception and
    (with `params`) the optimum executable (`optimum_plans`)."""
    if c.weighted is None or visible(c.weighted):
        return False
    if params is None:
        return True
    err = optimum_plans(c.weighted, c.table, params)
    if err and log is not None:
        log(f"  valid but the optimum cannot be carried out: {err}")
    return not err


def optimum_sequence(data: dict, table, params) -> tuple[str, ...]:
    """The exact optimum (qtree_task_planner.search.exact.solve) from a filled table: obstacles then the target."""
    from qtree_task_planner.search.exact import solve
    from relocation_app.evaluation.feasibility_cache import PlannerOracle
    sc = parse_scenario(data, data["name"])
    seq = solve(sc, PlannerOracle(sc, params, table)).sequence
    if seq is None:
        raise ValueError(f"{data['name']}: no relocation sequence frees the target in this table")
    return tuple(seq)


def optimum_plans(data: dict, table, params, repeats: int = 6) -> str:
    """'' if every relocation of the optimum can be planned `repeats` times in a row (`replans`) by the
    evaluation's planner for this scene, else what failed."""
    from relocation_app.evaluation.feasibility_cache import worker_planner
    sc = parse_scenario(data, data["name"])
    seq = optimum_sequence(data, table, params)
    return replans(worker_planner(sc, params), seq, repeats)


def replans(planner, sequence, repeats: int) -> str:
    """'' if `planner` plans every relocation of `sequence` (pick, carry, retreat, home:
    relocation.plan_relocation) `repeats` times in a row, else what failed. OMPL's random stream is per process
    (stpik_motion_planner/planning/rrt.py), so a plan depends on the queries before it; planning each relocation again
    from other stream states rejects the borderline ones (a feasible pick that the execution then cannot plan):
    twice was not enough, paper2_10's first T failed its pick in 5 of 12 plannings."""
    from stpik_motion_planner.execution.relocation import plan_relocation
    from stpik_motion_planner.planning.results import PlanningError
    for r in range(repeats):
        for k, oid in enumerate(sequence):
            try:
                plan_relocation(planner, oid, list(sequence[:k]))
            except PlanningError as e:
                return f"{'-'.join(sequence)} (planning {r + 1} of {repeats}): {e}"
    return ""


def describe(c: Candidate) -> str:
    """One line on a candidate scene for the search log: its tree's size and what it cost."""
    return ("too big" if c.size is None else f"{c.size.edges} edges, {c.size.target_leaves} target leaves") + \
        f" ({c.queries} planner calls, {c.seconds:.1f} s)"


def _finish(c: Candidate, params, directory, log) -> dict | None:
    """Weights for one optimum, then the camera check; the data on success, None otherwise."""
    d = c.weighted
    if d is None:  # no weights give one optimum (Candidate.ok asks for them)
        return None
    missing = visible(d)
    if missing:
        log(f"  match, but not visible: {missing}")
        return None
    log("  match: one optimum, every bottle visible")
    return d


# ------------------------------------------------------------------------------------------------ screen
# The proposal filter is the planner's own grasp-lane screen (stpik_motion_planner.model.blockers;
# docs/motion_planner.md,
# "Blockers"): per bottle and approach yaw, the bottles the hand meets on that lane with every bottle present; an object
# passes the screen once all blockers of one of its lanes are removed. STPIK and RRT-Connect can still fail after the
# screen, so every scene kept is judged by the real planner.
_SCREEN: dict = {}


def screen_size(data: dict, params) -> complete_tree.TreeSize:
    """Complete tree of a scene mapping under the lane screen (OR over lanes of AND over their blockers)."""
    from relocation_common.feasibility import Label
    from stpik_motion_planner.model.blockers import lane_blockers
    from stpik_motion_planner.planning.planner import MotionPlanner
    sc = parse_scenario(data, data["name"])
    mp = _SCREEN.get("mp")
    if mp is None or mp.scenario.shelf != sc.shelf:
        mp = _SCREEN["mp"] = MotionPlanner(sc, params)
    else:
        mp.set_scenario(sc)
    lanes = {o: [frozenset(b.objects) for b in sets] for o, sets in lane_blockers(mp).items()}

    def label_of(o, s):
        if not any(bl <= s for bl in lanes[o]):
            return Label.UNFEASIBLE
        return Label.TARGET if o == sc.target_id else Label.OBSTACLE
    return complete_tree.complete_tree(sc.obstacle_ids, sc.target_id, label_of)


def free_scene(seed: int, n: int, name: str, radius: float = RADIUS) -> dict:
    """n obstacles of `radius` at random non-overlapping spots in front of and beside a back-row target (no
    lattice), possibly behind a column straight in front of the target: a removal chain of as many bottles as
    the shelf's depth holds (3 of radius 0.033, 4 of 0.025)."""
    rng = random.Random(seed)
    tx, ty = rng.uniform(0.87, 0.91), rng.uniform(-0.1, 0.1)
    spread = rng.uniform(min(0.12 + 0.012 * (n - 5), 0.28), 0.33)  # room for n bottles
    pts: list[tuple[float, float]] = [(tx, ty)]
    pitch = (2 * radius + 0.006, 2 * radius + 0.019)
    for k in range(rng.randint(0, int((0.89 - 0.655) / pitch[0]))):  # the column in front of the target
        pts.append((round(pts[-1][0] - rng.uniform(*pitch), 3), round(ty + rng.uniform(-0.01, 0.01), 3)))
    if pts[-1][0] < 0.655:
        pts.pop()
    for _ in range(20000):
        if len(pts) == n + 1:
            break
        x, y = rng.uniform(0.655, tx + 0.02), ty + rng.uniform(-spread, spread)
        if abs(y) > 0.33 or math.hypot(x, y) > MAX_REACH:
            continue
        if all(math.hypot(x - a, y - b) >= 2 * radius + 0.002 for a, b in pts):
            pts.append((round(x, 3), round(y, 3)))
    if len(pts) < n + 1:
        raise RuntimeError(f"seed {seed}: cannot place {n} obstacles")
    return scene_data(rng, seed, name, pts[0], pts[1:], radius)


def extend_scene(base: dict, seed: int, n: int, name: str) -> dict | None:
    """`base` (a smaller scene whose tree has the paper's shape) with obstacles added at random free spots up to
    n: blocked ones add edges to every node, removable ones add nodes. None if they do not fit."""
    import copy
    rng = random.Random(seed)
    d = copy.deepcopy(base)
    d["name"] = name
    pts = [tuple(o["xy"]) for o in d["objects"]]
    gap = 2 * d.get("defaults", {}).get("radius", RADIUS) + 0.002
    k = sum(1 for o in d["objects"] if o["id"] != d["target"])
    for _ in range(20000):
        if k == n:
            break
        x, y = round(rng.uniform(0.655, 0.93), 3), round(rng.uniform(-0.33, 0.33), 3)
        if math.hypot(x, y) <= MAX_REACH and all(math.hypot(x - a, y - b) >= gap for a, b in pts):
            k += 1
            pts.append((x, y))
            d["objects"].insert(-1, {"id": f"o{k}", "weight": round(rng.uniform(0.05, 0.95), 2), "xy": [x, y]})
    if k < n:
        return None
    d["slots"] = "auto" if n + 1 > 12 else d["slots"]
    return d
