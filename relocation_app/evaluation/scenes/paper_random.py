"""Table 4's ten random cases at the paper's size (docs/evaluation.md): `python -m relocation_app.evaluation.scenes
paper-random`, scenes config/scenarios/paper_random5/paper_random5_XX.yaml.

The paper's random cases have 5 obstacles and complete Q-Trees of 71-104 edges (their LRND MP_q, Table 4). Case c
gets the first layout, in seed order after SEED0, of `layout.free_scene` (random spots around a back-row target,
possibly behind a column straight in front of it) that the lane screen puts near such a tree and whose complete tree,
counted with the real planner, has edges within WITHIN x of case c's, weights with one optimum (Eq. 8), every bottle
seen by perception and every relocation of the optimum planned six times in a row (`screening.valid`). There is
no climbing: the cases stay random draws, their weights drawn from the layout's seed. The paper gives no target-leaf
count for the cases; the screen asks for 0-20 (scenario 1 has 10).
"""
from __future__ import annotations

import copy
import time
from pathlib import Path

from relocation_app.evaluation import paper
from relocation_app.evaluation.scenes import complete_tree, screening
from relocation_app.evaluation.scenes.layout import made_by

DIR = "paper_random5"
SEED0 = 5000  # the first layout seed tried is SEED0 + 1
LEAVES = 10  # the screen's leaf goal (scenario 1's count), with slack 1.0: 0-20
HEADER = ("# Table 4 random case at the paper's size (docs/evaluation.md), drawn with the real motion planner by\n"
          f"# {made_by('paper-random')} on the shelf of paper_experiment_10. Format: docs/scenarios.md.")


def name(case: int) -> str:
    """Scene name of Table 4 case `case` (1-based): paper_random5_00 .. _09."""
    return f"{DIR}_{case - 1:02d}"


def case_edges() -> dict[int, int]:
    """Paper case -> complete-tree edges (LRND_b's MP_q: LRND completes the tree)."""
    return {c: int(round(algs["LRND_b"]["MP_q"])) for c, algs in paper.table4().items()}


def draw(case: int, params, work, seed: int, deadline: float, log=print):
    """(candidate, seed after it) of the first valid layout from `seed` on for `case`; (None, seed) at the deadline."""
    goal = (case_edges()[case], LEAVES)
    while time.time() < deadline:
        seed += 1
        d = screening.proposal(seed, 5, name(case), goal, params, slack=1.0)
        if d is None:
            continue
        c = screening.evaluate(d, params, work, goal)
        if c.size is None or not goal[0] / screening.WITHIN <= c.size.edges <= goal[0] * screening.WITHIN:
            continue
        edges = c.size.edges
        # weights drawn from the layout's seed: with the searches' seed 0, two cases of one blocking structure
        # got the same weights, hence the same training statistics
        c.weighted = screening.one_optimum(copy.deepcopy(d), c.table, 30, seed=seed)
        if c.weighted is None or not screening.valid(c, params, log):
            log(f"case {case} seed {seed}: {edges} edges, not valid (one optimum, every bottle seen, plannable)")
            continue
        log(f"case {case} seed {seed}: {edges} edges, {c.size.target_leaves} target leaves (paper {goal[0]} edges)")
        return c, seed
    return None, seed


def make(params, data_dir, scenarios: Path, cases=None, seed0: int = SEED0, minutes: float = 60.0,
         log=print, work: Path | None = None) -> int:
    """Draw and write the cases (all ten by default); returns how many were written. The candidates' tables are
    kept in `work` (default out/paper_search/tables)."""
    from relocation_common.paths import share_dir
    from relocation_common.scenario import parse_scenario
    work = work or share_dir() / "out" / "paper_search" / "tables"
    deadline = time.time() + 60 * minutes
    seed, written = seed0, 0
    for case in cases or sorted(case_edges()):
        c, seed = draw(case, params, work, seed, deadline, log)
        if c is None:
            log(f"case {case}: none within {minutes:g} min")
            break
        data = c.weighted
        sc = parse_scenario(data, data["name"])
        size = complete_tree.of_table(c.table, sc)
        data["description"] = (f"Table 4 case {case} at the paper's size (layout seed {seed}): complete Q-Tree of "
                               f"{size.edges} edges (paper: {case_edges()[case]}), {size.target_leaves} target "
                               f"leaves, one optimum.")
        screening.ship(data, c.table, params, scenarios / DIR / f"{name(case)}.yaml", HEADER, data_dir)
        written += 1
    return written
