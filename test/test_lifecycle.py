"""Nothing hangs, nothing is orphaned (docs/reliability.md, section 9): the demo under SIGTERM and SIGKILL, a killed
test harness.

Old code: SIGTERM to the demo hung it until its 900 s limit with the four nodes running (rclpy's handler only shut
the context down); after SIGKILL the nodes were re-parented to PID 1 and went on training. Now SIGTERM stops the
graph like Ctrl-C, and every node started by the launcher (or by the test harness) gets SIGTERM when its parent dies.
"""
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from ros_procs import REPO, VENV_PYTHON

from relocation_common.feasibility import default_replicas

pytestmark = pytest.mark.graph
PY = str(VENV_PYTHON if VENV_PYTHON.exists() else sys.executable)


def children(pid: int) -> list[int]:
    """Direct children of pid, from /proc."""
    out = []
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                if int((d / "stat").read_text().rsplit(")", 1)[1].split()[1]) == pid:
                    out.append(int(d.name))
            except (OSError, IndexError, ValueError):
                pass
    return out


def alive(pids) -> list[int]:
    left = []
    for p in pids:
        try:
            state = (Path("/proc") / str(p) / "stat").read_text().rsplit(")", 1)[1].split()[0]
            if state != "Z":
                left.append(p)
        except OSError:
            pass
    return left


def wait_gone(pids, timeout: float) -> float:
    t0 = time.monotonic()
    while alive(pids):
        if time.monotonic() - t0 > timeout:
            for p in alive(pids):  # never leak into later tests
                os.kill(p, signal.SIGKILL)
            raise AssertionError(f"processes {pids} still running {timeout} s after their parent went")
        time.sleep(0.1)
    return time.monotonic() - t0


def start_demo(tmp_path):
    log = open(tmp_path / "demo.log", "w")
    p = subprocess.Popen([PY, "-m", "relocation_app.demo", "--scenario", "scenario1_5", "--scene-source",
                          "ground_truth", "--no-execute", "--out", str(tmp_path / "out")], cwd=REPO, stdout=log,
                         stderr=subprocess.STDOUT, start_new_session=True)
    deadline = time.monotonic() + 120
    while "training" not in (tmp_path / "demo.log").read_text():
        if p.poll() is not None or time.monotonic() > deadline:
            p.kill()
            raise AssertionError("the demo never started training:\n" + (tmp_path / "demo.log").read_text()[-3000:])
        time.sleep(0.2)
    nodes = children(p.pid)
    # driver, motion planner and its feasibility replicas, task planner (ground truth: no perception)
    assert len(nodes) == 2 + default_replicas(), nodes
    return p, nodes


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGKILL], ids=["SIGTERM", "SIGKILL"])
def test_a_signalled_demo_leaves_no_node_running(tmp_path, sig):
    demo, nodes = start_demo(tmp_path)
    t0 = time.monotonic()
    demo.send_signal(sig)
    try:
        code = demo.wait(20)
    except subprocess.TimeoutExpired:
        demo.kill()
        wait_gone(nodes, 10)
        raise AssertionError(f"the demo did not exit within 20 s of {sig.name}")
    gone = wait_gone(nodes, 15)
    print(f"\n{sig.name}: demo exited with {code} after {time.monotonic() - t0 - gone:.2f} s, "
          f"its nodes gone {gone:.2f} s later")
    if sig == signal.SIGTERM:
        assert code in (130, 143, 1), code  # interrupted, the graph shut down
        assert "interrupted" in (tmp_path / "demo.log").read_text()


HARNESS = """
import sys, time
sys.path.insert(0, {test!r})
from ros_procs import RosGraph
g = RosGraph({tmp!r})
p = g.start("jaco2_sim_driver.driver_node", params={{"camera_rate": 0.0}})
print(p.pid, flush=True)
time.sleep(600)
"""


def test_a_killed_test_harness_leaves_no_node_running(tmp_path):
    """What `timeout` does to a hung test run: the harness dies without its teardown."""
    code = HARNESS.format(test=str(REPO / "test"), tmp=str(tmp_path / "g"))
    h = subprocess.Popen([PY, "-c", code], cwd=REPO, stdout=subprocess.PIPE, text=True, start_new_session=True)
    node = int(h.stdout.readline())
    time.sleep(2.0)
    assert alive([node])
    h.send_signal(signal.SIGKILL)
    h.wait(10)
    print(f"\nnode gone {wait_gone([node], 15):.2f} s after the harness was killed")
