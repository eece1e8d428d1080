"""SIGTERM to the task planner while it trains through the feasibility service (over real DDS, the motion planner
played by test_reliability_task_planner's fake): exit 0 without a traceback, and the checkpoint says why training
stopped (docs/reliability.md, "Never report success that is not true")."""
import signal
import time

import pytest
from ros_procs import RosGraph
from test_reliability_task_planner import SEED, Env, _payload, _wait

from qtree_task_planner.task_planner_node import train_goal

pytestmark = pytest.mark.graph


def test_sigterm_mid_training_exits_0_without_a_traceback_and_the_checkpoint_says_so(tmp_path):
    """Old code, 7 of 7 stops mid-training: 'RCLError: failed to check service availability: rcl node's context
    is invalid' with a traceback, saved as the checkpoint's reason."""
    with RosGraph(tmp_path) as g:
        env = Env(g)
        ck = tmp_path / "qtree.ckpt"
        env.fake(delay=0.02)  # each answer takes a moment: the stop comes while a query is pending
        tp = env.task_planner(checkpoint_path=str(ck), checkpoint_every=1000)
        env.scene()
        _wait(lambda: env.client.wait_for_server(timeout_sec=0.2), 30, "train action never appeared", tp)
        feedback = []
        env.client.send_goal_async(train_goal(seed=SEED, execute=False),
                                   feedback_callback=lambda f: feedback.append(f.feedback))
        _wait(lambda: any(f.phase == "training" and f.episode >= 2 for f in feedback), 60, "no training", tp)
        time.sleep(0.3)
        assert tp.stop(signal.SIGTERM, timeout=15) == 0, tp.log()[-3000:]
        log = tp.log()
        assert "Traceback" not in log and "RCLError" not in log, log[-3000:]
        reason = _payload(ck).get("reason", "")
        assert "stopped by the user (SIGTERM)" in reason, reason
