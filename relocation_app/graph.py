"""Start the node graph as separate processes (what `ros2 launch` does where launch_ros exists).

Each node runs as `python -m <module> --ros-args --params-file config/<node>.yaml -p k:=v` in its own process,
on a private ROS_DOMAIN_ID with discovery limited to the loopback, logs under the run directory. Used by the
demo, the benchmarks and the graph tests. Stop with Ctrl-C: every node gets SIGINT, then SIGKILL after a grace
period. Each node gets SIGTERM when the process that started it dies (Linux parent-death signal), so a killed
launcher leaves no node behind.

With `respawn=True` (the demo, the chaos benchmark) a node that dies is started again with the same command after
`respawn_delay` s, at most `max_respawns` times, as launch_ros's `respawn` does: config/graph.yaml, per node (the
launch file reads the same). Each death and restart is logged and kept in `events` (for the report); `check_alive`
raises NodeDied only for a node that is not coming back. Without it (the tests) any death raises at once.
"""
from __future__ import annotations

import ctypes
import os
import random
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

from relocation_common.arm_interface import ArmInterface
from relocation_common.config import ConfigError, node_section, read_yaml
from relocation_common.feasibility import default_replicas, replica_namespace
from relocation_common.node import RESPAWN_ENV
from relocation_common.paths import config_file, python_path

# node name -> (module with main(), parameter file)
NODES = {
    "jaco2_sim_driver": ("jaco2_sim_driver.driver_node", "jaco2_sim_driver.yaml"),
    "perception": ("perception_aruco.perception_node", "perception.yaml"),
    "motion_planner": ("stpik_motion_planner.motion_planner_node", "motion_planner.yaml"),
    "task_planner": ("qtree_task_planner.task_planner_node", "task_planner.yaml"),
}
ARM_NODES = ("jaco2_sim_driver", "motion_planner", "perception")  # they read config/arm_interface.yaml, must agree


LOCK_DIR = Path(tempfile.gettempdir()) / "ros_domain_locks"
SUPERVISE_PERIOD = 0.2  # s between looks at the node processes (respawn)


@dataclass(frozen=True)
class Respawn:
    """How a node that dies is restarted (config/graph.yaml; launch_ros's respawn, respawn_delay; launch's
    respawn_max_retries as max_respawns)."""

    respawn: bool
    respawn_delay: float
    max_respawns: int

    def __post_init__(self) -> None:
        if not isinstance(self.respawn, bool):
            raise ConfigError(f"config/graph.yaml: respawn must be true or false, got {self.respawn!r}")
        if isinstance(self.respawn_delay, bool) or not isinstance(self.respawn_delay, (int, float)) \
                or not 0 <= self.respawn_delay < 3600:
            raise ConfigError(f"config/graph.yaml: respawn_delay must be 0..3600 s, got {self.respawn_delay!r}")
        if isinstance(self.max_respawns, bool) or not isinstance(self.max_respawns, int) or self.max_respawns < 0:
            raise ConfigError(f"config/graph.yaml: max_respawns must be an integer >= 0, got {self.max_respawns!r}")


def respawn_policies(path: Path | None = None) -> dict[str, Respawn]:
    """node name -> Respawn, from config/graph.yaml (every node of NODES; ConfigError naming a missing or bad one)."""
    path = path or config_file("graph.yaml")
    data = read_yaml(path)
    out = {}
    for name in NODES:
        entry = data.get(name) if isinstance(data, dict) else None
        if not isinstance(entry, dict) or set(entry) != {"respawn", "respawn_delay", "max_respawns"}:
            raise ConfigError(f"{path}: {name} needs respawn, respawn_delay and max_respawns, got {entry!r}")
        out[name] = Respawn(**entry)
    return out


class NodeDied(RuntimeError):
    """A node of the graph died and is not coming back (no respawn, or max_respawns reached)."""

    def __init__(self, name: str, code: int | None, log_tail: str) -> None:
        super().__init__(f"node {name} exited with {code}:\n{log_tail}")
        self.name, self.code = name, code


def domains_in_use() -> set[int]:
    """ROS_DOMAIN_IDs in the environment of running processes: a graph must not join one of them; sharing a domain
    garbles every topic (seen: a demo's /clock and /motion_planner/relocate answering a test's client)."""
    used = set()
    for env in Path("/proc").glob("[0-9]*/environ"):
        try:
            for item in env.read_bytes().split(b"\0"):
                if item.startswith(b"ROS_DOMAIN_ID="):
                    used.add(int(item[len(b"ROS_DOMAIN_ID="):] or b"-1"))
        except (OSError, ValueError):
            continue
    return used


def reserve_domain_id(in_use: set[int] | None = None) -> tuple[int, Path]:
    """A ROS_DOMAIN_ID in 1..100 that no live reservation holds (lock file with the owner's pid) and no running
    process uses (`in_use`, default domains_in_use()); (id, lock file: unlink it when done)."""
    LOCK_DIR.mkdir(exist_ok=True)
    used = domains_in_use() if in_use is None else in_use
    ids = [i for i in range(1, 101) if i not in used]
    random.shuffle(ids)
    for i in ids:
        lock = LOCK_DIR / f"{i}.lock"
        try:
            fd = os.open(lock, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
        except FileExistsError:
            try:
                os.kill(int(lock.read_text() or "0"), 0)
                continue  # owner alive
            except (ProcessLookupError, ValueError):
                lock.unlink(missing_ok=True)  # stale: owner gone
                continue
            except PermissionError:
                continue
        os.write(fd, str(os.getpid()).encode())
        os.close(fd)
        return i, lock
    raise RuntimeError("no free ROS_DOMAIN_ID in 1..100")


def private_domain_id() -> tuple[int, Path | None]:
    """QTREE_DOMAIN_ID if set (a caller reserved one: no lock here), else a reserved one (reserve_domain_id)."""
    if os.environ.get("QTREE_DOMAIN_ID"):
        return int(os.environ["QTREE_DOMAIN_ID"]), None
    return reserve_domain_id()


def ros_env(domain_id: int, run_dir: Path) -> dict[str, str]:
    """Environment of a node process: the private domain, loopback discovery, logs and ROS home under `run_dir`."""
    env = dict(os.environ)
    env.update(
        ROS_DOMAIN_ID=str(domain_id),
        ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
        ROS_HOME=str(run_dir / "ros_home"),
        ROS_LOG_DIR=str(run_dir / "ros_log"),
        MUJOCO_GL=env.get("MUJOCO_GL", "egl"),
        # a 16 MB shared-memory segment: with Fast DDS's default most best-effort camera images are lost
        FASTRTPS_DEFAULT_PROFILES_FILE=env.get("FASTRTPS_DEFAULT_PROFILES_FILE", str(config_file("fastdds.xml"))),
        PYTHONUNBUFFERED="1",
        PYTHONPATH=os.pathsep.join(filter(None, [str(python_path()), env.get("PYTHONPATH")])),
    )
    return env


def clean_shared_memory() -> str:
    """Remove the Fast DDS shared-memory files whose owner process is gone, with Fast DDS's own tool (`fastdds shm
    clean`, shipped with Fast DDS; eProsima/Fast-DDS#1144): a node SIGKILLed or crashed leaves its segments behind in
    /dev/shm, RAM that nothing frees (the test suite left about 600 such segments, 2.5 GB, over a day of runs here);
    the files of a live process are locked and kept. The tool's counts in one line, or why it did not run."""
    tool = shutil.which("fastdds", path=os.pathsep.join([str(Path(sys.executable).parent),
                                                          os.environ.get("PATH", "")]))
    if tool is None:
        return "shared memory not cleaned: Fast DDS's fastdds tool not found"
    try:
        r = subprocess.run([tool, "shm", "clean"], capture_output=True, text=True, timeout=60,
                           stdin=subprocess.DEVNULL)
    except (OSError, subprocess.TimeoutExpired) as e:
        return f"shared memory not cleaned: {e}"
    counts = [line.strip() for line in r.stdout.splitlines() if "cleaned" in line]
    return ", ".join(counts) if r.returncode == 0 and counts else \
        f"shared memory not cleaned: fastdds shm clean exited {r.returncode}: {(r.stderr or r.stdout).strip()[:200]}"


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
    domain_id: int | None = None  # default: a reserved private one (private_domain_id), released by stop_all
    procs: dict[str, subprocess.Popen] = field(default_factory=dict)
    respawn: bool = False  # True: config/graph.yaml's respawn policies (the module docstring)
    on_event: Callable[[dict[str, Any]], None] = lambda event: None  # each death and restart, from the supervisor

    def __post_init__(self) -> None:
        self._lock = None
        if self.domain_id is None:
            self.domain_id, self._lock = private_domain_id()
        self.run_dir = Path(self.run_dir)
        (self.run_dir / "logs").mkdir(parents=True, exist_ok=True)
        self.arms: dict[str, ArmInterface] = {}  # started node -> the arm interface it runs with
        self.env = ros_env(self.domain_id, self.run_dir)
        self.policies = respawn_policies() if self.respawn else {}
        self.events: list[dict[str, Any]] = []  # {"node", "event": died | respawned | gave up, "code", "t"}
        self._cmds: dict[str, tuple[str, list[str]]] = {}  # started name -> (node kind, command)
        self._deaths: dict[str, int] = {}  # started name -> deaths so far
        self._dead: dict[str, int | None] = {}  # started name -> exit code, not coming back
        self._guard = threading.RLock()
        self._t0 = time.monotonic()
        self._stopping = threading.Event()
        self._supervisor: threading.Thread | None = None

    def start(self, name: str, params: dict | None = None, params_file: Path | None = None,
              namespace: str = "") -> subprocess.Popen:
        """Start node `name` (with a namespace: as `<name>_<namespace>`, e.g. motion_planner_replica_1)."""
        module, cfg = NODES[name]
        arm = self._agree(name, params or {}, params_file or config_file(cfg)) if name in ARM_NODES else None
        cmd = [sys.executable, "-m", module, "--ros-args", "--params-file", str(params_file or config_file(cfg))]
        for k, v in (params or {}).items():
            cmd += ["-p", f"{k}:={param_arg(v)}"]
        kind = name
        if namespace:
            cmd += ["-r", f"__ns:={namespace}"]
            name = f"{name}_{namespace.strip('/').replace('/', '_')}"
        with self._guard:
            self._cmds[name] = (kind, cmd)
            self._dead.pop(name, None)
            self.procs[name] = self._spawn(name, cmd, "w")
        if arm is not None:
            self.arms[name] = arm
        if self.respawn and self._supervisor is None:
            self._supervisor = threading.Thread(target=self._supervise, name="graph supervisor", daemon=True)
            self._supervisor.start()
        return self.procs[name]

    def _spawn(self, name: str, cmd: list[str], mode: str, respawn: int = 0) -> subprocess.Popen:
        env = dict(self.env, **{RESPAWN_ENV: str(respawn)}) if respawn else self.env  # the node's health says it
        with open(self.run_dir / "logs" / f"{name}.log", mode) as log:
            return subprocess.Popen(cmd, env=env, stdout=log, stderr=subprocess.STDOUT,
                                    stdin=subprocess.DEVNULL, cwd=self.run_dir, preexec_fn=die_with_parent)

    # -- respawn (launch_ros's respawn, respawn_delay; config/graph.yaml) ---------------------------------------
    def _supervise(self) -> None:
        """Until stop_all: a node that exited is started again after its respawn_delay, up to max_respawns times;
        every death and restart is an event (`events`, `on_event`, the log). A node stopped through `stop` is not."""
        due: dict[str, float] = {}  # name -> when to start it again
        while not self._stopping.wait(SUPERVISE_PERIOD):
            try:
                self._look(due)
            except Exception as e:  # never silent: the graph goes on without respawn
                print(f"[graph] supervisor stopped: {type(e).__name__}: {e}", file=sys.stderr, flush=True)
                return

    def _look(self, due: dict[str, float]) -> None:
        """One look at the processes (_supervise): deaths noted, restarts that are due made."""
        with self._guard:
            for name, p in list(self.procs.items()):
                code = p.poll()
                if code is None or name in due or name in self._dead:
                    continue
                policy = self.policies.get(self._cmds[name][0])
                n = self._deaths[name] = self._deaths.get(name, 0) + 1
                if policy is not None and policy.respawn and n <= policy.max_respawns:
                    due[name] = time.monotonic() + policy.respawn_delay
                    self._event(name, "died", code, f"restarting in {policy.respawn_delay:g} s "
                                                    f"({n} of {policy.max_respawns})")
                else:
                    self._dead[name] = code
                    why = "max_respawns reached" if policy is not None and policy.respawn else "no respawn"
                    self._event(name, "died", code, f"not restarted ({why}: config/graph.yaml)")
            for name, at in list(due.items()):
                if time.monotonic() >= at and name in self.procs and not self._stopping.is_set():
                    del due[name]
                    with open(self.run_dir / "logs" / f"{name}.log", "a") as log:
                        log.write(f"\n----- [graph] respawned after exit {self.procs[name].returncode} -----\n")
                    self.procs[name] = self._spawn(name, self._cmds[name][1], "a", self._deaths[name])
                    self._event(name, "respawned", None, f"pid {self.procs[name].pid}")

    def _event(self, name: str, what: str, code: int | None, note: str) -> None:
        event = {"node": name, "event": what, "code": code, "t": round(time.monotonic() - self._t0, 1),
                 "note": note}
        self.events.append(event)
        print(f"[graph] {name} {what}" + (f" (exit {code})" if code is not None else "") + f": {note}",
              file=sys.stderr, flush=True)
        self.on_event(event)

    def dead(self) -> dict[str, int | None]:
        """The nodes that died and are not coming back: name -> exit code (with respawn; without, any dead node)."""
        with self._guard:
            if self.respawn:
                return dict(self._dead)
            return {n: p.returncode for n, p in self.procs.items() if p.poll() is not None}

    def _agree(self, name: str, params: dict, params_file: Path) -> ArmInterface | None:
        """The arm interface node `name` will run with (config/arm_interface.yaml, then its params file's section,
        then `params`); ValueError naming the difference when a running node that shares it runs with another
        (the driver and the planners: config/arm_interface.yaml). None for settings the node will refuse itself."""
        try:
            section = node_section(params_file, name)
            values = {**ArmInterface.load().to_dict(), **section, **params}
            arm = ArmInterface.from_mapping({k: values[k] for k in ArmInterface.keys()})
        except (ConfigError, ValueError):
            return None  # the node exits with one line saying what is wrong
        for other, theirs in self.arms.items():
            proc = self.procs.get(other)
            diff = [f"{k} {getattr(arm, k)!r} vs {getattr(theirs, k)!r}" for k in ArmInterface.keys()
                    if getattr(arm, k) != getattr(theirs, k)]
            if diff and proc is not None and proc.poll() is None:
                raise ValueError(f"{name} and {other} would run on different arm interfaces ({', '.join(diff)}): "
                                 f"set them in config/arm_interface.yaml, or pass the same to both")
        return arm

    def start_planners(self, replicas: int | None = None, params: dict | None = None) -> list[subprocess.Popen]:
        """The motion planner and replicas - 1 feasibility-only replicas under /replica_<k> (docs/architecture.md:
        the task planner started with the same `replicas` keeps one question in flight per replica); `replicas`
        None: one per core (relocation_common.feasibility.default_replicas)."""
        replicas = default_replicas() if replicas is None else replicas
        procs = [self.start("motion_planner", params)]
        for k in range(1, replicas):
            procs.append(self.start("motion_planner", dict(params or {}, serve_relocation=False),
                                    namespace=replica_namespace(k)))
        return procs

    def log(self, name: str) -> str:
        """The log of node `name` so far."""
        return (self.run_dir / "logs" / f"{name}.log").read_text(errors="replace")

    def check_alive(self) -> None:
        """Raise NodeDied (a RuntimeError) naming a node that died and is not coming back (with respawn: its
        policy let it go; without: any dead node), with the end of its log."""
        for name, code in self.dead().items():
            raise NodeDied(name, code, self.log(name)[-3000:])

    def stop(self, name: str, sig: int = signal.SIGINT, grace: float = 5.0) -> int:
        """Stop node `name` (signal `sig`, SIGKILL after `grace` s; never respawned); its exit code."""
        with self._guard:
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
        """SIGINT to every node, SIGKILL to those still running after `grace` s; name -> exit code."""
        self._stopping.set()  # no respawn from here on
        with self._guard:
            pass  # a respawn in progress has finished: its process is in procs
        if self._supervisor is not None:
            self._supervisor.join(timeout=2.0)
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
        if self.events or any(code < 0 for code in codes.values()):  # a node killed or crashed: its files stay
            clean_shared_memory()
        if self._lock is not None:  # the domain is free again
            self._lock.unlink(missing_ok=True)
            self._lock = None
        return codes

    def __enter__(self) -> "Graph":
        return self

    def __exit__(self, *exc) -> None:
        self.stop_all()


def wait_for_interfaces(node, services=(), actions=(), timeout: float = 60.0, graph: Graph | None = None,
                        check=lambda: None, error: type[Exception] = RuntimeError) -> None:
    """Block until every service (name, type) and action (name, action client) given is available; `error` on
    timeout. While waiting, `check()` and the graph's liveness check (a dead node raises at once)."""
    deadline = time.monotonic() + timeout
    clients = [node.create_client(t, n) for n, t in services]
    pending = [(f"service {c.srv_name}", c.wait_for_service) for c in clients]
    pending += [(f"action {name}", a.wait_for_server) for name, a in actions]
    try:
        for what, wait in pending:
            while not wait(timeout_sec=0.2):
                check()
                if graph is not None:
                    graph.check_alive()
                if time.monotonic() > deadline:
                    raise error(f"{what} not available after {timeout:.0f} s: is the node graph up?")
    finally:
        for c in clients:
            node.destroy_client(c)
