"""Time to fill a scene's complete feasibility table from scratch (docs/benchmarks.md), side by side in one run:

- `replicas K`: through K motion planner processes over ROS (`python -m relocation_app.evaluation fill --replicas K`:
  the task planner's ReplicaOracle, one question in flight per replica);
- `local K`: K planner processes of this process's pool (the evaluation's default fill).

Each fill goes to a fresh temporary directory; the labels are compared with the committed table.

    .venv/bin/python scripts/bench_table_fill.py --scenario scenario3_15 [--modes replicas1,replicas2,local1,local2]
"""
from __future__ import annotations

import argparse
import sys
import tempfile
import time
from contextlib import nullcontext
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # this checkout's packages first

from relocation_app.evaluation.__main__ import planner_params
from relocation_app.evaluation.feasibility_cache import fill_reachable, open_table
from relocation_app.evaluation.replica_fill import replica_oracle
from relocation_common.paths import resolve_scenario
from relocation_common.scenario import load_scenario

REPO = Path(__file__).resolve().parent.parent


def fill(path: Path, mode: str) -> tuple[float, dict, object]:
    """(wall s, labels, oracle or None) of one fill in `mode` (replicasK | localK)."""
    kind, k = mode.rstrip("0123456789"), int(mode[len(mode.rstrip("0123456789")):])
    scenario, params = load_scenario(path), planner_params()
    table, _ = open_table(scenario, params, tempfile.mkdtemp(prefix="bench_fill_"))
    with replica_oracle(path, k, params.timeout) if kind == "replicas" else nullcontext() as oracle:
        t0 = time.perf_counter()  # planners started and seen: the fill only
        fill_reachable(scenario, params, table, workers=k, progress=False, oracle=oracle)
        wall = time.perf_counter() - t0
    return wall, {key: v[0] for key, v in table.entries.items()}, oracle


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="scenario3_15")
    ap.add_argument("--modes", default="replicas1,replicas2,local1,local2")
    a = ap.parse_args()
    path = resolve_scenario(a.scenario)
    scenario, params = load_scenario(path), planner_params()
    committed = {key: v[0] for key, v in open_table(scenario, params)[0].entries.items()}
    print(f"complete feasibility table of {scenario.name} from scratch ({len(committed)} answers committed)")
    walls = {}
    for mode in a.modes.split(","):
        wall, labels, oracle = fill(path, mode)
        walls[mode] = wall
        same = sum(labels.get(key) == v for key, v in committed.items())
        spread = f"; {oracle.summary()}" if oracle is not None else ""
        print(f"  {mode}: {len(labels)} answers in {wall:.1f} s ({len(labels) / wall:.1f}/s), "
              f"{same} labels equal to the committed table{spread}", flush=True)
    for one, two in (("replicas1", "replicas2"), ("local1", "local2")):
        if one in walls and two in walls:
            print(f"  {two} / {one}: {walls[one] / walls[two]:.2f}x faster")


if __name__ == "__main__":
    main()
