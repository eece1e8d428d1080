"""Run real ROS 2 node processes in tests (no launch_ros wheel: docs/install.md, "Platform notes") and talk to
them over DDS.

    with RosGraph(tmp_path) as g:
        g.start("jaco2_sim_driver.driver_node", params_file="config/jaco2_sim_driver.yaml",
                params={"real_time_factor": 1.0})
        states = g.probe.collect("/joint_states", JointState)
        states.wait(lambda msgs: len(msgs) >= 5, timeout=20)
        g.probe.call(Trigger, "/j2s7s300_driver/in/home", Trigger.Request())

Isolation: every graph gets its own ROS_DOMAIN_ID (reserved with a lock file, so parallel test runs never share
one), discovery on loopback only (ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST), and ROS_HOME / ROS_LOG_DIR under the
test's tmp dir. The test side is a `Probe`: a node in a private rclpy Context spun by a background thread.
Teardown: SIGINT, wait, then SIGKILL as a fallback; `stop()` returns the exit code so a test can check that a node
exits cleanly. Nodes are started with the launcher's parent-death signal (relocation_app.graph.die_with_parent):
a test run killed by `timeout` or SIGKILL leaves no node behind. Environment and parameter text come from the
launcher too (one formatter for both).
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any, Callable

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # this checkout's packages first
from relocation_app import graph
from relocation_app.graph import die_with_parent, param_arg, ros_env

REPO = Path(__file__).resolve().parent.parent
VENV_PYTHON = REPO / ".venv" / "bin" / "python"


def domains_in_use() -> set[int]:
    """graph.domains_in_use; a test may narrow what counts as free by replacing this function."""
    return graph.domains_in_use()


def reserve_domain_id() -> tuple[int, Path]:
    """graph.reserve_domain_id, minus the domains `domains_in_use` (this module's) reports."""
    return graph.reserve_domain_id(domains_in_use())


class NodeProcess:
    """One node started as `python -m module --ros-args ...`; stdout+stderr go to a log file."""

    def __init__(self, argv: list[str], env: dict[str, str], log_path: Path, cwd: Path | None = None):
        self.argv, self.log_path = argv, log_path
        self._log = open(log_path, "wb")
        self.popen = subprocess.Popen(argv, env=env, cwd=cwd or REPO, stdout=self._log, stderr=subprocess.STDOUT,
                                      start_new_session=True, preexec_fn=die_with_parent)

    @property
    def pid(self) -> int:
        return self.popen.pid

    def alive(self) -> bool:
        return self.popen.poll() is None

    def log(self) -> str:
        if not self._log.closed:
            self._log.flush()
        return self.log_path.read_text(errors="replace")

    def send_signal(self, sig: int) -> None:
        if self.alive():
            self.popen.send_signal(sig)

    def stop(self, sig: int = signal.SIGINT, timeout: float = 10.0) -> int:
        """Send `sig` (SIGINT by default), wait up to timeout, then SIGKILL. Returns the exit code."""
        if self.alive():
            self.popen.send_signal(sig)
            try:
                self.popen.wait(timeout)
            except subprocess.TimeoutExpired:
                self.popen.kill()
                self.popen.wait(5)
        self._log.close()
        return self.popen.returncode


class Collector:
    """Messages of one topic received by the probe, with their receive times (time.monotonic())."""

    def __init__(self):
        self.msgs: list[Any] = []
        self.times: list[float] = []
        self._cond = threading.Condition()

    def _on(self, msg) -> None:
        with self._cond:
            self.msgs.append(msg)
            self.times.append(time.monotonic())
            self._cond.notify_all()

    def wait(self, predicate: Callable[[list], bool] = lambda m: len(m) > 0, timeout: float = 10.0) -> list:
        """Block until predicate(msgs) holds; return a copy of the messages. TimeoutError otherwise."""
        deadline = time.monotonic() + timeout
        with self._cond:
            while not predicate(self.msgs):
                left = deadline - time.monotonic()
                if left <= 0:
                    raise TimeoutError(f"condition not met within {timeout} s ({len(self.msgs)} messages)")
                self._cond.wait(left)
            return list(self.msgs)

    def timed(self) -> list[tuple[float, Any]]:
        """(receive time, message) of every message so far."""
        with self._cond:
            return list(zip(self.times, self.msgs))

    def clear(self) -> None:
        with self._cond:
            self.msgs.clear()
            self.times.clear()

    def latest(self):
        with self._cond:
            return self.msgs[-1] if self.msgs else None


class Probe:
    """The test's own node (private Context, background executor thread)."""

    def __init__(self, domain_id: int, name: str = "test_probe"):
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        self._rclpy = rclpy
        self.context = rclpy.Context()
        from rclpy.signals import SignalHandlerOptions
        rclpy.init(context=self.context, domain_id=domain_id, signal_handler_options=SignalHandlerOptions.NO)
        self.node = rclpy.create_node(name, context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self._thread = threading.Thread(target=self._spin, daemon=True)
        self._thread.start()

    def _spin(self) -> None:
        try:
            self.executor.spin()
        except Exception:  # context shut down under us
            if self.context.ok():
                raise

    def collect(self, topic: str, msg_type, qos: Any = 10) -> Collector:
        c = Collector()
        self.node.create_subscription(msg_type, topic, c._on, qos)
        return c

    def publisher(self, msg_type, topic: str, qos: Any = 10):
        return self.node.create_publisher(msg_type, topic, qos)

    def wait_for_subscribers(self, publisher, count: int = 1, timeout: float = 10.0) -> None:
        deadline = time.monotonic() + timeout
        while publisher.get_subscription_count() < count:
            if time.monotonic() > deadline:
                raise TimeoutError(f"no subscriber on {publisher.topic_name} within {timeout} s")
            time.sleep(0.02)

    def client(self, srv_type, name: str, timeout: float = 10.0):
        cli = self.node.create_client(srv_type, name)
        if not cli.wait_for_service(timeout_sec=timeout):
            raise TimeoutError(f"service {name} not available within {timeout} s")
        return cli

    def call(self, srv_type, name: str, request=None, timeout: float = 10.0):
        """Blocking service call (the background thread spins the response in)."""
        cli = self.client(srv_type, name, timeout)
        future = cli.call_async(request if request is not None else srv_type.Request())
        done = threading.Event()
        future.add_done_callback(lambda _: done.set())
        if not done.wait(timeout):
            raise TimeoutError(f"service {name} did not answer within {timeout} s")
        self.node.destroy_client(cli)
        return future.result()

    def close(self) -> None:
        self.executor.shutdown(timeout_sec=1.0)
        try:
            self.node.destroy_node()
        finally:
            if self.context.ok():
                self._rclpy.shutdown(context=self.context)
        self._thread.join(timeout=5)


class RosGraph:
    """Context manager: a private domain, node processes, and a probe node; everything torn down on exit."""

    def __init__(self, tmp_dir: str | Path, python: str | Path | None = None):
        self.tmp = Path(tmp_dir)
        self.tmp.mkdir(parents=True, exist_ok=True)
        self.python = str(python or (VENV_PYTHON if VENV_PYTHON.exists() else sys.executable))
        self.domain_id, self._lock = reserve_domain_id()
        self.env = ros_env(self.domain_id, self.tmp)
        self.env["RCUTILS_LOGGING_BUFFERED_STREAM"] = "0"
        self.procs: list[NodeProcess] = []
        self._saved = {k: os.environ.get(k) for k in ("ROS_AUTOMATIC_DISCOVERY_RANGE", "ROS_HOME", "ROS_LOG_DIR")}
        for k in self._saved:  # the probe lives in this process: same discovery settings
            os.environ[k] = self.env[k]
        self.probe = Probe(self.domain_id)

    def start(self, module: str, *, params_file: str | Path | None = None, params: dict | None = None,
              ros_args: tuple[str, ...] = (), name: str | None = None) -> NodeProcess:
        """Start `python -m module --ros-args [--params-file f] [-p k:=v ...] [ros_args]`."""
        argv = [self.python, "-m", module, "--ros-args"]
        if params_file is not None:
            argv += ["--params-file", str(params_file)]
        for k, v in (params or {}).items():
            argv += ["-p", f"{k}:={param_arg(v)}"]
        argv += list(ros_args)
        return self.start_argv(argv, name or module.rsplit('.', 1)[-1])

    def start_argv(self, argv: list[str], name: str, env: dict | None = None, cwd: Path | None = None) -> NodeProcess:
        """Start any command (an installed executable) in this graph's domain."""
        p = NodeProcess(argv, {**self.env, **(env or {})}, self.tmp / f"{name}_{len(self.procs)}.log", cwd)
        self.procs.append(p)
        return p

    def relocate_client(self, driver: NodeProcess, planner: NodeProcess, timeout: float = 60.0) -> Any:
        """The probe's ActionClient of the motion planner's RelocateObject, once its server is there (the driver and
        the planner alive meanwhile: else their logs)."""
        from qtree_relocation_msgs.action import RelocateObject

        from relocation_common.node import ActionClient

        client = ActionClient(self.probe.node, RelocateObject, "/motion_planner/relocate")
        deadline = time.monotonic() + timeout
        while not client.wait_for_server(timeout_sec=0.5):
            assert planner.alive and driver.alive, planner.log()[-2000:] + driver.log()[-2000:]
            assert time.monotonic() < deadline, "relocate action never appeared"
        return client

    def close(self) -> None:
        try:
            for p in reversed(self.procs):
                p.stop()
        finally:
            self.probe.close()
            for k, v in self._saved.items():
                if v is None:
                    os.environ.pop(k, None)
                else:
                    os.environ[k] = v
            self._lock.unlink(missing_ok=True)

    def __enter__(self) -> "RosGraph":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def main_in_process(main: Callable[[list[str]], None], ros_args: list[str], capfd: Any, tmp: Path,
                    timeout: float = 60.0) -> tuple[Any, list[str]]:
    """Call a node's `main` with `--ros-args ros_args` in this process, for a start that must fail before the node
    serves: (its exit status, the non-empty lines it wrote to stdout and stderr, read from the file descriptors).
    That is the code `python -m <node> --ros-args ...` runs after its imports, in a domain of its own; a process
    costs 1.5-1.9 s of CPU in imports, this 0.02-0.16 s. One start per node stays a process (the tests that use
    this), for what only a process shows: its imports' and rcl's own output, its exit. A start that does not fail
    is shut down after `timeout` s (rclpy's context, from a timer thread): status 0, the test's assertion then says
    so instead of waiting for pytest's own timeout."""
    import rclpy

    domain, lock = reserve_domain_id()
    saved = {k: os.environ.get(k) for k in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE", "ROS_HOME",
                                            "ROS_LOG_DIR")}
    os.environ.update({k: v for k, v in ros_env(domain, tmp).items() if k in saved})
    capfd.readouterr()
    guard = threading.Timer(timeout, rclpy.try_shutdown)
    guard.start()
    try:
        main(["main_in_process", "--ros-args", *ros_args])
        status: Any = 0
    except SystemExit as e:
        status = e.code
    finally:
        guard.cancel()
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
        lock.unlink(missing_ok=True)
    out = capfd.readouterr()
    return status, [ln for ln in (out.out + out.err).splitlines() if ln.strip()]


def planner_has_scene(probe: "Probe", timeout: float = 60.0) -> None:
    """Wait until the task planner's /diagnostics say it has a scene (ros_clients.goal_health's "scene" value), as
    the demo does before its goal: the test's own subscription having a scene does not mean the planner's has one
    (a goal sent then was refused "no scene received" after scene_wait). TimeoutError otherwise."""
    from diagnostic_msgs.msg import DiagnosticArray

    from qtree_task_planner.ros_clients import GOAL_STATUS, SCENE_NONE

    def has_scene(msgs: list) -> bool:
        return any(st.name == GOAL_STATUS and any(kv.key == "scene" and kv.value != SCENE_NONE for kv in st.values)
                   for m in msgs for st in m.status)
    probe.collect("/diagnostics", DiagnosticArray).wait(has_scene, timeout)


def future_result(fut: Any, timeout: float, what: str = "no result") -> Any:
    """An rclpy future's result, waited for at most `timeout` s (AssertionError `what` when it does not come)."""
    done = threading.Event()
    fut.add_done_callback(lambda _: done.set())
    assert done.wait(timeout), what
    return fut.result()


def load_script(name: str):
    """A script of scripts/ (not a package) imported as module `name`, e.g. load_script("bench_chaos")."""
    import importlib.util

    spec = importlib.util.spec_from_file_location(name, REPO / "scripts" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module
