"""The paper's own Tables 1-4 (Golluccio et al., JINT 2022, Sect. 5.1), from data/paper/ (README there: source,
how each cell was read, which cells are uncertain or doubtful).

`cells(k)` gives scenario k's Table 1-3 cells in the shape of tables.index (so claims.py can judge the paper's
numbers with the same code as ours); `table4()` the ten random cases; `mark(...)` the flag of a cell:
'?' uncertain (reconstructed or unreadable), '!' doubtful (read cleanly, breaks a pattern), '' clean.
"""
from __future__ import annotations

import csv
from functools import lru_cache

from relocation_common.paths import data_dir

PAPER_DIR = data_dir() / "paper"
SCENARIOS = {1: 5, 2: 10, 3: 15}  # Table k -> obstacles
COMPLETE_TREE = {1: 84, 2: 622, 3: 1675}  # edges of the complete tree: LRND's MP_q (complete_tree.py)
TARGET_LEAVES = {1: 10, 2: 20, 3: 20}  # "feasible sequences" (Sect. 5.1)
MARKS = {"uncertain": "?", "doubtful": "!"}


def _num(v: str) -> float | None:
    return float(v) if v.strip() else None


def _rows(name: str) -> list[dict]:
    with (PAPER_DIR / name).open(newline="") as f:
        return list(csv.DictReader(f))


@lru_cache(maxsize=None)
def _flags() -> dict:
    """(table, scenario or case, alpha, gamma, algorithm, metric) -> kind, from uncertain_cells.csv."""
    out = {}
    for r in _rows("uncertain_cells.csv"):
        out[(int(r["table"]), int(r["scenario_or_case"]), _num(r["alpha"]), _num(r["gamma"]), r["algorithm"],
             r["metric"])] = r["kind"]
    return out


def mark(table: int, k: int, alpha, gamma, algorithm: str, metric: str) -> str:
    """'?' uncertain, '!' doubtful, '' clean (Table 4: alpha = gamma = None)."""
    kind = _flags().get((table, k, alpha, gamma, algorithm, metric))
    return MARKS.get(kind, "") if kind is not None else ""


@lru_cache(maxsize=None)
def _tables_1_3() -> dict:
    out: dict = {}
    for r in _rows("tables_1_3.csv"):
        st = {m: _num(r[m]) for m in ("E_ss", "MP_q", "E_1st")}
        st["E_1st_pen"] = st["E_1st"]  # the paper gives no count of runs that never found the optimum
        out.setdefault(int(r["scenario"]), {})[(r["algorithm"], float(r["alpha"]), float(r["gamma"]))] = st
    return out


def cells(k: int) -> dict:
    """Scenario k (Table k): {(algorithm, alpha, gamma): {'E_ss', 'MP_q', 'E_1st', 'E_1st_pen'}}; None = missing."""
    return {key: dict(v) for key, v in _tables_1_3()[k].items()}


@lru_cache(maxsize=None)
def _table4() -> dict:
    out: dict = {}
    for r in _rows("table_4.csv"):
        st = {m: _num(r[m]) for m in ("E_ss", "MP_q", "E_1st")}
        st["E_1st_pen"] = st["E_1st"]
        out.setdefault(int(r["case"]), {})[r["algorithm"]] = st  # case 10 is listed twice, identically
    return out


def table4() -> dict:
    """{case 1..10: {algorithm: {'E_ss', 'MP_q', 'E_1st', 'E_1st_pen'}}}."""
    return {c: {a: dict(v) for a, v in algs.items()} for c, algs in _table4().items()}


def index() -> dict:
    """The paper's numbers as a tables.index-shaped mapping: 'paper scenario k' -> cells(k), and 'paper case c'
    -> Table 4's case c (alpha, gamma unknown: keyed None)."""
    out = {f"paper scenario {k}": cells(k) for k in SCENARIOS}
    for c, algs in table4().items():
        out[f"paper case {c}"] = {(a, None, None): st for a, st in algs.items()}
    return out
