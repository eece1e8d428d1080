"""Scenes of the paper's size (Sect. 5.1), searched with the real motion planner: `python -m
relocation_app.evaluation.scenes paper N` writes config/scenarios/paper1_5, paper2_10 or paper3_15 (docs/evaluation.md,
"Complete trees"); the search log goes to out/paper_search/.

The paper's scenarios 1-3 have complete Q-Trees (complete_tree.py) of 84 / about 622 / about 1,675 edges (their
LRND MP_q) with 10 / 20 / 20 target leaves and one optimum. Candidates are layouts at random free spots
(layout.free_scene: around a back-row target, possibly behind a column straight in front of it) or the smaller
paper scene with bottles added (layout.extend_scene), screened and judged as screening.py says; then `steps` of
hill climbing (`perturb`: one bottle moved) from the best, scored by `score`.
"""
from __future__ import annotations

import math
import random
from pathlib import Path

import yaml

from relocation_app.evaluation.scenes import complete_tree
from relocation_app.evaluation.scenes.layout import MAX_REACH, RADIUS, X_FREE, Y_FREE, made_by
from relocation_app.evaluation.scenes.screening import (
    WITHIN,
    Candidate,
    evaluate,
    proposal,
    screen_size,
    ship,
    valid,
    visible,
)
from relocation_common.scenario import parse_scenario

PAPER_TREES = {5: (84, 10), 10: (622, 20), 15: (1675, 20)}  # obstacles -> (complete-tree edges, target leaves)
PAPER_NAMES = {5: "paper1_5", 10: "paper2_10", 15: "paper3_15"}
INVALID_SLACK = 1.0  # strict climb: how much worse than a start that is not valid its first valid step may be


def header(n: int) -> str:
    """The scenario file's header of the paper-size scene with n obstacles."""
    return ("# Scene of the paper's size (docs/evaluation.md \"Complete trees\"), found with the real motion\n"
            f"# planner by {made_by(f'paper {n}')} on the shelf of paper_experiment_10.\n"
            "# Format: docs/scenarios.md.")


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
        o["xy"] = [round(rng.uniform(*X_FREE), 3), round(rng.uniform(-Y_FREE, Y_FREE), 3)]
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


def search(n: int, name: str, params, directory, seeds, steps: int, log=print, deadline: float = math.inf,
           base: dict | None = None, start: dict | None = None, strict: bool = False, climb_seed: int | None = None,
           temperature: float = 0.0, on_best=None, radius: float = RADIUS):
    """Random candidates (`seeds`, screening.proposal), then `steps` of hill climbing (perturb, keep if not
    worse) from the best; candidates that match the goal (edges within WITHIN x, leaves exact) are checked for
    visibility and one optimum. `strict`: the climb keeps only valid scenes (screening.valid); a start that is not
    valid is left for the first valid step within INVALID_SLACK of its score. `temperature` > 0: a worse step is
    also kept with probability exp(-(score increase) / temperature) (simulated annealing; one bottle at a time
    cannot otherwise leave a local optimum), the best scene seen is returned. `on_best(candidate)` is called on
    each new best. `radius`: of the proposals' bottles (a `base` of another radius is not extended).
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
            done = _finish(best, log)
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


def describe(c: Candidate) -> str:
    """One line on a candidate scene for the search log: its tree's size and what it cost."""
    return ("too big" if c.size is None else f"{c.size.edges} edges, {c.size.target_leaves} target leaves") + \
        f" ({c.queries} planner calls, {c.seconds:.1f} s)"


def _finish(c: Candidate, log) -> dict | None:
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


def make(n: int, params, data_dir, scenarios: Path, seeds: int, steps: int, minutes: float, seed0: int = 0,
         write_best: bool = False, resume: bool = False, strict: bool = False, temperature: float = 0.0,
         radius: float | None = None) -> bool:
    """Search a scene of the paper's size with n obstacles (`search`) and write it into `scenarios` with its
    complete feasibility table when one matches; the best candidate goes to out/paper_search/ either way.
    `strict`: the climb keeps only valid scenes (one optimum, every bottle visible), and `write_best` writes only
    a valid one."""
    import json
    import time

    from relocation_common.paths import share_dir
    name = PAPER_NAMES[n]
    logdir = share_dir() / "out" / "paper_search"
    logdir.mkdir(parents=True, exist_ok=True)

    def log(msg: str) -> None:
        print(time.strftime("%H:%M:%S"), msg, flush=True)
    smaller = scenarios / f"{PAPER_NAMES[n - 5]}.yaml" if n > 5 else None
    base = yaml.safe_load(smaller.read_text()) if smaller is not None and smaller.exists() else None
    best_file = logdir / f"best_{name}.json"
    best, data, _ = search(n, name, params, logdir / "tables", range(seed0, seed0 + seeds), steps, log,
                           time.time() + 60 * minutes, base, shipped(scenarios, name, radius) if resume else None,
                           strict=strict, climb_seed=seed0 if resume else None, temperature=temperature,
                           radius=radius or RADIUS,
                           on_best=lambda c: best_file.write_text(json.dumps(c.weighted or c.data)))
    best_file.write_text(json.dumps((best.weighted or best.data) if best else None))
    if data is None:
        log(f"{name}: no match; best {describe(best) if best else 'none'}")
        if not write_best or best is None or best.size is None or (strict and not best.valid):
            return False
        data = best.weighted or best.data
        log(f"{name}: the closest; bottles perception cannot locate: {visible(data) or 'none'}")
    size = complete_tree.of_table(best.table, parse_scenario(data, name))
    data["description"] = (f"{n} obstacles in tight clutter: complete Q-Tree of {size.edges} edges, "
                           f"{size.target_leaves} target leaves, {size.optimal_leaves} optimal (paper: "
                           f"{PAPER_TREES[n][0]}, {PAPER_TREES[n][1]}, 1)"
                           + ("" if best.ok(PAPER_TREES[n]) else "; the closest the search reached") + ".")
    path = ship(data, best.table, params, scenarios / f"{name}.yaml", header(n), data_dir)
    log(f"{name}: written ({size.edges} edges, {size.target_leaves} target leaves), table {path}")
    return True


def shipped(scenarios: Path, name: str, radius: float | None = None) -> dict:
    """The shipped scene `name`, its bottles of `radius` when given (the layout is kept: smaller bottles fit)."""
    d = yaml.safe_load((scenarios / f"{name}.yaml").read_text())
    d["description"] = ""
    if radius:
        d["defaults"]["radius"] = radius
    return d
