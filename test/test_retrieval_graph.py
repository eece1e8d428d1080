"""The main job end to end: the demo command on a 5-obstacle scenario through the four node processes over DDS
(sim driver, perception, motion planner, task planner), checked against the simulator's ground truth."""
import json
import os
import subprocess
import sys

import pytest
from ros_procs import REPO, reserve_domain_id

from relocation_common.scenario import load_scenario

pytestmark = [pytest.mark.graph, pytest.mark.slow]

SCENARIO = REPO / "config" / "scenarios" / "scenario1_5.yaml"


def test_demo_retrieves_the_target_of_a_five_obstacle_scene(tmp_path):
    domain, lock = reserve_domain_id()
    try:
        cmd = [sys.executable, "-m", "relocation_app.demo", "--scenario", str(SCENARIO),
               "--out", str(tmp_path), "--seed", "1", "--timeout", "600", "--no-record"]  # test_recording records
        env = dict(os.environ, QTREE_DOMAIN_ID=str(domain))
        proc = subprocess.run(cmd, cwd=REPO, env=env, capture_output=True, text=True, timeout=900)
    finally:
        lock.unlink(missing_ok=True)
    logs = "\n".join(p.read_text(errors="replace")[-1500:] for p in (tmp_path / "run" / "logs").glob("*.log"))
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:] + logs
    report = json.loads((tmp_path / "report.json").read_text())
    scenario = load_scenario(SCENARIO)
    assert report["success"], report["message"]
    seq = report["learned_sequence"]
    assert seq[-1] == scenario.target_id and len(set(seq)) == len(seq)
    assert report["learned_weight"] == pytest.approx(sum(scenario.weights[o] for o in seq[:-1]))
    assert report["learned_weight"] >= report["optimal_weight"] - 1e-9  # the exact optimum is a lower bound
    final = report["final_scene"]
    assert final["target_on_bottom_shelf"]
    assert all(final["relocated_on_bottom_shelf"].values()), final
    assert final["max_displacement_untouched_m"] < 0.01  # bottles not in the sequence stay where they were
    assert (tmp_path / "learning_curve.png").stat().st_size > 1000
    assert (tmp_path / "retrieval_strip.png").stat().st_size > 1000
    assert "learned sequence" in proc.stdout and "exact optimum" in proc.stdout
