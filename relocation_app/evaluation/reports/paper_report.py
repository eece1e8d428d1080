"""Sections of docs/evaluation.md that put the paper's numbers (paper.py, data/paper/) beside ours:
complete-tree sizes, Tables 1-3 cell by cell with the ratio, Table 4 per case, the findings judged on both.

A cell reads `paper / ours (ours/paper)`; the paper's value carries '?' when uncertain and '!' when doubtful
(data/paper/README.md), '-' when missing. Ours are the means over the runs of the cell (tables.cell_stats); for
E_1st a run that never reached the optimum is left out, as in Tables 1-3 shape.
"""
from __future__ import annotations

import statistics
from typing import Sequence

from relocation_app.evaluation import paper
from relocation_app.evaluation.reports import claims
from relocation_app.evaluation.reports.tables import METRICS, algorithms_order, grid_of
from relocation_app.evaluation.scenes import complete_tree


def _v(x) -> str:
    return "-" if x is None else (f"{x:.0f}" if abs(x) >= 100 else f"{x:.1f}".rstrip("0").rstrip("."))


def _cell(p, flag: str, ours) -> str:
    r = ours / p if p and ours is not None else None
    ratio = "" if r is None else f" ({r:.2g})" if r < 100 else f" ({r:,.0f})"
    return f"{_v(p)}{flag} / {_v(ours)}{ratio}"


def tree_table(rows: list[tuple[str, int, complete_tree.TreeSize | str]]) -> str:
    """rows: (scene, paper scenario k, complete_tree.TreeSize or an error string)."""
    lines = ["| scene | obstacles | complete-tree edges: paper / ours (ratio) | target leaves: paper / ours | "
             "optimal target leaves | nodes |", "|---|---:|---|---|---:|---:|"]
    for name, k, size in rows:
        if isinstance(size, str):
            lines.append(f"| {name} | {paper.SCENARIOS[k]} | not available: {size} | | | |")
            continue
        lines.append(f"| {name} | {paper.SCENARIOS[k]} | {_cell(paper.COMPLETE_TREE[k], '', size.edges)} | "
                     f"{paper.TARGET_LEAVES[k]} / {size.target_leaves} | {size.optimal_leaves} | {size.nodes} |")
    return "\n".join(lines)


def side_by_side(ours: dict, k: int) -> str:
    """Table k of the paper beside `ours` (a tables.index entry): one block per metric, rows = algorithms,
    columns = (alpha, gamma)."""
    theirs = paper.cells(k)
    grid = grid_of(theirs)
    out = []
    for metric in METRICS:
        lines = [f"**{metric}** (paper / ours (ratio))\n",
                 "| algorithm | " + " | ".join(f"a={a:g} g={g:g}" for a, g in grid) + " |",
                 "|---|" + "---:|" * len(grid)]
        for alg in algorithms_order():
            row = []
            for a, g in grid:
                st = ours.get((alg, a, g))
                row.append(_cell(theirs[(alg, a, g)][metric], paper.mark(k, k, a, g, alg, metric),
                                 None if st is None else st[metric]))
            lines.append(f"| {alg} | " + " | ".join(row) + " |")
        out.append("\n".join(lines) + "\n")
    return "\n".join(out)


def ratio_summary(ours: dict, k: int) -> str:
    """One line per metric: the median and range of ours/paper over the cells both have."""
    theirs = paper.cells(k)
    parts = []
    for metric in METRICS:
        r = [ours[key][metric] / v[metric] for key, v in theirs.items()
             if v[metric] and key in ours and ours[key][metric] is not None]
        if r:
            parts.append(f"{metric} ours/paper median {statistics.median(r):.2g} (range {min(r):.2g}-{max(r):.2g}, "
                         f"{len(r)} cells)")
    return "; ".join(parts) or "no cells in common"


def _table4_pairs(idx: dict, random: list[str]) -> dict:
    """(case, scene, algorithm, metric) -> (the paper's value, ours: the mean over the scene's (alpha, gamma) grid,
    the paper does not say which alpha, gamma Table 4 used; None when missing); case c beside random[c-1]."""
    cases = paper.table4()
    out = {}
    for c in sorted(cases):
        scene = random[c - 1] if c - 1 < len(random) else None
        cells = idx.get(scene, {}) if scene else {}
        for alg in algorithms_order():
            sts = [st for (al, _, _), st in cells.items() if al == alg]
            for m in METRICS:
                vals = [st[m] for st in sts if st[m] is not None]
                out[(c, scene, alg, m)] = (cases[c][alg][m], statistics.fmean(vals) if vals else None)
    return out


def table4(idx: dict, random: list[str]) -> str:
    """Table 4 per case: case c of the paper beside random[c-1], one row per algorithm."""
    pairs = _table4_pairs(idx, random)
    lines = ["| case | our scene | algorithm | E_ss | MP_q | E_1st |", "|---:|---|---|---|---|---|"]
    for c, scene, alg in dict.fromkeys(k[:3] for k in pairs):
        row = []
        for m in METRICS:
            theirs, ours = pairs[(c, scene, alg, m)]
            row.append(_cell(theirs, paper.mark(4, c, None, None, alg, m), ours))
        lines.append(f"| {c} | {scene or '-'} | {alg} | " + " | ".join(row) + " |")
    return "\n".join(lines)


def table4_ratios(idx: dict, random: list[str]) -> str:
    """One line per metric: the median and range of ours/paper over Table 4's cells."""
    parts = []
    for m in METRICS:
        r = [o / p for (_, _, _, mm), (p, o) in _table4_pairs(idx, random).items() if mm == m and p and o is not None]
        if r:
            parts.append(f"{m} ours/paper median {statistics.median(r):.2g} (range {min(r):.2g}-{max(r):.2g}, "
                         f"{len(r)} cells)")
    return "; ".join(parts) or "no cells in common"


def findings(sets: list[tuple[str, dict, list[str], list[str], frozenset]]
             ) -> tuple[str, list[tuple[str, list[tuple[str, str, str]]]]]:
    """Each finding judged on each set: (label, index, scenes 1-3, random scenes, off-target cells). The paper's
    own numbers come first. Returns the markdown table and the deciding numbers per set."""
    verdicts = []
    for label, idx, main, rnd, off in sets:
        present = [s for s in main if s in idx and len({k[0] for k in idx[s]}) == 6]  # all six algorithms
        found = claims.check(idx, present, present[1:], [r for r in rnd if r in idx], off) if present else []
        verdicts.append((label, found))
    names = [c for c, _, _ in max((f for _, f in verdicts), key=len)]
    head = "| finding | " + " | ".join(label for label, _ in verdicts) + " |"
    lines = [head, "|---|" + "---|" * len(verdicts)]
    for i, name in enumerate(names):
        lines.append(f"| {name} | " + " | ".join(f"**{f[i][1]}**" if i < len(f) else "not checked"
                                                  for _, f in verdicts) + " |")
    return "\n".join(lines), verdicts


def table4_trees(info: dict, random: list[str]) -> str:
    """Complete trees of the random cases beside the paper's (case c's LRND MP_q: LRND completes the tree)."""
    cases = paper.table4()
    lines = ["| case | our scene | complete-tree edges: paper / ours (ratio) | target leaves | optimal target leaves |",
             "|---:|---|---|---:|---:|"]
    for c, name in enumerate(random, 1):
        if c not in cases or name not in info:
            continue
        t = complete_tree.of_table(info[name][1], info[name][0])
        lines.append(f"| {c} | {name} | {_cell(cases[c]['LRND_b']['MP_q'], '', t.edges)} | {t.target_leaves} | "
                     f"{t.optimal_leaves} |")
    return "\n".join(lines)


SEARCH_NOTE = """**How the scenes of the paper's size were found** (`python -m relocation_app.evaluation.scenes
paper N`, `paper_size.py`; logs in out/paper_search/). Only bottle positions (and weights) were chosen: same
shelf, bottle size, hand and planner parameters as every other scene. Layouts (a column of up to three bottles
straight in front of the target plus bottles at random free spots, or the smaller paper scene with bottles added)
are screened with the planner's grasp-lane screen (`stpik_motion_planner.model.blockers`); promising ones are filled
with the real planner (stopped once the tree passes 2x the paper's) and hill-climbed with it, one bottle moved per step;
weights are then drawn until one target leaf has the least weight (Eq. 8), and perception must locate every bottle
in the first camera frame (arm at home). With `--strict` the climb keeps only valid scenes: one optimum, every
bottle seen, and every relocation of the optimum planned six times in a row (OMPL's random stream is per process, so
a plan depends on the queries before it; the paper scenes were found with two, which let paper2_10's borderline pick
of T through). Each paper scene's optimum is relocated in MuJoCo by the independent checker
(`test_motion_checker.py`): 0 contacts, carried bottle at least 10.0 mm from everything, arm at least 20.4 mm.
paper2_10: 14 min, then 12 more climbing from it: edges within 2x, 21 target leaves in the search's fill. paper3_15:
`--resume --strict` found 844 edges (within 2x) and 49 target leaves in 2.5 min; about 45 more minutes of climbing,
annealing (`--temperature`) and hand-placed variants found nothing valid with 838+ edges and fewer leaves (a valid
788-edge / 29-leaf variant, 6 % short of 2x on the edges, was not kept: docs/scenarios.md). Why it is hard: a bottle
up to about 0.2 m straight in front of another blocks all three approach yaws and two bottles of one row closer than
about 0.115 m block each other for good, so an added bottle either can be removed, and then multiplies the target
leaves (it can be relocated before or after others), or cannot, and then adds only one edge per node. Among 150,000
random blocking structures with at most three bottles in a row in front of the target (what this shelf's depth
allows) and a single-order optimum, none with 838+ edges had fewer than 33 target leaves; about 28 would need a
five-bottle removal chain. A deeper shelf would put its back row beyond the arm's reach (0.92 m), so smaller bottles
were tried (`--radius 0.025`, four in a column in front of the target): `--resume --strict --radius 0.025` (55 min)
reached 844 edges / 39 target leaves, one optimum, but its pick of T, at the arm's limit, failed in 2-4 of 12
plannings in one process and moving T forward left no single optimum, so it was not kept; a fresh radius-0.025
search (45 min) reached 788 / 29, not valid. The hand, not the bottle, decides what blocks what. paper2_10's T was
moved 10 mm forward after the search: at 0.902 its pick failed in 5 of 12 plannings in one process, 0 of 16 after; a
fresh fill gives 353 edges / 24 target leaves. A five-obstacle layout with exactly the paper's shape reached
83 edges and 10 target leaves, but no weights gave it one optimum: 10 sequences of one set of
bottles weigh the same, as two removal chains of 2 and 3 bottles in front of the target would (exactly 83 edges, 10
leaves); the paper's 84 / 10 / one optimum needs an optimum that Eq. 8 alone does not single out.
These searches ran with 3 approach yaws up to 0.35 rad. With the default grasp set (5 yaws up to 0.5 rad and a
second tier), honest lanes and certified relocations (docs/motion_planner.md) more lanes open: the first paper1_5
grew to 129 edges / 40 target leaves, paper2_10 to 3,523 / 616 with a lighter optimum (o6 o3 T), paper3_15 past 2x
the paper's edges (the table above). paper1_5 was then searched again with the default grasp set (`scenes paper 5
--resume --strict`): o4 moved 8 mm back and 7 mm to the right gives the table's tree, the same optimum o1 o3 T. A
fresh 35-minute `scenes paper 10 --strict` search with it found no match (closest 284 edges / 19 target leaves), so
paper2_10 and paper3_15 keep their layouts; paper3_15 was not searched again (docs/bench/evaluation_2026-12-05.md).
"""


def _trees(info: dict, names: list[str]) -> list[tuple[str, int, complete_tree.TreeSize | str]]:
    """(scene, paper scenario k, its complete_tree.TreeSize or why not) for scenes 1-3 of a set."""
    return [(name, k, complete_tree.of_table(info[name][1], info[name][0]) if name in info
             else "no complete feasibility table") for k, name in enumerate(names, 1)]


def complete_tree_section(info: dict, paper_set: list[str], main: list[str]) -> list[str]:
    """Section "Complete trees": edges and target leaves of each scene's complete tree beside the paper's."""
    md = ["## Complete trees: the paper's scenes against ours\n"]
    for label, names in (("Scenes of the paper's size", paper_set), ("This project's geometry", main)):
        rows = _trees(info, names)
        if rows:
            md.append(f"**{label}**\n\n" + tree_table(rows) + "\n")
    md.append("Paper: LRND's MP_q, (nearly) constant over alpha and gamma because LRND completes the tree (84 / "
              "621-623 / 1,649-1,675 in Tables 1-3; 622 and 1,675 taken), and 10 / 20 / 20 feasible sequences with one "
              "optimum (Sect. 5.1). 'optimal target leaves': target leaves of least total weight (Eq. 8).\n")
    if paper_set:
        md.append(SEARCH_NOTE)
    return md


def beside_paper_sections(idx: dict, paper_set: list[str], main: list[str], random: list[str],
                          paper_random: Sequence[str] = (), info: dict | None = None) -> list[str]:
    """Sections "Table k beside the paper" for both sets of scenes, then Table 4 per case for both random sets."""
    md = []
    for label, names in (("scenes of the paper's size", paper_set), ("this project's geometry", main)):
        for k, s in enumerate(names, 1):
            if s not in idx:
                continue
            md.append(f"## Table {k} beside the paper: {s} ({label})\n")
            md.append(f"Ratios: {ratio_summary(idx[s], k)}.\n")
            md.append(side_by_side(idx[s], k))
    for label, rnd in (("scenes of the paper's size", list(paper_random)), ("this project's geometry", random)):
        if not any(r in idx for r in rnd):
            continue
        md.append(f"## Table 4 beside the paper, per case ({label})\n")
        md.append(f"Case c of the paper beside {rnd[0][:-2]}{{c-1}}; ours are the means over the (alpha, gamma) grid, "
                  "the paper does not say which alpha and gamma Table 4 used.\n")
        if info is not None and rnd is not random:
            md.append(RANDOM_NOTE + "\n" + table4_trees(info, rnd) + "\n")
        md.append(f"Ratios: {table4_ratios(idx, rnd)}.\n")
        md.append(table4(idx, rnd) + "\n")
    return md


RANDOM_NOTE = """The cases at the paper's size (`python -m relocation_app.evaluation.scenes paper-random`,
`paper_random.py`) are random draws, not searched: case c is the first layout in seed order (after 5000) of the paper
scenes' generator (random spots around a back-row target, sometimes behind a column in front of it) whose complete
tree, with the real planner, is within 2x of case c's edges, with weights (drawn from the layout's seed) giving one
optimum, every bottle seen by perception and the optimum planned six times in a row; each optimum is relocated in
MuJoCo by the independent checker (`test_motion_checker.py`). The paper gives no target-leaf count for its cases.
"""


def findings_section(md: list[str], idx, paper_set, main, random, off_target, paper_random=()) -> list:
    """Section "The paper's findings": each judged on the paper's numbers and on ours (both sets); the deciding
    numbers per set below. Returns [(set label, [(claim, verdict, evidence)])]."""
    pidx = paper.index()
    sets: list[tuple[str, dict, list[str], list[str], frozenset]] = [
        ("the paper's numbers", pidx, [f"paper scenario {k}" for k in (1, 2, 3)],
         [f"paper case {c}" for c in range(1, 11)], frozenset())]
    for label, names, rnd in (("ours: scenes of the paper's size", paper_set, list(paper_random)),
                              ("ours: this project's geometry", main, random)):
        present = [s for s in names if s in idx]
        if present:
            sets.append((label, idx, present, rnd, off_target(present)))
    table, verdicts = findings(sets)
    md += ["## The paper's findings\n", table, ""]
    for label, found in verdicts:
        md.append(f"**Deciding numbers, {label}**\n")
        md += [f"- {claim}: **{verdict}**. {ev}" for claim, verdict, ev in found]
        md.append("")
    return verdicts


def closing_note(info: dict, paper_set: list[str], main: list[str], found: list) -> str:
    """Section "Closing note": the complete trees reached per scene against the paper's, and each finding's
    verdict on the paper's numbers and on ours."""
    lines = ["## Closing note: the paper's scenes against ours\n"]
    for label, names in (("Scenes of the paper's size", paper_set), ("This project's geometry", main)):
        parts = [f"{name} {t.edges} edges / {t.target_leaves} target leaves / {t.optimal_leaves} optimal (paper "
                 f"{paper.COMPLETE_TREE[k]} / {paper.TARGET_LEAVES[k]} / 1)"
                 for name, k, t in _trees(info, names) if not isinstance(t, str)]
        if parts:
            lines.append(f"- {label}: " + "; ".join(parts) + ".")
    if found:
        for i, (claim, _, _) in enumerate(found[0][1]):
            lines.append(f"- {claim}: " + "; ".join(f"{label} **{f[i][1] if i < len(f) else 'not checked'}**"
                                                     for label, f in found) + ".")
    return "\n".join(lines) + "\n"
