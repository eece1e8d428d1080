"""`colcon build` gives the `ros2 run` layout, and the installed executables run from anywhere.

The package is built by colcon from a copy of the checkout; each installed executable is then started from an
empty working directory with only the install space on PYTHONPATH (no source tree), as `ros2 run` would start it,
and must serve its interfaces: configuration and scenarios come from share/qtree_relocation through the ament index.
"""
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
EXES = ("task_planner", "motion_planner", "jaco2_sim_driver", "perception", "qtree")


@pytest.fixture(scope="module")
def install(tmp_path_factory):
    ws = tmp_path_factory.mktemp("ws")
    src = ws / "src" / "qtree_relocation"
    files = subprocess.run(["git", "ls-files", "--cached", "--others", "--exclude-standard"], cwd=ROOT,
                           capture_output=True, text=True, check=True).stdout.split()
    for f in files:
        if f.startswith(("msg_defs/", "test/")) or not (ROOT / f).is_file():
            continue  # the interface packages are built into the venv by the setup script
        (src / f).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(ROOT / f, src / f)
    colcon = Path(sys.executable).parent / "colcon"
    r = subprocess.run([str(colcon), "build", "--packages-select", "qtree_relocation"], cwd=ws,
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
    return ws / "install" / "qtree_relocation"


def installed_env(install: Path) -> dict:
    """Only the install space on PYTHONPATH (never the checkout), the package in the ament index."""
    site = next((install / "lib").glob("python3*/site-packages"))
    return {"PYTHONPATH": str(site), "AMENT_PREFIX_PATH": f"{install}:{sys.prefix}"}


def test_ros2_run_layout(install):
    for exe in EXES:
        assert os.access(install / "lib" / "qtree_relocation" / exe, os.X_OK), exe
    assert (install / "share" / "ament_index" / "resource_index" / "packages" / "qtree_relocation").is_file()
    assert (install / "share" / "qtree_relocation" / "package.xml").is_file()
    for cfg in ("task_planner", "motion_planner", "jaco2_sim_driver", "perception", "arm_interface"):
        assert (install / "share" / "qtree_relocation" / "config" / f"{cfg}.yaml").is_file()
    assert (install / "share" / "qtree_relocation" / "config" / "fastdds.xml").is_file()  # the graph's DDS profile
    scen = install / "share" / "qtree_relocation" / "config" / "scenarios"
    assert (scen / "paper_experiment_10.yaml").is_file()
    for d in ("random5", "paper_random5", "world"):  # the Table 4 sets, the shelf as it is (--scenario random5_00)
        assert sorted(p.name for p in (scen / d).glob("*.yaml")) == \
            sorted(p.name for p in (ROOT / "config" / "scenarios" / d).glob("*.yaml")), d


def test_the_installed_cli_runs_from_anywhere(install, tmp_path):
    env = dict(os.environ, **installed_env(install))
    r = subprocess.run([str(install / "lib" / "qtree_relocation" / "qtree"), "solve", "--scenario", "blocking_5"],
                       env=env, capture_output=True, text=True, timeout=60, cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert '"total_weight"' in r.stdout


@pytest.mark.graph
def test_every_installed_node_starts_from_an_empty_directory_and_serves(install, tmp_path):
    from qtree_relocation_msgs.action import TrainPlanner
    from qtree_relocation_msgs.srv import PlanFeasibility
    from ros_procs import RosGraph
    from sensor_msgs.msg import JointState

    from relocation_common.node import ActionClient  # rclpy#1123 fixed

    lib = install / "lib" / "qtree_relocation"
    cwd = tmp_path / "empty"
    cwd.mkdir()
    with RosGraph(tmp_path / "graph") as g:
        t0 = time.monotonic()
        procs = {name: g.start_argv([str(lib / name), "--ros-args", *args], name, installed_env(install), cwd)
                 for name, args in (("jaco2_sim_driver", ["-p", "camera_rate:=1.0"]), ("perception", []),
                                    ("motion_planner", ["-p", "scene_topic:=/sim/objects"]),
                                    ("task_planner", ["-p", "scene_source:=sim"]))}
        up = {}

        def wait(name, ready):
            deadline = time.monotonic() + 90
            while not ready():
                assert procs[name].alive(), f"{name} exited:\n{procs[name].log()[-2000:]}"
                assert time.monotonic() < deadline, f"{name} never served:\n{procs[name].log()[-2000:]}"
                time.sleep(0.1)
            up[name] = round(time.monotonic() - t0, 1)

        states = g.probe.collect("/j2s7s300_driver/out/joint_state", JointState)
        wait("jaco2_sim_driver", lambda: len(states.msgs) > 0)
        wait("perception", lambda: "perception" in g.probe.node.get_node_names())
        feas = g.probe.client(PlanFeasibility, "/motion_planner/plan_feasibility", timeout=90)
        up["motion_planner"] = round(time.monotonic() - t0, 1)
        g.probe.node.destroy_client(feas)
        res = g.probe.call(PlanFeasibility, "/motion_planner/plan_feasibility",
                           PlanFeasibility.Request(object_id="o2", timeout=5.0), timeout=30)
        assert res.ok, res.message
        train = ActionClient(g.probe.node, TrainPlanner, "/task_planner/train")
        wait("task_planner", lambda: train.wait_for_server(timeout_sec=0.1))
        print(f"\ninstalled executables serving after (s): {up}")
        for name, p in procs.items():
            assert p.stop() == 0, f"{name}:\n{p.log()[-2000:]}"
