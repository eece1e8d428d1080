"""Sections of docs/evaluation.md that put the paper's numbers (paper.py, data/paper/) beside ours (issue 16):
complete-tree sizes, Tables 1-3 cell by cell with the ratio, Table 4 per case, the findings judged on both.

A cell reads `paper / ours (ours/paper)`; the paper's value carries '?' when uncertain and '!' when doubtful
(data/paper/README.md), '-' when missing. Ours are the means over the runs of the cell (tables.cell_stats); for
E_1st a run that never reached the optimum is left out, as in Tables 1-3 shape.
"""
from __future__ import annotations

import statistics

from . import claims, paper
from .tables import METRICS, algorithms_order, grid_of


def _v(x) -> str:
    return "-" if x is None else (f"{x:.0f}" if abs(x) >= 100 else f"{x:.1f}".rstrip("0").rstrip("."))


def _cell(p, flag: str, ours) -> str:
    ratio = f" ({ours / p:.2g})" if p and ours is not None else ""
    return f"{_v(p)}{flag} / {_v(ours)}{ratio}"


def tree_table(rows: list[tuple[str, int, object]]) -> str:
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


def table4(idx: dict, random: list[str]) -> str:
    """Table 4 per case: case c of the paper beside random5_{c-1}; ours = mean over its (alpha, gamma) grid (the
    paper does not say which alpha, gamma Table 4 used)."""
    cases = paper.table4()
    lines = ["| case | our scene | algorithm | E_ss | MP_q | E_1st |", "|---:|---|---|---|---|---|"]
    for c in sorted(cases):
        scene = random[c - 1] if c - 1 < len(random) else None
        cells = idx.get(scene, {}) if scene else {}
        for alg in algorithms_order():
            sts = [st for (al, _, _), st in cells.items() if al == alg]
            row = []
            for m in METRICS:
                vals = [st[m] for st in sts if st[m] is not None]
                ours = statistics.fmean(vals) if vals else None
                row.append(_cell(cases[c][alg][m], paper.mark(4, c, None, None, alg, m), ours))
            lines.append(f"| {c} | {scene or '-'} | {alg} | " + " | ".join(row) + " |")
    return "\n".join(lines)


def findings(sets: list[tuple[str, dict, list[str], list[str], frozenset]]) -> tuple[str, list[list]]:
    """Each finding judged on each set: (label, index, scenes 1-3, random scenes, off-target cells). The paper's
    own numbers come first. Returns the markdown table and the deciding numbers per set."""
    verdicts = []
    for label, idx, main, rnd, off in sets:
        present = [s for s in main if s in idx]
        found = claims.check(idx, present, present[1:], [r for r in rnd if r in idx], off) if present else []
        verdicts.append((label, found))
    names = [c for c, _, _ in max((f for _, f in verdicts), key=len)]
    head = "| finding | " + " | ".join(label for label, _ in verdicts) + " |"
    lines = [head, "|---|" + "---|" * len(verdicts)]
    for i, name in enumerate(names):
        lines.append(f"| {name} | " + " | ".join(f"**{f[i][1]}**" if i < len(f) else "not checked"
                                                  for _, f in verdicts) + " |")
    return "\n".join(lines), verdicts
