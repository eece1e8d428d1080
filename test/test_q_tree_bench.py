"""A tiny run of scripts/bench_qtree.py: checks what it measures, never its speed."""
import importlib.util
from pathlib import Path

import pytest

from relocation_common.paths import scenarios_dir
from relocation_common.scenario import load_scenario

spec = importlib.util.spec_from_file_location(
    "bench_qtree", Path(__file__).resolve().parent.parent / "scripts" / "bench_qtree.py")
bench = importlib.util.module_from_spec(spec)
spec.loader.exec_module(bench)


@pytest.mark.bench
def test_bench_qtree_tiny():
    sc = load_scenario(scenarios_dir() / "blocking_15.yaml")
    rows = bench.throughput(sc, seeds=1, episodes=30)
    assert len(rows) == 12 and all(r["eps"] > 0 and r["mpq"] >= r["calls"] for r in rows)
    e = bench.exact(sc)
    assert e["weight"] == pytest.approx(1.09) == pytest.approx(e["brute_weight"])
    assert 0 < e["calls"] < e["brute_calls"]
