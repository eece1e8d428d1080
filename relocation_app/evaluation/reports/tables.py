"""Tables shaped like the paper's Tables 1-4 from the sweep's JSONL records (means over the runs of a cell).

E_ss: episodes to steady state (Eq. 16); MP_q: motion-planner queries as the paper counts them (new tree
edges); E_1st: first episode whose greedy sequence is optimal (runs that never get there are counted apart);
calls: real planner calls one training needs with the set-keyed cache; opt: runs ending with the optimum.
"""
from __future__ import annotations

import statistics
from collections import defaultdict

from relocation_app.evaluation.sweep import ALGORITHMS, algo_name

METRICS = ("E_ss", "MP_q", "E_1st")


def cell_stats(rec: dict) -> dict:
    """Statistics over the runs of one JSONL record (E_ss, MP_q, E_1st and its spread, calls, optima)."""
    runs = rec["runs_data"]
    e1 = [r["E_1st"] for r in runs if r["E_1st"] is not None]
    return {
        "E_ss": statistics.fmean(r["E_ss"] for r in runs),
        "MP_q": statistics.fmean(r["MP_q"] for r in runs),
        "E_1st": statistics.fmean(e1) if e1 else None,
        "E_1st_min": min(e1) if e1 else None,
        "E_1st_max": max(e1) if e1 else None,
        "E_1st_missing": len(runs) - len(e1),
        # for ranking: a run that never found the optimum counts with all its episodes
        "E_1st_pen": statistics.fmean(r["E_1st"] if r["E_1st"] is not None else r["episodes"] for r in runs),
        "calls": statistics.fmean(r["calls"] for r in runs),
        "optimal": sum(r["optimal"] for r in runs),
        "converged": sum(r["converged"] for r in runs),
        "runs": len(runs),
    }


def index(records: list[dict]) -> dict:
    """{scenario: {(algorithm, alpha, gamma): stats}} keeping the last record of a cell."""
    out: dict = defaultdict(dict)
    for rec in records:
        out[rec["scenario"]][(rec["algorithm"], rec["alpha"], rec["gamma"])] = cell_stats(rec) | {
            "e_max": rec["e_max"], "optimal_weight": rec["optimal_weight"], "exact_calls": rec["exact_calls"]}
    return out


def _fmt(v, missing: int = 0, runs: int = 0) -> str:
    if v is None:
        return "never"
    s = f"{v:.0f}" if v >= 100 else f"{v:.1f}"
    return s + (f" ({runs - missing}/{runs})" if missing else "")


def algorithms_order() -> list[str]:
    """The six algorithms in the paper's table order."""
    return [algo_name(p, s) for p, s in ALGORITHMS]


def grid_of(cells: dict) -> list[tuple[float, float]]:
    """The (alpha, gamma) pairs of `cells`, alpha ascending then gamma descending."""
    return sorted({(a, g) for (_, a, g) in cells}, key=lambda x: (x[0], -x[1]))


def metric_table(cells: dict, metric: str) -> str:
    """Rows: the six algorithms; columns: (alpha, gamma); entries: mean over the runs."""
    grid = grid_of(cells)
    head = "| algorithm | " + " | ".join(f"a={a:g} g={g:g}" for a, g in grid) + " |"
    lines = [head, "|---|" + "---:|" * len(grid)]
    for alg in algorithms_order():
        row = []
        for a, g in grid:
            st = cells.get((alg, a, g))
            if st is None:
                row.append("-")
            elif metric == "E_1st":
                row.append(_fmt(st["E_1st"], st["E_1st_missing"], st["runs"]))
            else:
                row.append(_fmt(st[metric]))
        lines.append(f"| {alg} | " + " | ".join(row) + " |")
    return "\n".join(lines)


def summary_table(cells: dict) -> str:
    """Per algorithm over the whole (alpha, gamma) grid: optimum rate, MP_q vs real calls, E_1st spread."""
    lines = ["| algorithm | optimal runs | converged | E_ss mean | MP_q mean | real calls (set cache) mean | "
             "calls / MP_q | E_1st min / mean / max | E_max |",
             "|---|---:|---:|---:|---:|---:|---:|---|---:|"]
    for alg in algorithms_order():
        sts = [v for (al, _, _), v in cells.items() if al == alg]
        if not sts:
            continue
        runs = sum(s["runs"] for s in sts)
        opt = sum(s["optimal"] for s in sts)
        conv = sum(s["converged"] for s in sts)
        ess = statistics.fmean(s["E_ss"] for s in sts)
        mpq = statistics.fmean(s["MP_q"] for s in sts)
        calls = statistics.fmean(s["calls"] for s in sts)
        e1 = [s for s in sts if s["E_1st"] is not None]
        e1s = (f"{min(s['E_1st_min'] for s in e1)} / {statistics.fmean(s['E_1st'] for s in e1):.1f} / "
               f"{max(s['E_1st_max'] for s in e1)}") if e1 else "never"
        lines.append(f"| {alg} | {opt}/{runs} | {conv}/{runs} | {ess:.0f} | {mpq:.0f} | {calls:.0f} | "
                     f"{calls / mpq:.2f} | {e1s} | {max(s['e_max'] for s in sts)} |")
    return "\n".join(lines)


def random_table(idx: dict, scenes: list[str]) -> str:
    """Table 4: per algorithm, the mean over the random scenes (and over the grid) of E_ss, MP_q, E_1st,
    and the optimum rate."""
    lines = ["| algorithm | E_ss | MP_q | E_1st | real calls | optimal runs |", "|---|---:|---:|---:|---:|---:|"]
    for alg in algorithms_order():
        sts = [v for s in scenes for (al, _, _), v in idx.get(s, {}).items() if al == alg]
        if not sts:
            continue
        e1 = [s["E_1st"] for s in sts if s["E_1st"] is not None]
        lines.append(f"| {alg} | {statistics.fmean(s['E_ss'] for s in sts):.0f} | "
                     f"{statistics.fmean(s['MP_q'] for s in sts):.0f} | "
                     f"{statistics.fmean(e1):.1f} | " if e1 else f"| {alg} | - | - | never | ")
        if e1:
            lines[-1] += (f"{statistics.fmean(s['calls'] for s in sts):.0f} | "
                          f"{sum(s['optimal'] for s in sts)}/{sum(s['runs'] for s in sts)} |")
    return "\n".join(lines)
