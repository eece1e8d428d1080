"""`qtree` command line: train/solve outputs (subprocess, the module as the installed `qtree` runs it), and one clear
line + exit status 2 on bad input (in-process through the same `main`, one case also as a subprocess: a process per
case cost about 1.5 s of imports each)."""
import contextlib
import io
import json
import re
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parent.parent
SC5 = ROOT / "config" / "scenarios" / "blocking_5.yaml"


def qtree(*args, cwd=ROOT):
    return subprocess.run([sys.executable, "-m", "relocation_app.cli", *map(str, args)], cwd=cwd,
                          capture_output=True, text=True, timeout=60)


def qtree_main(*args) -> subprocess.CompletedProcess:
    """`main(argv)` in this process, its exit status, stdout and stderr as a subprocess's would be."""
    from relocation_app.cli import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main([*map(str, args)])
        except SystemExit as e:  # argparse's own errors
            code = e.code if isinstance(e.code, int) else 1
    return subprocess.CompletedProcess(["qtree", *map(str, args)], code, out.getvalue(), err.getvalue())


def test_train_writes_json_and_dot(tmp_path):
    out, dot = tmp_path / "r.json", tmp_path / "tree.dot"
    p = qtree("train", "--scenario", SC5, "--policy", "h-eg", "--search", "breadth", "--max-episodes", 300,
              "--seed", 3, "--solve-first", "--json", out, "--tree-dot", dot)
    assert p.returncode == 0, p.stderr
    r = json.loads(out.read_text())
    assert r["sequence"] == ["o1", "o4", "T"] and r["total_weight"] == pytest.approx(0.76)
    assert r["params"]["seed"] == 3 and r["params"]["search"] == "breadth"
    assert r["exact"]["total_weight"] == pytest.approx(0.76) and r["E_1st"] >= 1
    assert len(r["q_sum_history"]) == r["episodes"] and r["MP_q"] >= r["planner_calls"] > 0
    text = dot.read_text()
    assert text.startswith("digraph blocking_5 {") and text.count(" -> ") == r["tree_edges"]


def test_train_to_stdout_with_progress_on_stderr():
    p = qtree("train", "--scenario", SC5, "--max-episodes", 50, "--beta", 0)
    assert p.returncode == 0, p.stderr
    assert json.loads(p.stdout)["episodes"] == 50 and "Traceback" not in p.stderr


def test_progress_in_a_log_is_a_line_every_few_seconds_not_one_per_update():
    """stderr piped (not a terminal): the progress is plain lines at most every LOG_INTERVAL_S seconds and one at the
    end (the old tqdm bar wrote an update every 0.1 s: dozens of them in a CI or launch log)."""
    from relocation_app.progress import LOG_INTERVAL_S
    sc15 = ROOT / "config" / "scenarios" / "blocking_15.yaml"
    t0 = time.monotonic()
    p = qtree("train", "--scenario", sc15, "--policy", "lrnd", "--search", "depth", "--max-episodes", 8000,
              "--beta", 0)
    wall = time.monotonic() - t0
    assert p.returncode == 0, p.stderr
    progress = [seg for seg in re.split(r"[\r\n]", p.stderr) if seg.strip() and not seg.startswith("qtree:")]
    assert len(progress) <= 1 + wall / LOG_INTERVAL_S, progress
    assert progress[-1].startswith("episodes: 8000/8000 ep q_sum=")


def test_solve():
    p = qtree("solve", "--scenario", SC5)
    assert p.returncode == 0, p.stderr
    r = json.loads(p.stdout)
    assert r["sequence"] == ["o1", "o4", "T"] and r["oracle_calls"] > 0


def write_scenario(tmp_path, mutate):
    data = yaml.safe_load(SC5.read_text())
    mutate(data)
    f = tmp_path / "bad.yaml"
    f.write_text(yaml.safe_dump(data))
    return f


def _dup(d):
    d["objects"][1]["id"] = "o1"


def _unknown(d):
    d["blocking"]["T"] = ["o99"]


def _weight(d):
    d["objects"][0]["weight"] = 1.5


def _no_target(d):
    del d["target"]


def _no_blocking(d):
    del d["blocking"]


@pytest.mark.parametrize("mutate, expect", [
    (_dup, "duplicate id"), (_unknown, "blocking[T]"), (_weight, "weight must be in (0, 1]"),
    (_no_target, "target: missing"), (_no_blocking, "no 'blocking:' section")])
def test_bad_scenarios_get_one_line(tmp_path, mutate, expect):
    p = qtree_main("train", "--scenario", write_scenario(tmp_path, mutate), "--oracle", "blocking", "--no-progress")
    assert p.returncode == 2 and p.stdout == ""
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("qtree: error:") and expect in lines[0], p.stderr


@pytest.mark.parametrize("args, expect", [
    (["--alpha", "1.5"], "alpha must be in [0.0, 1.0]"),
    (["--gamma", "-0.2"], "gamma must be in [0.0, 1.0]"),
    (["--max-episodes", "-5"], "max_episodes must be >= 1"),
    (["--max-steps", "-1"], "max_steps must be >= 1"),
    (["--beta", "-1"], "beta must be in"),
    (["--policy", "greedy"], "invalid choice"),
    (["--alpha", "abc"], "invalid float value"),
    (["--params", "/nonexistent.yaml"], "cannot read parameters file"),
])
def test_bad_arguments_get_one_line(args, expect):
    p = qtree_main("train", "--scenario", SC5, *args)
    lines = p.stderr.strip().splitlines()
    assert p.returncode == 2 and len(lines) == 1 and lines[0].startswith("qtree: error:")
    assert expect in lines[0], p.stderr


def test_malformed_yaml_and_missing_file(tmp_path):
    f = tmp_path / "m.yaml"
    f.write_text("objects: [\n  - {id: a\n")
    for path, expect in ((f, "malformed YAML"), (tmp_path / "none.yaml", "cannot read scenario file")):
        p = qtree_main("solve", "--scenario", path)
        lines = p.stderr.strip().splitlines()
        assert p.returncode == 2 and len(lines) == 1 and expect in lines[0], p.stderr


def test_bad_input_from_the_command_exits_2_with_one_line():
    """The same checks as above through the process (the exit status is the interpreter's, not main's return)."""
    for args, expect in ((["train", "--scenario", SC5, "--beta", "-1"], "beta must be in"),
                         (["train", "--scenario", SC5, "--policy", "greedy"], "invalid choice")):
        p = qtree(*args)
        lines = p.stderr.strip().splitlines()
        assert p.returncode == 2 and p.stdout == "" and len(lines) == 1 and lines[0].startswith("qtree: error:"), p
        assert expect in lines[0], p.stderr
