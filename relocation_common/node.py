"""What every node shares: its parameters declared from its YAML, its main() (spin, clean exit), a blocking
service call with a timeout, an action client without rclpy's lost-response race, its health on /diagnostics, and
the check that the interfaces' Python classes and C libraries come from one build (check_type_support).

SIGINT and SIGTERM end the spin loop, then the context is shut down (running callbacks see rclpy.ok() false)
and the node closed: exit 0. Bad parameters or a bad scene: one line on stderr and exit status 2, never a traceback.
"""
from __future__ import annotations

import gc
import importlib
import os
import signal
import sys
import threading
import time
from contextlib import contextmanager
from types import FrameType
from typing import Any, Callable, Iterator, Mapping

import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.action import ActionClient as RclpyActionClient
from rclpy.action.client import ClientGoalHandle
from rclpy.action.server import ServerGoalHandle
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.client import Client
from rclpy.context import Context
from rclpy.exceptions import ParameterException
from rclpy.executors import Executor, ExternalShutdownException, MultiThreadedExecutor, SingleThreadedExecutor
from rclpy.impl.rcutils_logger import RcutilsLogger
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions
from rclpy.task import Future

from .config import ConfigError, ParameterError, check_params_files, node_section
from .paths import config_file

STOP_POLL = 0.2  # s: how often a node's main loop looks for SIGINT/SIGTERM
STOP_GRACE = 5  # s (whole): a node still running this long after SIGINT/SIGTERM is ended by SIGALRM (run_node)
CALLBACK_GRACE = 2.5  # s a stopping node waits for its running callbacks (a training writing its checkpoint)
_stopped_by: list[str] = []  # the signal that ended run_node's loop (SIGINT, SIGTERM)


def stop_reason() -> str:
    """Why this process is stopping: "stopped by the user (SIGTERM)" (or SIGINT) after a signal, else
    "shutting down"."""
    return f"stopped by the user ({_stopped_by[-1]})" if _stopped_by else "shutting down"


@contextmanager
def stopping_as(exc_type: Callable[[str], Exception]) -> Iterator[None]:
    """Inside: an RCLError raised because the node's context was shut down (its process is stopping; e.g. rclpy's
    "failed to check service availability: rcl node's context is invalid" of Client.service_is_ready) becomes
    exc_type(stop_reason()), an outcome the caller handles, never a traceback. Any other RCLError is raised as is."""
    from rclpy._rclpy_pybind11 import RCLError

    try:
        yield
    except RCLError:
        if rclpy.ok():
            raise
        raise exc_type(stop_reason()) from None


def declare_parameters(node: Node, shared: tuple[str, ...] = ()) -> dict[str, Any]:
    """Declare every parameter of `config/<node name>.yaml` with that file's value as its default: the one place a
    node's parameters and defaults are written; and those of the `/**` section of each `shared` file under config/
    (settings several nodes must agree on, e.g. arm_interface.yaml). ParameterError for a key in two of these files,
    and for an override (-p, --params-file) that names a parameter the node does not have (a typo is never silently
    ignored). Returns {name: value}.

    A nested mapping is declared as ROS reads it from a params file: one parameter per leaf, its keys joined by dots
    (`action_cost: {top_grasp: 1.5}` -> `action_cost.top_grasp`; flat_parameters).

    Read-only (ParameterDescriptor.read_only): a node checks its parameters once, at start, and some are read again
    while it runs; `ros2 param set` is refused ("parameter is read-only") instead of bypassing those checks. Set
    them with -p or --params-file and restart the node."""
    name = node.get_name()
    defaults = node_section(config_file(f"{name}.yaml"), name)
    for f in shared:
        more = node_section(config_file(f), "/**")
        twice = sorted(set(more) & set(defaults))
        if twice:
            raise ParameterError(f"parameter(s) {', '.join(twice)} in both config/{name}.yaml and config/{f}: "
                                 f"keep them in config/{f} only")
        defaults.update(more)
    defaults = flat_parameters(defaults)
    for k, v in defaults.items():
        node.declare_parameter(k, v, ParameterDescriptor(read_only=True))
    unknown = sorted(set(node._parameter_overrides) - set(node._parameters))
    if unknown:
        raise ParameterError(f"unknown parameter(s) {', '.join(unknown)}; known: {', '.join(sorted(defaults))}")
    return {k: node.get_parameter(k).value for k in defaults}


def flat_parameters(section: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """A params-file section with its nested mappings flattened to dotted names, as rcl does: {"a": {"b": 1}} ->
    {"a.b": 1}."""
    out: dict[str, Any] = {}
    for k, v in section.items():
        if isinstance(v, Mapping):
            out.update(flat_parameters(v, f"{prefix}{k}."))
        else:
            out[f"{prefix}{k}"] = v
    return out


class SideNode:
    """A hidden node spun by its own single-threaded executor in a thread: for a high-rate stream (100 Hz joint
    states) that rclpy's MultiThreadedExecutor delivers with gaps of up to 0.8 s (measured here, rclpy 7.1.6; the
    performance issue rclpy#1452), while the main node's long callbacks need that executor. `threads` > 1: a
    MultiThreadedExecutor (an action server whose execute callback waits, and whose goal and cancel requests must
    still be served meanwhile). Call close()."""

    def __init__(self, name: str, context: Context | None = None, threads: int = 1) -> None:
        self.node = Node(name if name.startswith("_") else f"_{name}", context=context)
        self._executor = (SingleThreadedExecutor(context=context) if threads <= 1
                          else MultiThreadedExecutor(num_threads=threads, context=context))
        self._executor.add_node(self.node)
        self._thread = threading.Thread(target=self._spin, name=name, daemon=True)
        self._thread.start()

    def _spin(self) -> None:
        try:
            self._executor.spin()
        except (KeyboardInterrupt, ExternalShutdownException):
            pass
        except Exception:
            if rclpy.ok(context=self.node.context):
                raise

    def close(self) -> None:
        """Stop the executor, join its thread, and destroy the node once nothing spins it."""
        self._executor.shutdown(timeout_sec=2.0)
        self._thread.join(timeout=3.0)
        if not self._thread.is_alive():  # destroying a node its executor still waits on can crash the process
            self.node.destroy_node()


def run_node(node_factory: Callable[[], Node], args: list[str] | None = None, threads: int = 4) -> None:
    """Spin one node until SIGINT/SIGTERM (a single-threaded executor for threads=1, else a multi-threaded one);
    then `node.close()` if it has one.

    The signals are handled here, in the main thread, not by rclpy's own handler: that one runs in a thread of its
    own and triggers every executor's guard condition while this thread, woken by the same signal, already
    destroys those executors; the race segfaulted 1 SIGINT in 3 (core dump: rcl_trigger_guard_condition called
    from rclpy's signal thread). Here the flag is checked between waits of at most STOP_POLL s.

    The stop is bounded: the signal also sets an alarm (SIGALRM, default action: the process ends) STOP_GRACE s
    later, as launch's SIGTERM-then-SIGKILL does for the nodes it started. A node orphaned by a SIGKILLed demo has no
    launcher left to do that: in one fresh-clone CI run all four nodes of such a demo were still running 15 s after
    their parent-death SIGTERM (not reproduced in 30 runs here; Fast DDS's shared-memory transport is known to block
    a process whose peer died holding a port, eProsima/Fast-DDS#1144; the cause was not confirmed)."""
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    stop = threading.Event()
    def on_signal(sig: int, _frame: FrameType | None) -> None:
        _stopped_by.append(signal.Signals(sig).name)
        stop.set()
        signal.signal(signal.SIGALRM, signal.SIG_DFL)
        signal.alarm(STOP_GRACE)  # kernel-side: ends the process even if this thread never runs Python again

    previous = {sig: signal.signal(sig, on_signal) for sig in (signal.SIGINT, signal.SIGTERM)}
    node = None
    executor = SingleThreadedExecutor() if threads == 1 else MultiThreadedExecutor(num_threads=threads)
    settled = True
    try:
        node = node_factory()
        executor.add_node(node)
        while not stop.is_set() and rclpy.ok():
            executor.spin_once(timeout_sec=STOP_POLL)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except Exception:
        if rclpy.ok():
            raise
    finally:
        rclpy.try_shutdown()  # running callbacks see rclpy.ok() false; every executor is woken
        settled = _wait_for_callbacks(executor, CALLBACK_GRACE)
        executor.shutdown(timeout_sec=1.0 if settled else 0.0)
        if node is not None:
            close = getattr(node, "close", None)
            if close is not None:
                close()
            if not settled and _stopped_by:
                node.get_logger().info(f"stopped; a callback still running after {CALLBACK_GRACE} s is not waited for")
            node.destroy_node()
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    if not settled and _stopped_by:
        _leave_running_callbacks()


def _leave_running_callbacks() -> None:
    """Exit 0 now, leaving the callbacks still running (a perception frame that took 3-6 s at a load of 5): the
    interpreter's exit would wait for them (concurrent.futures joins the executor's pool threads), past STOP_GRACE,
    and SIGALRM would end a clean stop with -14."""
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(0)


def _wait_for_callbacks(executor: Executor, timeout: float) -> bool:
    """After shutdown: until the callbacks a MultiThreadedExecutor's pool still runs have ended (at most `timeout`
    s), then their errors are taken (a callback that published after the context went away fails, as expected).
    rclpy neither waits nor takes them: the perception node printed "The following exception was never retrieved:
    cannot use Destroyable ..." (a callback ending after shutdown() destroyed the executor's guard condition) or
    "... publisher's context is invalid" on SIGINT and SIGTERM. True when none is running any more."""
    deadline = time.monotonic() + timeout
    futures = list(getattr(executor, "_futures", ()))
    while any(not f.done() for f in futures) and time.monotonic() < deadline:
        time.sleep(0.01)
    for f in futures:
        if f.done():
            f.exception()  # taken: not printed when the task is collected
    return all(f.done() for f in futures)


def node_main(name: str, node_factory: Callable[[], Node], args: list[str] | None = None, threads: int = 4,
              errors: tuple[type[Exception], ...] = ()) -> None:
    """main() of a node: check the interfaces' build (check_type_support) and the params files, run it; unusable
    input is one line on stderr and exit 2."""
    unusable: tuple[type[Exception], ...] = (ConfigError, ParameterException, ValueError, TypeError,
                                             InterfaceMismatch) + errors
    try:
        check_type_support()
        check_params_files(sys.argv if args is None else args)
        run_node(node_factory, args, threads)
    except unusable as e:
        print(f"{name}: {type(e).__name__}: {e}", file=sys.stderr)
        raise SystemExit(2) from None
    _freeze_for_exit()


def _freeze_for_exit() -> None:
    """The node has stopped and the process ends: move every object to the collector's permanent generation, which
    the interpreter's finalization does not traverse. Its collections were most of a node's exit (the driver's main
    thread in gc_collect_main for about 100 ms of CPU after SIGINT; 0.14-0.20 s of CPU from the signal to the end of
    the process, 0.07-0.13 s frozen), and under load each CPU second is several of wall time against the 2 s a stop
    may take. Objects are still freed by their reference counts and the C++ exit handlers still run (Fast DDS's
    participants are destroyed, their removal announced: unlike ending with os._exit, which lost it)."""
    gc.freeze()


class ActionClient(RclpyActionClient):
    """rclpy's ActionClient with the fix of rclpy#1123 (rclpy#1308; not in the Jazzy wheels this project uses).
    send_goal_async, cancel and get_result send the request and only then register its sequence number; when the
    executor thread took the response in between, rclpy dropped it ('Ignoring unexpected goal response') and the
    future never completed: a fresh-clone CI run waited 30 s for a goal response that had come. Here the
    registration and the handling of responses hold one lock."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._registration = threading.RLock()  # re-entrant: a feedback callback may send a goal

    def send_goal_async(self, *args: Any, **kwargs: Any) -> Future:
        """rclpy's send_goal_async, registered under the lock that also handles the responses."""
        with self._registration:
            return super().send_goal_async(*args, **kwargs)

    def _cancel_goal_async(self, goal_handle: ClientGoalHandle) -> Future:
        with self._registration:
            return super()._cancel_goal_async(goal_handle)

    def _get_result_async(self, goal_handle: ClientGoalHandle) -> Future:
        with self._registration:
            return super()._get_result_async(goal_handle)

    async def execute(self, taken_data: Any) -> None:
        """rclpy's response handling, under the lock that registers requests."""
        with self._registration:
            return await super().execute(taken_data)


def abort_with_reason(goal_handle: ServerGoalHandle, result: Any, reason: str, logger: RcutilsLogger) -> Any:
    """End a goal that cannot be carried out: accepted, then aborted with `reason` in the result's message (as nav2
    does: a rejection carries no reason to the client). Logged as an error; returns `result` for the execute
    callback."""
    result.success, result.message = False, reason
    logger.error(reason)
    end_goal(goal_handle, "abort")
    return result


def end_goal(goal_handle: ServerGoalHandle, outcome: str) -> None:
    """goal_handle.succeed() / abort() / canceled(), unless the node is shutting down (then the action server's
    publishers are gone and rclpy raises; a client learns from the server's disappearance instead)."""
    from rclpy._rclpy_pybind11 import RCLError

    try:
        getattr(goal_handle, outcome)()
    except RCLError:
        if rclpy.ok():
            raise


def call(client: Client, request: Any, timeout: float, abandon: Callable[[], bool] = lambda: False) -> Any:
    """Call a service from a worker thread and wait for the answer (an executor spins the node elsewhere).
    TimeoutError after `timeout` s, or as soon as `abandon()` is true; the pending request is dropped."""
    done = threading.Event()
    fut = client.call_async(request)
    fut.add_done_callback(lambda _: done.set())
    deadline = time.monotonic() + timeout
    while not done.wait(0.05):
        if abandon() or time.monotonic() > deadline:
            client.remove_pending_request(fut)
            raise TimeoutError(f"no answer from {client.srv_name} within {timeout:.1f} s")
    return fut.result()


RESPAWN_ENV = "QTREE_RESPAWN"  # set by the graph launcher in a respawned node's environment: how many times
STARTED_NOTE_S = 30.0  # s after a start during which a node's status says it (re)started
Report = Callable[[], tuple[int, str, dict[str, str]]]  # () -> (level: 0 OK, 1 WARN, 2 ERROR, message, values)


class Health:
    """A node's health on /diagnostics (diagnostic_msgs/DiagnosticArray, what rqt_robot_monitor and the diagnostic
    aggregator read): one DiagnosticStatus `name` from `report()`, every `period` s on a timer of its own (a node's
    busy callbacks do not delay it); without `report`, only what `send` is given (perception: one per frame). Every
    status carries the process id and its uptime; for STARTED_NOTE_S s after the start its message begins with
    "started" or, in a respawned process (RESPAWN_ENV set by the launcher), "restarted (respawn N)": a respawn shows
    as a status that resets and says so."""

    def __init__(self, node: Node, name: str, hardware_id: str, report: Report | None = None,
                 period: float = 1.0) -> None:
        self.node, self.name, self.hardware_id, self.report = node, name, hardware_id, report
        self.t0 = time.monotonic()
        respawn = os.environ.get(RESPAWN_ENV, "")
        self.start_note = f"restarted (respawn {respawn})" if respawn else "started"
        self.pub = node.create_publisher(DiagnosticArray, "/diagnostics", 10)
        if report is not None:
            node.create_timer(period, self.publish, MutuallyExclusiveCallbackGroup())

    def publish(self) -> None:
        """The status report() gives now (report() failing is itself an ERROR status, never an exception)."""
        assert self.report is not None
        try:
            level, message, values = self.report()
        except Exception as e:
            level, message, values = 2, f"health report failed: {type(e).__name__}: {e}", {}
        self.send(level, message, values)

    def send(self, level: int, message: str, values: dict[str, str]) -> None:
        """One status (level 0 OK, 1 WARN, 2 ERROR) with the start note, the pid and the uptime added."""
        up = time.monotonic() - self.t0
        if up < STARTED_NOTE_S:
            message = f"{self.start_note} {up:.0f} s ago; {message}"
        msg = DiagnosticArray()
        msg.header.stamp = self.node.get_clock().now().to_msg()
        kv = [KeyValue(key=k, value=str(v)) for k, v in {**values, "pid": os.getpid(), "up (s)": f"{up:.0f}"}.items()]
        msg.status = [DiagnosticStatus(level=bytes([level]), name=self.name, message=message[:1000],
                                       hardware_id=self.hardware_id, values=kv)]
        try:
            self.pub.publish(msg)
        except Exception:
            if rclpy.ok(context=self.node.context):
                raise

# -------------------------------------------------------------------------------- the interfaces' build
# The project's interfaces checked at start: the Python classes of qtree_relocation_msgs and the C type support
# libraries the process loaded for them must come from one build of msg_defs/.
# A Python package generated from a newer PlanFeasibility than the C libraries found first on LD_LIBRARY_PATH loses
# the fields the libraries do not know, silently, on every message: a node then answers a feasible pick without its
# near set (`near_known` false: no reuse across answers, the task planner asks several times the questions) and takes
# a certify request for a plain pick (`certify` false). The ros_wheels_bootstrapper of the venv (its .pth) orders
# LD_LIBRARY_PATH through a Python set, so with two builds on it which one a process loads changes from one start to
# the next. `check_type_support` sends one message of every type, each field set away from its default, through
# rclpy's serialization (the C libraries) and back, and raises InterfaceMismatch naming the fields lost.
PACKAGE = "qtree_relocation_msgs"
_PARTS = {"msg": (), "srv": ("Request", "Response"), "action": ("Goal", "Result", "Feedback")}


class InterfaceMismatch(Exception):
    """The interface package's Python classes and its C libraries come from different builds."""


def interface_types(package: str = PACKAGE) -> list[type]:
    """Every message class of `package`: its messages, the requests and responses of its services, the goals,
    results and feedback of its actions."""
    out: list[type] = []
    for sub, parts in _PARTS.items():
        mod = importlib.import_module(f"{package}.{sub}")
        for name in sorted(n for n in dir(mod) if not n.startswith("_")):
            obj = getattr(mod, name)
            if isinstance(obj, type) and parts and all(hasattr(obj, p) for p in parts):
                out.extend(getattr(obj, p) for p in parts)
            elif isinstance(obj, type) and not parts and hasattr(obj, "get_fields_and_field_types"):
                out.append(obj)
    return out


def sample(cls: Any, package: str = PACKAGE) -> Any:
    """An instance of message class `cls` with every field away from its default (nested messages of `package`
    likewise, one element in each sequence; fixed-size arrays and other packages' messages left as they are)."""
    from rosidl_parser.definition import AbstractSequence, NamespacedType

    msg = cls()
    for (name, _), slot in zip(cls.get_fields_and_field_types().items(), cls.SLOT_TYPES):
        value = getattr(msg, name)
        if isinstance(slot, AbstractSequence):
            t = slot.value_type
            if isinstance(t, NamespacedType):
                elem = getattr(importlib.import_module(".".join(t.namespaces)), t.name)
                value.append(sample(elem, package) if t.namespaces[0] == package else elem())
            elif hasattr(value, "typecode"):  # array.array of numbers
                value.append(0.5 if value.typecode in "fd" else 1)
            else:
                value.append(_scalar(t.typename if hasattr(t, "typename") else "string"))
        elif isinstance(slot, NamespacedType):
            value = sample(type(value), package) if slot.namespaces[0] == package else value
        elif isinstance(value, (bool, int, float, str, bytes)):
            value = _flip(value)
        setattr(msg, name, value)
    return msg


def _flip(value: bool | int | float | str | bytes) -> bool | int | float | str | bytes:
    if isinstance(value, bool):
        return not value
    if isinstance(value, int):
        return value + 1
    if isinstance(value, float):
        return value + 0.5
    return value + "x" if isinstance(value, str) else value + b"\x01"


def _scalar(typename: str) -> bool | int | float | str:
    if typename == "boolean":
        return True
    if typename in ("float", "double"):
        return 0.5
    return "x" if "string" in typename or typename == "char" else 1


def lost_fields(cls: Any, package: str = PACKAGE) -> list[str]:
    """The fields of `cls` that do not come back equal from a round trip through the C type support."""
    from rclpy.serialization import deserialize_message, serialize_message

    sent = sample(cls, package)
    back = deserialize_message(serialize_message(sent), cls)
    return [f for f in cls.get_fields_and_field_types()
            if repr(getattr(back, f, "<missing>")) != repr(getattr(sent, f))]


def check_type_support(package: str = PACKAGE) -> None:
    """InterfaceMismatch when a message of `package` loses a field in the C type support (the module docstring),
    naming the fields, where the Python package and the C libraries were loaded from, and what to do."""
    lost = {f"{cls.__module__.split('.')[1]}/{cls.__name__}": f for cls in interface_types(package)
            if (f := lost_fields(cls, package))}
    if not lost:
        return
    where = list(importlib.import_module(package).__path__)[0]
    libs = sorted({line.split()[-1] for line in _maps() if f"lib{package}__" in line})
    fields = "; ".join(f"{t}: {' '.join(f)}" for t, f in lost.items())
    raise InterfaceMismatch(
        f"{package}: fields lost in the C type support ({fields})"
        f": the Python package ({where}) and the C libraries loaded "
        f"({', '.join(libs) or 'unknown'}) come from different builds of msg_defs/. Rebuild them together "
        "(bash scripts/setup_env.sh); a package installed elsewhere needs its own lib/ alone on LD_LIBRARY_PATH")


def _maps() -> list[str]:
    try:
        with open("/proc/self/maps") as f:
            return f.read().splitlines()
    except OSError:
        return []
