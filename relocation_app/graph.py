"""Start the node graph as separate processes (what `ros2 launch` does where launch_ros exists).

Each node runs as `python -m <module> --ros-args --params-file config/<node>.yaml -p k:=v` in its own process,
on a private ROS_DOMAIN_ID with discovery limited to the loopback, logs under the run directory. Used by the
demo, the benchmarks and the graph tests. Stop with Ctrl-C: every node gets SIGINT, then SIGKILL after a grace
period. Each node gets SIGTERM when the process that started it dies (Linux parent-death signal), so a killed
launcher leaves no node behind.
"""
from __future__ import annotations

import ctypes
import os
import signal
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

from relocation_common.paths import config_file, python_path

# node name -> (module with main(), parameter file)
NODES = {
    "jaco2_sim_driver": ("jaco2_sim_driver.driver_node", "jaco2_sim_driver.yaml"),
    "perception": ("perception_aruco.perception_node", "perception.yaml"),
    "motion_planner": ("stpik_motion_planner.motion_planner_node", "motion_planner.yaml"),
    "task_planner": ("qtree_task_planner.task_planner_node", "task_planner.yaml"),
}


def private_domain_id() -> int:
    """QTREE_DOMAIN_ID if set (tests reserve one), else one unlikely to collide with other runs on this machine
    (0..101 are valid with the default ports)."""
    if os.environ.get("QTREE_DOMAIN_ID"):
        return int(os.environ["QTREE_DOMAIN_ID"])
    return 10 + os.getpid() % 90


def ros_env(domain_id: int, run_dir: Path) -> dict[str, str]:
    env = dict(os.environ)
    env.update(
        ROS_DOMAIN_ID=str(domain_id),
        ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
        ROS_HOME=str(run_dir / "ros_home"),
        ROS_LOG_DIR=str(run_dir / "ros_log"),
        MUJOCO_GL=env.get("MUJOCO_GL", "egl"),
        PYTHONUNBUFFERED="1",
        PYTHONPATH=os.pathsep.join(filter(None, [str(python_path()), env.get("PYTHONPATH")])),
    )
    return env


def die_with_parent() -> None:
    """preexec_fn: SIGTERM to this child when its parent dies (prctl PR_SET_PDEATHSIG; Linux only)."""
    try:
        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGTERM)  # 1 = PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass


def param_arg(v) -> str:
    """A parameter value as `-p name:=value` text (YAML: strings in lists quoted)."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (list, tuple)):
        return "[" + ",".join(param_arg(x) if not isinstance(x, str) else f"'{x}'" for x in v) + "]"
    return str(v)


@dataclass
class Graph:
    """A set of node processes sharing one private domain. Use as a context manager."""

    run_dir: Path
    domain_id: int = field(default_factory=private_domain_id)
    procs: dict[str, subprocess.Popen] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.run_dir = Path(self.run_dir)
        (self.run_dir / "logs").mkdir(parents=True, exist_ok=True)
        self.env = ros_env(self.domain_id, self.run_dir)

    def start(self, name: str, params: dict | None = None, params_file: Path | None = None) -> subprocess.Popen:
        module, cfg = NODES[name]
        cmd = [sys.executable, "-m", module, "--ros-args", "--params-file", str(params_file or config_file(cfg))]
        for k, v in (params or {}).items():
            cmd += ["-p", f"{k}:={param_arg(v)}"]
        log = open(self.run_dir / "logs" / f"{name}.log", "w")
        self.procs[name] = subprocess.Popen(cmd, env=self.env, stdout=log, stderr=subprocess.STDOUT,
                                            stdin=subprocess.DEVNULL, cwd=self.run_dir,
                                            preexec_fn=die_with_parent)
        log.close()
        return self.procs[name]

    def log(self, name: str) -> str:
        return (self.run_dir / "logs" / f"{name}.log").read_text(errors="replace")

    def check_alive(self) -> None:
        """Raise RuntimeError naming any node that died, with the end of its log."""
        for name, p in self.procs.items():
            if p.poll() is not None:
                raise RuntimeError(f"node {name} exited with {p.returncode}:\n{self.log(name)[-3000:]}")

    def stop(self, name: str, sig: int = signal.SIGINT, grace: float = 5.0) -> int:
        p = self.procs.pop(name)
        if p.poll() is None:
            p.send_signal(sig)
            try:
                p.wait(grace)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()
        return p.returncode

    def stop_all(self, grace: float = 5.0) -> dict[str, int]:
        for p in self.procs.values():
            if p.poll() is None:
                p.send_signal(signal.SIGINT)
        deadline = time.monotonic() + grace
        codes = {}
        for name in list(self.procs):
            p = self.procs[name]
            try:
                p.wait(max(0.1, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()
            codes[name] = p.returncode
        self.procs.clear()
        return codes

    def __enter__(self) -> "Graph":
        return self

    def __exit__(self, *exc) -> None:
        self.stop_all()


def wait_for_interfaces(node, services=(), actions=(), timeout: float = 60.0, graph: Graph | None = None) -> None:
    """Block until every service (name, type) and action client given is available; RuntimeError on timeout."""
    deadline = time.monotonic() + timeout
    clients = [node.create_client(t, n) for n, t in services]
    pending = [(f"service {c.srv_name}", c.wait_for_service) for c in clients]
    pending += [(f"action {a._action_name}", a.wait_for_server) for a in actions]
    for what, wait in pending:
        while not wait(timeout_sec=0.2):
            if graph is not None:
                graph.check_alive()
            if time.monotonic() > deadline:
                raise RuntimeError(f"{what} not available after {timeout:.0f} s")
    for c in clients:
        node.destroy_client(c)
