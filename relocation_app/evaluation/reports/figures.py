"""Figures like the paper's Figs. 3-10 (matplotlib, Agg backend), written as PNG into docs/figures/."""
from __future__ import annotations

import shutil
import statistics
import subprocess
from pathlib import Path

import matplotlib

from relocation_app.evaluation.reports.tables import algorithms_order, grid_of

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402 - pyplot after matplotlib.use("Agg") (headless)

# dot's command-line attributes for Fig. 3 (graph, node and edge defaults; to_dot's own per-edge marks stay)
TREE_STYLE = ("-Grankdir=LR", "-Gnodesep=0.12", "-Granksep=0.45", "-Glabelloc=t", "-Gfontsize=14",
              "-Gfontname=Helvetica", "-Nshape=box", "-Nstyle=rounded", "-Nfontsize=12", "-Nfontname=Helvetica",
              "-Efontsize=9", "-Efontname=Helvetica")
COLORS = dict(zip(algorithms_order(), ["#bbbbbb", "#777777", "#9ecae1", "#3182bd", "#fdae6b", "#e6550d"]))


def qsum_curves(records: list[dict], scenario: str, alpha: float, gamma: float, path: Path) -> Path:
    """Fig. 4-like: normalised Q_sum (Eq. 15) per episode, mean over the runs, one line per algorithm."""
    fig, ax = plt.subplots(figsize=(6.4, 3.6))
    for rec in records:
        if rec["scenario"] == scenario and rec["alpha"] == alpha and rec["gamma"] == gamma:
            xs, ys = zip(*rec["curve"])
            ax.plot(xs, ys, label=rec["algorithm"], color=COLORS[rec["algorithm"]])
    ax.set_xscale("log")
    ax.set_xlabel("episode")
    ax.set_ylabel("Q_sum / max Q_sum (mean of runs)")
    ax.set_title(f"{scenario}: normalised sum of values, alpha={alpha:g} gamma={gamma:g}")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def bars(cells: dict, scenario: str, path: Path) -> Path:
    """Figs. 5-7-like: E_ss, MP_q, E_1st per (alpha, gamma), one bar per algorithm."""
    grid = grid_of(cells)
    algs = [a for a in algorithms_order() if any(k[0] == a for k in cells)]
    fig, axes = plt.subplots(3, 1, figsize=(9, 8), sharex=True)
    w = 0.8 / max(1, len(algs))
    for ax, metric in zip(axes, ("E_ss", "MP_q", "E_1st")):
        for k, alg in enumerate(algs):
            ys = [(cells.get((alg, a, g)) or {}).get(metric) or 0 for a, g in grid]
            ax.bar([i + (k - len(algs) / 2 + 0.5) * w for i in range(len(grid))], ys, w, label=alg,
                   color=COLORS[alg])
        ax.set_ylabel(metric)
        ax.set_yscale("log")
    axes[-1].set_xticks(range(len(grid)), [f"a={a:g}\ng={g:g}" for a, g in grid], fontsize=8)
    axes[0].legend(ncol=6, fontsize=7)
    axes[0].set_title(f"{scenario}: means over the runs per (alpha, gamma)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def breadth_depth(idx: dict, scenarios: list[str], path: Path) -> Path:
    """Fig. 8-9-like: breadth vs depth per policy (means over the grid) for E_1st and E_ss."""
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8))
    pols = ["LRND", "H-LRND", "H-eG"]
    for ax, metric in zip(axes, ("E_1st", "E_ss")):
        labels, bvals, dvals = [], [], []
        for s in scenarios:
            for p in pols:
                def m(alg):
                    v = [st[metric] for (al, _, _), st in idx.get(s, {}).items()
                         if al == alg and st[metric] is not None]
                    return statistics.fmean(v) if v else 0
                labels.append(f"{s.split('_')[0][-1] if s.startswith('scenario') else s}\n{p}")
                bvals.append(m(p + "_b"))
                dvals.append(m(p + "_d"))
        xs = range(len(labels))
        ax.bar([x - 0.2 for x in xs], bvals, 0.4, label="breadth", color="#9ecae1")
        ax.bar([x + 0.2 for x in xs], dvals, 0.4, label="depth", color="#e6550d")
        ax.set_xticks(list(xs), labels, fontsize=7)
        ax.set_yscale("log")
        ax.set_title(f"{metric}: breadth vs depth (scenario / policy)")
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def e1st_spread(records: list[dict], scenarios: list[str], path: Path) -> Path:
    """Fig. 10-like: min / mean / max of E_1st over the runs, per algorithm (all (alpha, gamma) pooled)."""
    fig, axes = plt.subplots(1, len(scenarios), figsize=(4 * len(scenarios), 3.6), squeeze=False)
    for ax, s in zip(axes[0], scenarios):
        for k, alg in enumerate(algorithms_order()):
            e1 = [r["E_1st"] for rec in records if rec["scenario"] == s and rec["algorithm"] == alg
                  for r in rec["runs_data"] if r["E_1st"] is not None]
            if not e1:
                continue
            mean = statistics.fmean(e1)
            ax.errorbar([k], [mean], yerr=[[mean - min(e1)], [max(e1) - mean]], fmt="o", capsize=4,
                        color=COLORS[alg])
        ax.set_xticks(range(6), algorithms_order(), rotation=45, fontsize=7)
        ax.set_yscale("log")
        ax.set_title(f"{s}: E_1st min/mean/max", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def tree_figure(dot_file: Path, path: Path, title: str) -> Path:
    """Fig. 3: the Q-Tree drawn by Graphviz (`dot -Tpng`) from the text QTree.to_dot wrote to `dot_file`, left to
    right, removed sets in boxes, edges labelled with the object and Q; the learned path bold, edges to the target
    green, unfeasible ones (g_U, Eq. 11) red dashed, as to_dot marks them. SystemExit with one line when Graphviz is
    not installed."""
    dot = shutil.which("dot")
    if dot is None:
        raise SystemExit("figures: Graphviz's `dot` is not on PATH, needed for Fig. 3: install graphviz "
                         "(apt-get install graphviz; ./run setup does)")
    legend = "bold: the learned path; green: to the target; red dashed: unfeasible"
    subprocess.run([dot, "-Tpng", "-o", str(path), *TREE_STYLE, f"-Glabel={title}\n{legend}", str(dot_file)],
                   check=True)
    return path
