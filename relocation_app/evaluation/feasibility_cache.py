"""Disk feasibility cache: the real motion planner's answers (Eq. 11) computed once, reused by every training.

Feasibility depends only on (object, set of removed objects) (design sketch), so one JSON file per
(scenario geometry, planner parameters) holds `label` per (object, removed set). The file name and its `key`
field carry a SHA-256 of

- the scenario content that the planner sees: shelf boards and every bottle's id, position, radius, height and
  which one is the target (weights, colours, slots and the marker do not change a feasibility answer, so a
  re-weighted scene reuses the table);
- every PlannerParams field (seed, timeouts, STPIK gains and bounds ...);
- CACHE_VERSION (bump it when the planner's algorithm changes).

A changed scene or parameter gives another key, hence another file: a stale table is never read for the wrong
scene. A file that is not valid JSON, has another key or malformed entries raises FeasibilityCacheError.

`PlannerOracle` is the FeasibilityOracle the trainings use: a table hit answers at once; a miss runs the real
MotionPlanner (created lazily, so a complete table never loads Pinocchio/OMPL) and records the answer.
`fill_reachable` computes the complete table: breadth-first (qtree_task_planner/search/reachable.py) over every set
reachable by feasible removals, which is exactly the set of questions any training (or the exact solver) can
ask; level by level over a process pool.
"""
from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import time
from pathlib import Path
from typing import Any

import numpy as np

from qtree_task_planner.search import reachable
from relocation_common.feasibility import FeasibilityAnswer, Label, ask_many
from relocation_common.paths import data_dir

CACHE_VERSION = 1
DATA_DIR = data_dir() / "feasibility"
EVAL_TIMEOUT = 60.0  # s: wall-clock safety net per planner query when filling the cache (answers are load-independent)


class FeasibilityCacheError(ValueError):
    """A cache file that cannot be used (corrupted, for another scene or planner setting, malformed entry)."""


def planner_params():
    """The evaluation's planner parameters: config/motion_planner.yaml's, with the safety net EVAL_TIMEOUT (not part
    of the cache key) and every answer certified (certify_relocation: the tables hold eager answers, final for a
    training that asks nothing else; docs/motion_planner.md, "Lazy certification"). Shared by the evaluation's
    commands, the scene search and the tests."""
    from stpik_motion_planner.planning.params import PlannerParams
    p = PlannerParams.load()
    p.timeout = EVAL_TIMEOUT
    p.certify_relocation = True
    return p


# ------------------------------------------------------------------------------------------------ keys
def scenario_content(scenario) -> dict:
    """What of a Scenario the feasibility answers depend on (see the module docstring)."""
    s = scenario.shelf
    return {
        "shelf": {f.name: round(getattr(s, f.name), 9) for f in dataclasses.fields(s)},
        "objects": [[o.id, round(o.x, 9), round(o.y, 9), round(o.radius, 9), round(o.height, 9), o.is_target]
                    for o in scenario.objects],
        "target": scenario.target_id,
    }


SAFETY_NETS = ("timeout", "carry_timeout")  # wall-clock limits that never change an answer (they raise instead)
NOT_LABELS = ("reuse_distance",)  # what an answer reports besides its label (its near set), not in the tables
SCENE_READING = ("flat_tilt",)  # how a perceived pose is read (the scene it gives is in the key), no answer's
PUSH = ("push",)  # the push's settings (push.*): no pick's answer, and the tables hold picks (planning/push/)


def planner_content(params) -> dict:
    """Every PlannerParams field that can change an answer, as plain JSON (numpy arrays as lists, nested
    StpikParams flattened); the wall-clock safety nets are left out."""
    def plain(v):
        if isinstance(v, np.ndarray):
            return [float(x) for x in v]
        if isinstance(v, (tuple, list)):
            return [plain(x) for x in v]
        if dataclasses.is_dataclass(v):
            return {f.name: plain(getattr(v, f.name)) for f in dataclasses.fields(v)}
        return v
    from relocation_common import robot_description as rd
    content = {k: v for k, v in plain(params).items() if k not in SAFETY_NETS + NOT_LABELS + SCENE_READING + PUSH}
    content["stpik"]["qdot_max"] = plain(rd.QDOT_MAX)  # the robot's joint speed limits (Table 7) change answers too
    return content


def cache_key(scenario, params) -> str:
    """SHA-256 (hex) of the scene content, planner parameters and CACHE_VERSION: the table's identity."""
    blob = json.dumps({"version": CACHE_VERSION, "scenario": scenario_content(scenario),
                       "planner": planner_content(params)}, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(blob.encode()).hexdigest()


def cache_path(scenario, params, directory: str | Path = DATA_DIR) -> Path:
    """The table file of `scenario` and `params` in `directory`: <scene name>-<first 12 of the key>.json."""
    return Path(directory) / f"{scenario.name}-{cache_key(scenario, params)[:12]}.json"


# ------------------------------------------------------------------------------------------------ table
class FeasibilityTable:
    """label (and planning time, attempts) per (object, frozenset(removed)); JSON round trip."""

    def __init__(self, key: str, scenario_name: str = "", planner: dict | None = None) -> None:
        self.key = key
        self.scenario_name = scenario_name
        self.planner = planner or {}
        self.entries: dict[tuple[str, frozenset[str]], tuple[Label, float, int]] = {}
        self.planner_seconds = 0.0  # total real planning time recorded in the table

    @classmethod
    def for_scenario(cls, scenario, params) -> "FeasibilityTable":
        """An empty table keyed for `scenario` and `params`."""
        return cls(cache_key(scenario, params), scenario.name, planner_content(params))

    def __len__(self) -> int:
        return len(self.entries)

    def get(self, object_id: str, removed: frozenset[str]) -> Label | None:
        """The recorded label of (object_id, removed), None when not in the table."""
        e = self.entries.get((object_id, removed))
        return None if e is None else e[0]

    def put(self, object_id: str, removed: frozenset[str], label: Label, planning_time: float = 0.0,
            attempts: int = 0) -> None:
        """Record a label (and its planning time and attempts) for (object_id, removed)."""
        self.entries[(object_id, frozenset(removed))] = (Label(label), float(planning_time), int(attempts))

    def to_json(self) -> dict:
        """The file's JSON object: header and rows sorted by set size, set, object."""
        rows: list[list[Any]] = [[o, sorted(r), int(lab), round(t, 6), a]
                                 for (o, r), (lab, t, a) in self.entries.items()]
        rows.sort(key=lambda x: (len(x[1]), x[1], x[0]))
        return {"format": "qtree-feasibility-cache", "version": CACHE_VERSION, "key": self.key,
                "scenario": self.scenario_name, "planner": self.planner,
                "columns": ["object", "removed", "label", "planning_time_s", "attempts"], "entries": rows}

    def save(self, path: str | Path) -> Path:
        """Write atomically (tmp file + rename), merging with what another process saved there meanwhile."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        if path.exists():
            other = load_table(path, self.key)
            for k, v in other.entries.items():
                self.entries.setdefault(k, v)
        tmp = path.with_suffix(f".tmp{os.getpid()}")
        tmp.write_text(json.dumps(self.to_json(), separators=(",", ":")) + "\n")
        os.replace(tmp, path)
        return path


def load_table(path: str | Path, expected_key: str | None = None) -> FeasibilityTable:
    """Read a cache file; FeasibilityCacheError naming the file and the problem if it cannot be used."""
    path = Path(path)
    try:
        data = json.loads(path.read_text())
    except OSError as e:
        raise FeasibilityCacheError(f"{path}: cannot read feasibility cache ({e.strerror})") from None
    except json.JSONDecodeError as e:
        raise FeasibilityCacheError(f"{path}: corrupted feasibility cache (not JSON: {e.msg} at line {e.lineno}); "
                                    "delete it to recompute it with the motion planner") from None
    if not isinstance(data, dict) or data.get("format") != "qtree-feasibility-cache":
        raise FeasibilityCacheError(f"{path}: not a feasibility cache file (missing format tag)")
    if data.get("version") != CACHE_VERSION:
        raise FeasibilityCacheError(f"{path}: cache version {data.get('version')!r}, expected {CACHE_VERSION}")
    if expected_key is not None and data.get("key") != expected_key:
        raise FeasibilityCacheError(f"{path}: cache key {str(data.get('key'))[:12]} does not match the scenario and "
                                    f"planner parameters ({expected_key[:12]}): it was computed for another setting")
    table = FeasibilityTable(str(data.get("key")), str(data.get("scenario", "")), data.get("planner") or {})
    entries = data.get("entries")
    if not isinstance(entries, list):
        raise FeasibilityCacheError(f"{path}: 'entries' must be a list")
    for k, row in enumerate(entries):
        try:
            o, removed, lab, t, a = row
            if not isinstance(o, str) or not isinstance(removed, list) or not all(isinstance(r, str) for r in removed):
                raise TypeError
            table.put(o, frozenset(removed), Label(lab), t, a)
            table.planner_seconds += float(t)
        except (TypeError, ValueError):
            raise FeasibilityCacheError(f"{path}: malformed entry {k}: {row!r}") from None
    return table


def open_table(scenario, params, directory: str | Path = DATA_DIR) -> tuple[FeasibilityTable, Path]:
    """The table of (scenario, params) from `directory` (empty if there is no file yet) and its path."""
    path = cache_path(scenario, params, directory)
    if path.exists():
        return load_table(path, cache_key(scenario, params)), path
    return FeasibilityTable.for_scenario(scenario, params), path


# ------------------------------------------------------------------------------------------------ oracle
class PlannerOracle:
    """FeasibilityOracle over a FeasibilityTable; misses go to the real MotionPlanner (created on first miss).

    `real_calls` counts motion-planner runs made by this oracle (0 when the table is complete);
    `new` lists the entries it added (a sweep worker sends them back to the parent to be saved)."""

    def __init__(self, scenario, params, table: FeasibilityTable, planner=None) -> None:
        self.scenario = scenario
        self.params = params
        self.table = table
        self._planner = planner
        self.real_calls = 0
        self.new: list[tuple[str, frozenset[str], Label, float, int]] = []

    @property
    def planner(self):
        """The real MotionPlanner, created on the first table miss."""
        if self._planner is None:
            from stpik_motion_planner.planning.planner import MotionPlanner
            self._planner = MotionPlanner(self.scenario, self.params)
        return self._planner

    def feasibility(self, object_id: str, removed: frozenset[str]) -> FeasibilityAnswer:
        """Eq. 11 for `object_id` with `removed` gone: from the table, else planned and recorded."""
        removed = frozenset(removed)
        label = self.table.get(object_id, removed)
        if label is not None:
            return FeasibilityAnswer(label)
        a = self.planner.feasibility(object_id, removed)
        self.real_calls += 1
        self.table.put(object_id, removed, a.label, a.planning_time, a.attempts)
        self.new.append((object_id, removed, Label(a.label), a.planning_time, a.attempts))
        return FeasibilityAnswer(Label(a.label), a.planning_time, a.attempts, a.message)


# ------------------------------------------------------------------------------------------------ complete fill
_WORKER: dict = {}


def _init_worker(scenario, params) -> None:
    from stpik_motion_planner.planning.planner import MotionPlanner
    _WORKER["mp"] = MotionPlanner(scenario, params)


def _use_scenario(scenario, params) -> None:
    """This process's planner on `scenario`: a new MotionPlanner for new parameters or another shelf, otherwise
    the loaded one with the scene swapped (MotionPlanner.set_scenario; a scene search asks thousands of layouts)."""
    mp = _WORKER.get("mp")
    if mp is None or _WORKER.get("params") is not params or mp.scenario.shelf != scenario.shelf:
        _init_worker(scenario, params)
        _WORKER["params"] = params
    elif mp.scenario is not scenario:
        mp.set_scenario(scenario)


def worker_planner(scenario, params):
    """This process's MotionPlanner on `scenario` (`_use_scenario`: loaded once, the scene swapped after)."""
    _use_scenario(scenario, params)
    return _WORKER["mp"]


def _ask(q: tuple[str, tuple[str, ...]]):
    o, removed = q
    a = _WORKER["mp"].feasibility(o, frozenset(removed))
    return o, removed, int(a.label), a.planning_time, a.attempts


def _removable(table: FeasibilityTable):
    """removable(o, s) for reachable.py: the table holds an OBSTACLE answer (feasible removal) for (o, s)."""
    return lambda o, s: table.get(o, s) == Label.OBSTACLE


def reachable_sets(table: FeasibilityTable, scenario) -> list[frozenset[str]]:
    """Sets reachable from {} by feasible removals, as far as the table knows, sorted by (size, members)."""
    return sorted(reachable.reachable_sets(scenario.obstacle_ids, _removable(table)),
                  key=lambda s: (len(s), sorted(s)))


def _ask_oracle(oracle, todo):
    """A level's questions through a BatchOracle (planner replicas over ROS: relocation_app.evaluation.replica_fill)."""
    qs = [(o, frozenset(r)) for o, r in todo]
    return [(o, r, int(a.label), a.planning_time, a.attempts) for (o, r), a in zip(todo, ask_many(oracle, qs))]


def fill_reachable(scenario, params, table: FeasibilityTable, workers: int = 2, progress: bool = True,
                   save_to: str | Path | None = None, max_queries: int | None = None, oracle=None) -> dict:
    """Ask the real planner every (object, S) for every reachable S not yet in the table. Level-synchronous BFS;
    the queries of a level go to `workers` processes (each its own MotionPlanner), or, with `oracle` given, to
    that oracle all at once (relocation_common.feasibility.ask_many: motion planner replicas keep one each in
    flight). Saves after each level when `save_to` is given (so an interruption keeps what was computed).
    Returns {'real_calls', 'seconds', 'sets'}."""
    t0 = time.perf_counter()
    calls = 0
    pool = None
    try:
        level: list[frozenset] = [frozenset()]
        reached: dict[frozenset, tuple[str, ...]] = {frozenset(): ()}
        removable = _removable(table)
        while level:
            todo = [(o, tuple(sorted(s))) for s in level for o in scenario.ids
                    if o not in s and table.get(o, s) is None]
            if max_queries is not None:
                todo = todo[:max(0, max_queries - calls)]
            if todo:
                if oracle is not None:
                    answers = _ask_oracle(oracle, todo)
                elif workers > 1 and len(todo) > 8:
                    if pool is None:
                        import multiprocessing as mp
                        pool = mp.get_context("spawn").Pool(workers, _init_worker, (scenario, params))
                    answers = pool.imap_unordered(_ask, todo, chunksize=4)
                else:
                    _use_scenario(scenario, params)
                    answers = map(_ask, todo)
                for o, removed, lab, t, a in answers:
                    table.put(o, frozenset(removed), Label(lab), t, a)
                    table.planner_seconds += t
                    calls += 1
                if save_to is not None:
                    table.save(save_to)
            nxt = reachable.next_level(level, scenario.obstacle_ids, removable, reached)
            if progress:
                print(f"  fill {scenario.name}: level {len(level[0])}: {len(level)} sets, {len(todo)} planner calls, "
                      f"{time.perf_counter() - t0:.1f} s", flush=True)
            if max_queries is not None and calls >= max_queries:
                break
            level = nxt
    finally:
        if pool is not None:
            pool.close()
            pool.join()
    return {"real_calls": calls, "seconds": time.perf_counter() - t0, "sets": len(reached)}
