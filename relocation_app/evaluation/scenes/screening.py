"""How the scene makers judge a drawn layout before keeping it (docs/evaluation.md, "Complete trees").

First the planner's own grasp-lane screen, no planner run (`screen_size`; stpik_motion_planner.model.blockers,
docs/motion_planner.md "Blockers"): per bottle and approach yaw, the bottles the hand meets on that lane with every
bottle present; an object passes once all blockers of one of its lanes are removed. `proposal` keeps the layouts
whose screened tree is near the goal. STPIK and RRT-Connect can still fail after the screen, so a kept layout is
judged by the real planner: its feasibility table filled (`fill`; `evaluate` stops once the tree is too big, the
fill's questions being at most the tree's edges) and its complete tree counted (complete_tree.py). Weights are
drawn last until exactly one target leaf has the least total weight (`one_optimum`, Eq. 8); `valid` adds that
perception locates every bottle in the camera's first frame (`visible`) and that the optimum is planned again
(`optimum_plans`). `ship` writes the kept scene with its table.
"""
from __future__ import annotations

import random
from dataclasses import dataclass
from pathlib import Path

from relocation_app.evaluation.scenes import complete_tree
from relocation_app.evaluation.scenes.layout import RADIUS, extend_scene, free_scene, write_scene
from relocation_common.scenario import parse_scenario

WITHIN = 2.0  # accepted factor on the edges (docs/evaluation.md, "Complete trees")


@dataclass
class Candidate:
    """A scene drawn by a search, with its complete-tree size and the checks it passed."""

    data: dict
    size: complete_tree.TreeSize | None  # None: the fill stopped, the tree is larger than the cap
    queries: int
    seconds: float
    table: object = None  # its FeasibilityTable (real planner answers)
    weighted: dict | None = None  # the data with weights that give one optimum (None: no draw does)
    valid: bool | None = None  # strict search: one optimum and every bottle visible (None: not checked)

    def ok(self, goal: tuple[int, int], leaves_tol: float = 0.0) -> bool:
        """True when edges are within WITHIN x the goal's, target leaves within tolerance, one optimum."""
        s = self.size
        return (s is not None and goal[0] / WITHIN <= s.edges <= goal[0] * WITHIN
                and abs(s.target_leaves - goal[1]) <= leaves_tol * goal[1] and self.weighted is not None)


def fill(data: dict, params, directory, save: bool, workers: int = 1, max_queries: int | None = None):
    """(scenario, table, its path, fill stats): the feasibility table of a scene mapping from `directory`, filled
    with the real planner (feasibility_cache.fill_reachable; saved after each level when `save`)."""
    from relocation_app.evaluation.feasibility_cache import fill_reachable, open_table
    sc = parse_scenario(data, data["name"])
    table, path = open_table(sc, params, directory)
    st = fill_reachable(sc, params, table, workers=workers, progress=False, save_to=path if save else None,
                        max_queries=max_queries)
    return sc, table, path, st


def evaluate(data: dict, params, directory, goal: tuple[int, int]) -> Candidate:
    """Fill the candidate's table with the real planner up to WITHIN x the goal's edges, count its tree."""
    import copy
    import time
    cap = int(goal[0] * WITHIN) + 1
    t0 = time.perf_counter()
    sc, table, _, st = fill(data, params, directory, save=False, max_queries=cap)
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
    from stpik_motion_planner.planning.planner import PlanningError
    for r in range(repeats):
        for k, oid in enumerate(sequence):
            try:
                plan_relocation(planner, oid, list(sequence[:k]))
            except PlanningError as e:
                return f"{'-'.join(sequence)} (planning {r + 1} of {repeats}): {e}"
    return ""


def ship(data: dict, table, params, path: Path, header: str, data_dir) -> Path:
    """Write the kept scene to `path` (after `header`) and its filled table to `data_dir`; the table's path."""
    from relocation_app.evaluation.feasibility_cache import open_table
    write_scene(data, path, header)
    final, table_path = open_table(parse_scenario(data, data["name"]), params, data_dir)
    final.entries.update(table.entries)
    final.planner_seconds = table.planner_seconds
    final.save(table_path)
    return table_path


# ------------------------------------------------------------------------------------------------ screen
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


def proposal(seed: int, n: int, name: str, goal: tuple[int, int], params, slack: float = 0.5,
             base: dict | None = None, radius: float = RADIUS) -> dict | None:
    """free_scene(seed, radius), or `base` extended to n obstacles (odd seeds, when given), if its screened tree is
    near the goal (leaves within `slack`, edges within WITHIN^2 x), else None: the real planner is asked only about
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

