"""Load (docs/reliability.md, section 6), the test-sized version of scripts/bench_reliability.py: 40 feasibility
requests (one in ten bad) from 4 concurrent client processes against the real motion_planner node. Every request is
answered: a label, or a refusal with a reason (all bad ones, no valid one); the node survives, its memory stays bounded,
it exits 0."""
import importlib.util

import pytest
from ros_procs import REPO

pytestmark = [pytest.mark.graph, pytest.mark.bench]


def _bench_module():
    spec = importlib.util.spec_from_file_location("bench_reliability", REPO / "scripts" / "bench_reliability.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_40_requests_from_4_clients_all_answered_or_refused_with_a_reason(tmp_path):
    bench = _bench_module()
    s = bench.bench(40, 4, seed=3, answer_timeout=60.0, run_dir=tmp_path)
    print(s)
    assert s["client_errors"] == [] and s["requests"] == 40
    assert s["answered"] == 40 and s["unanswered"] == 0
    assert s["refused_without_reason"] == 0
    assert s["bad_sent"] == 4 and s["bad_refused"] == 4 and s["good_refused"] == 0
    assert s["ok"] == 36 and s["labels"]["UNFEASIBLE"] + s["labels"]["OBSTACLE"] + s["labels"]["TARGET"] == 36
    assert any("unknown object id" in r for r in s["refusal_reasons"])
    assert s["planner_alive_after"] and s["planner_exit_code"] == 0
    rss = s["rss_kb"]
    assert 0 < rss["before"] <= rss["peak_sampled"] and rss["after"] - rss["before"] < 64 * 1024  # bounded


def test_bad_requests_are_spread_over_every_kind():
    bench = _bench_module()
    reqs = [r for c in range(4) for r in bench.requests_for(c, 100, ["o1", "o2", "o3", "T"], "T", 1)]
    bad = [r for r in reqs if bench.is_bad(r)]
    assert len(bad) == 40 and {r[0] for r in bad} >= {"ghost", "", "o1", "T", "o2"}
