"""The paper's sweep (Sect. 5.1): six algorithms x (alpha, gamma) x N runs per scenario, on cached real-planner
feasibility; process pool over the cores, tqdm progress, resumable (one JSONL line per finished cell).

A cell is (scenario, policy, search, alpha, gamma). LRND and H-LRND run with E_max = 10,000; H-eG with E_max =
the largest number of episodes any LRND run needed on that scenario (the paper's rule), so the LRND cells of a
scenario run first. epsilon0 = 1, epsilon_min = 1e-3; the other parameters are config/task_planner.yaml's.
Each run asks a PlannerOracle over the scenario's FeasibilityTable; `train` puts a fresh set-keyed CachedOracle
in front of it per run, so a run's `planner_calls` is the number of real planner calls that one training
needs with the set-keyed cache (vs its MP_q, the paper's count of tree edges).
"""
from __future__ import annotations

import json
import math
import os
import signal
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path

from qtree_task_planner.learning.params import TrainingParams
from qtree_task_planner.learning.training import WEIGHT_TOL, train
from qtree_task_planner.problem import RelocationProblem
from qtree_task_planner.search import exact
from relocation_app.evaluation.feasibility_cache import PlannerOracle, load_table
from relocation_app.progress import Progress

ALGORITHMS = (("lrnd", "breadth"), ("lrnd", "depth"), ("h-lrnd", "breadth"), ("h-lrnd", "depth"),
              ("h-eg", "breadth"), ("h-eg", "depth"))
ALPHAS = (0.3, 0.5, 1.0)
GAMMAS = (0.9, 0.5, 0.1)
GRID = tuple((a, g) for a in ALPHAS for g in GAMMAS)
E_MAX_RANDOM = 10_000
CURVE_POINTS = 200


def algo_name(policy: str, search: str) -> str:
    """Table name of an algorithm: policy and search initial, e.g. H-eG_d (the paper's naming)."""
    return {"lrnd": "LRND", "h-lrnd": "H-LRND", "h-eg": "H-eG"}[policy] + "_" + search[0]


@dataclass(frozen=True)
class Cell:
    """One cell of the sweep: a scene with its feasibility table, an algorithm, (alpha, gamma), runs and E_max."""

    scenario: str  # scenario name
    scenario_path: str
    cache_path: str
    cache_key: str
    policy: str
    search: str
    alpha: float
    gamma: float
    runs: int
    e_max: int

    @property
    def ident(self) -> tuple:
        """What identifies a finished cell in the JSONL results (resume skips it)."""
        return (self.scenario, self.cache_key[:12], self.policy, self.search, self.alpha, self.gamma, self.runs,
                self.e_max)


_LOADED: dict = {}


def _setting(cell: Cell):
    """Scenario, problem, table and optimum of a cell's scene, loaded once per worker process."""
    key = (cell.scenario_path, cell.cache_path)
    if key not in _LOADED:
        from relocation_common.scenario import load_scenario
        sc = load_scenario(cell.scenario_path)
        table = load_table(cell.cache_path, cell.cache_key)
        oracle = PlannerOracle(sc, None, table)
        problem = RelocationProblem.from_scenario(sc)
        opt = exact.solve(problem, oracle)
        _LOADED[key] = (sc, problem, oracle, opt)
    return _LOADED[key]


def _curve(histories: list[list[float]]) -> list[list[float]]:
    """Mean over runs of Q_sum(e) / max_e Q_sum(e) (Eq. 15 normalised, paper Fig. 4); a run that stopped keeps
    its last value; sampled at <= CURVE_POINTS episodes."""
    n = max(len(h) for h in histories)
    idx = sorted({min(n - 1, int(round(k * (n - 1) / max(1, CURVE_POINTS - 1)))) for k in range(CURVE_POINTS)})
    out = []
    for i in idx:
        vals = []
        for h in histories:
            m = max(h) or 1.0
            vals.append(h[min(i, len(h) - 1)] / m)
        out.append([i + 1, round(sum(vals) / len(vals), 5)])
    return out


def run_cell(cell: Cell) -> dict:
    """All runs of one cell (seeds 0 .. runs-1); returns the JSONL record."""
    sc, problem, oracle, opt = _setting(cell)
    base = TrainingParams.from_yaml(ignore_unknown=True).replace(
        policy=cell.policy, search=cell.search, alpha=cell.alpha, gamma=cell.gamma, epsilon0=1.0, epsilon_min=1e-3,
        max_episodes=cell.e_max)
    t0 = time.perf_counter()
    runs, histories = [], []
    calls0 = oracle.real_calls
    for seed in range(cell.runs):
        r = train(problem, oracle, base.replace(seed=seed), optimal_weight=opt.total_weight)
        optimal = r.total_weight is not None and r.total_weight <= opt.total_weight + WEIGHT_TOL
        runs.append({"seed": seed, "E_ss": r.e_ss, "MP_q": r.mp_q, "E_1st": r.e_1st, "calls": r.planner_calls,
                     "episodes": r.episodes, "converged": r.converged, "weight": r.total_weight,
                     "optimal": optimal, "sequence": list(r.sequence) if r.sequence else None})
        histories.append(r.q_sum_history)
    return {"scenario": cell.scenario, "cache_key": cell.cache_key[:12], "policy": cell.policy,
            "search": cell.search, "algorithm": algo_name(cell.policy, cell.search), "alpha": cell.alpha,
            "gamma": cell.gamma, "runs": cell.runs, "e_max": cell.e_max, "optimal_weight": opt.total_weight,
            "exact_calls": opt.oracle_calls, "runs_data": runs, "curve": _curve(histories),
            "seconds": round(time.perf_counter() - t0, 3), "new_planner_calls": oracle.real_calls - calls0,
            "new_entries": [[o, sorted(r), int(lab), t, a] for o, r, lab, t, a in oracle.new]}


def read_results(path: str | Path) -> list[dict]:
    """The finished cells in a JSONL file (a torn last line from an interruption is ignored)."""
    path = Path(path)
    if not path.exists():
        return []
    out = []
    lines = path.read_text().splitlines()
    for k, line in enumerate(lines):
        if not line.strip():
            continue
        try:
            out.append(json.loads(line))
        except json.JSONDecodeError:
            if k == len(lines) - 1:
                continue  # interrupted while writing the last line
            raise ValueError(f"{path}: line {k + 1} is not JSON; delete the file to restart the sweep") from None
    return out


def _ident(rec: dict) -> tuple:
    return (rec["scenario"], rec["cache_key"], rec["policy"], rec["search"], rec["alpha"], rec["gamma"],
            rec["runs"], rec["e_max"])


def eg_episodes(records: list[dict], scenario: str, runs: int) -> int | None:
    """E_max of the H-eG cells: the largest number of episodes an LRND run needed on `scenario`; None until all
    LRND cells of the scenario are there."""
    lr = [r for r in records if r["scenario"] == scenario and r["policy"] == "lrnd" and r["runs"] == runs
          and r["e_max"] == E_MAX_RANDOM]
    if len(lr) < 2 * len(GRID_IN_USE.get(scenario, GRID)):
        return None
    return max(x["episodes"] for r in lr for x in r["runs_data"])


GRID_IN_USE: dict[str, tuple] = {}


@dataclass(frozen=True)
class Scene:
    """A scene of the sweep: its scenario file, feasibility table and (alpha, gamma) grid."""

    name: str
    scenario_path: str
    cache_path: str
    cache_key: str
    grid: tuple = GRID


def sweep(scenes: list[Scene], runs: int, out: str | Path, workers: int | None = None, progress: bool = True,
          algorithms=ALGORITHMS) -> dict:
    """Run every missing cell, appending one JSONL line per cell to `out`; returns timing and counts."""
    import multiprocessing as mp

    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    workers = workers or os.cpu_count() or 1
    for s in scenes:
        GRID_IN_USE[s.name] = s.grid
    if out.exists():  # drop a line torn by an interruption, so that appending starts on a fresh line
        text = out.read_text()
        if text and not text.endswith("\n"):
            out.write_text(text[:text.rfind("\n") + 1])
    records = read_results(out)
    done = {_ident(r) for r in records}
    t0 = time.perf_counter()
    ran = 0

    def cells(phase: int) -> list[Cell]:
        res = []
        for s in scenes:
            for policy, search in algorithms:
                if (policy == "h-eg") != (phase == 2):
                    continue
                if phase == 2:
                    e_max = eg_episodes(records, s.name, runs) if any(p == "lrnd" for p, _ in algorithms) else None
                    e_max = e_max or E_MAX_RANDOM
                else:
                    e_max = E_MAX_RANDOM
                for a, g in s.grid:
                    c = Cell(s.name, s.scenario_path, s.cache_path, s.cache_key, policy, search, a, g, runs, e_max)
                    if c.ident not in done:
                        res.append(c)
        return res

    bar = None
    if progress:  # a bar on a terminal, a line every few seconds in a log (relocation_app.progress)
        total = sum(len(s.grid) for s in scenes) * len(algorithms)
        bar = Progress("sweep", "cell", total=total,
                       initial=total - len(cells(1)) - _pending_eg(scenes, algorithms, done, runs))
    # Workers forked from a forkserver, not from this process: a pool worker forked from a test run's worker (its
    # rclpy and DDS objects, its threads) crashed in its garbage collector, and multiprocessing.Pool waited forever
    # for the lost cell; a worker that dies now fails the sweep (BrokenProcessPool) and a rerun resumes it.
    ctx = mp.get_context("forkserver")
    with ProcessPoolExecutor(workers, mp_context=ctx, initializer=_default_signals) as pool, out.open("a") as f:
        for phase in (1, 2):
            todo = sorted(cells(phase), key=lambda c: -_cost_hint(c))
            for done_cell in as_completed([pool.submit(run_cell, c) for c in todo]):
                rec = done_cell.result()
                f.write(json.dumps(rec, separators=(",", ":")) + "\n")
                f.flush()
                records.append(rec)
                done.add(_ident(rec))
                ran += 1
                if bar is not None:
                    bar.update(advance=1, postfix=f"{rec['scenario']} {rec['algorithm']} a={rec['alpha']} "
                                                  f"g={rec['gamma']}")
    if bar is not None:
        bar.close()
    new = [e for r in records for e in r.get("new_entries", [])]
    return {"cells_run": ran, "seconds": time.perf_counter() - t0, "records": len(records),
            "new_planner_calls": len(new)}


def _default_signals() -> None:
    """Pool workers die on SIGTERM and SIGINT (a Ctrl-C of the sweep reaches its process group) whatever handlers
    were set where they came from: a worker that survived a SIGTERM while holding the task queue's lock once left
    the sweep waiting forever."""
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _pending_eg(scenes, algorithms, done, runs) -> int:
    n = 0
    for s in scenes:
        for policy, search in algorithms:
            if policy != "h-eg":
                continue
            for a, g in s.grid:
                if not any(d[0] == s.name and d[2] == policy and d[3] == search and d[4] == a and d[5] == g
                           and d[6] == runs for d in done):
                    n += 1
    return n


def _cost_hint(c: Cell) -> float:
    n = 15 if "15" in c.scenario else 10 if "10" in c.scenario else 5
    return n ** 2 * (4 if c.search == "depth" else 1) * math.log(c.e_max + 1)
