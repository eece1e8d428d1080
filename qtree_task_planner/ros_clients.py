"""The task planner's clients over ROS, outside the node file (the node and relocation_app.client use them).

- ServiceOracle: the feasibility oracle (Eq. 11) over the motion planner's PlanFeasibility service, with the
  outage rules of docs/reliability.md ("Dead planner"); also the push question (action "push").
- Relocator: one RelocateObject goal to the motion planner (a relocation, or a push: action "push"), watched
  (shutdown, server gone, silence, cancel, timeout: qtree_task_planner.executive.retrieval.relocation_stop).
- SceneWatch: the latest scene message and when it arrived; `checked(...)` is the one a goal starts from,
  `after(t, ...)` waits for one received later (closed-loop execution: a scene perceived after a relocation ended).
- through_outages: a call to the feasibility service's work carried through planner outages with feedback.
- goal_health: the node's status on /diagnostics from the goal's feedback and the execution so far.
- train_goal / goal_params: a TrainPlanner goal whose numeric fields say "the node's parameter" (negative), and
  the TrainingParams a goal asks for; fill_optimum / fill_training_result: the outcome in the TrainPlanner result.
"""
from __future__ import annotations

import copy
import threading
import time
from typing import Any, Callable, Mapping, TypeVar

import rclpy
from qtree_relocation_msgs.action import RelocateObject, TrainPlanner
from qtree_relocation_msgs.msg import ObjectArray
from qtree_relocation_msgs.srv import PlanFeasibility
from rclpy.action.server import ServerGoalHandle
from rclpy.client import Client
from rclpy.impl.rcutils_logger import RcutilsLogger
from rclpy.task import Future
from rclpy.time import Time

from qtree_task_planner.executive.outage import Cancelled, PlannerUnavailable, until_available
from qtree_task_planner.executive.push import PUSH, PushAnswer
from qtree_task_planner.executive.replicas import ReplicaOracle
from qtree_task_planner.executive.retrieval import check_scene, relocation_stop
from qtree_task_planner.executive.world import SeenObject, seen_object
from qtree_task_planner.learning.params import TrainingParams
from qtree_task_planner.learning.training import TrainingResult
from qtree_task_planner.oracles import Lanes
from qtree_task_planner.search.exact import ExactResult
from relocation_common.feasibility import FeasibilityAnswer, Label
from relocation_common.node import ActionClient, call, stop_reason, stopping_as
from relocation_common.ros_conversions import (
    NO_ANSWER,
    blockers_from_msgs,
    lanes_from_msgs,
    moved_to_fields,
    msg_to_objects,
    near_from_fields,
)
from relocation_common.scenario import ScenarioError


class ServiceOracle:
    """FeasibilityOracle over the PlanFeasibility service (blocking call from a worker thread).

    Raises PlannerUnavailable as soon as the service is missing (after `connect_wait` s), when it disappears from
    the graph while a query is pending (a clean shutdown), or when no answer came within timeout + margin (a
    killed or wedged planner). `last_ok` is the monotonic time of the last answer. Raises Cancelled before a query
    when `stop()` is true (goal cancelled, node shutting down); `on_answer()` is called after each answer."""

    def __init__(self, client: Client, timeout: float, margin: float, connect_wait: float = 1.0,
                 stop: Callable[[], bool] = lambda: False, on_answer: Callable[[], None] = lambda: None) -> None:
        self.client, self.timeout, self.margin, self.connect_wait = client, timeout, margin, connect_wait
        self.stop, self.on_answer = stop, on_answer
        self.last_ok = time.monotonic()
        self.name: str = client.srv_name
        self.moved: dict[str, tuple[float, float]] = {}  # `what_if`: the questions' objects elsewhere

    def what_if(self, moved: Mapping[str, tuple[float, float]]) -> ServiceOracle:
        """This oracle asking on the scene with the objects of `moved` at those (x, y) on the top shelf
        (PlanFeasibility's moved_ids and moved_to: what would follow a push); this one is unchanged."""
        other = copy.copy(self)
        other.moved = dict(moved)
        return other

    def _request(self, **fields: Any) -> PlanFeasibility.Request:
        ids, points = moved_to_fields(self.moved)
        return PlanFeasibility.Request(timeout=self.timeout, moved_ids=ids, moved_to=points, **fields)

    def ready(self, timeout: float) -> bool:
        """Whether the service is up, waiting up to `timeout` s for it."""
        with stopping_as(Cancelled):  # the node stopping: Cancelled with the reason, never rclpy's RCLError
            return self.client.service_is_ready() or (timeout > 0 and self.client.wait_for_service(timeout_sec=timeout))

    def feasibility(self, object_id: str, removed: frozenset[str]) -> FeasibilityAnswer:
        """Eq. 11's label of relocating `object_id` after `removed` (and the lane blockers the planner saw, the
        objects a feasible pick comes near, the action a feasible answer is for)."""
        return self._ask(object_id, removed, False)

    def certify(self, object_id: str, removed: frozenset[str]) -> FeasibilityAnswer:
        """The certification of (object_id, removed): the whole relocation (relocation_common.feasibility)."""
        return self._ask(object_id, removed, True)

    def _ask(self, object_id: str, removed: frozenset[str], certify: bool) -> FeasibilityAnswer:
        # the label only: training never uses the trajectory (about 5 ms of a feasible answer's round trip)
        req = self._request(object_id=object_id, removed_ids=sorted(removed), label_only=True, certify=certify)
        resp = self._call(req, f"the certification of {object_id!r}" if certify else repr(object_id))
        return FeasibilityAnswer(Label(resp.label), resp.planning_time, resp.attempts, resp.message,
                                 blockers=blockers_from_msgs(resp.blockers),
                                 near=near_from_fields(resp.near_known, resp.near_ids), action=resp.action)

    def push(self, object_id: str, clear_for: str, removed: frozenset[str]) -> PushAnswer:
        """Can `object_id` be pushed out of the grasp lanes of `clear_for` (PlanFeasibility, action "push")? A
        planner that refuses the question, or answers it as a pick (one that does not plan pushes: its answer's
        action is not "push"), says no, with why."""
        req = self._request(object_id=object_id, removed_ids=sorted(removed), label_only=True, action=PUSH,
                            clear_for=clear_for)
        try:
            resp = self._call(req, f"the push of {object_id!r}")
        except ValueError as e:
            return PushAnswer(False, str(e), None)
        return push_answer(Label(resp.label), resp.action, resp.message, resp.end_pose.position)

    def lane_blockers(self, removed: frozenset[str]) -> Lanes | None:
        """Every remaining object's lane blockers at once (the planner's screen, no planning: all_lanes); None
        from a planner that refuses the question (one without lane blockers: the A* then learns from answers)."""
        req = self._request(object_id="", removed_ids=sorted(removed), all_lanes=True)
        try:
            return lanes_from_msgs(self._call(req, "the lane blockers").lanes)
        except ValueError:
            return None

    def _call(self, req: PlanFeasibility.Request, what: str) -> PlanFeasibility.Response:
        with stopping_as(Cancelled):  # the node stopping mid-query: Cancelled with the reason, never RCLError
            return self._call_once(req, what)

    def _call_once(self, req: PlanFeasibility.Request, what: str) -> PlanFeasibility.Response:
        if self.stop():
            raise Cancelled("cancelled while asking the motion planner" if rclpy.ok() else stop_reason())
        srv = self.client.srv_name
        if not self.client.service_is_ready() and not self.client.wait_for_service(timeout_sec=self.connect_wait):
            raise PlannerUnavailable(f"feasibility service {srv} is not available")
        limit = self.timeout + self.margin
        try:
            resp = call(self.client, req, limit, abandon=lambda: not self.client.service_is_ready())
        except TimeoutError:
            gone = not self.client.service_is_ready()
            raise PlannerUnavailable(
                f"feasibility service {srv} went away while answering {what}" if gone else
                f"no feasibility answer for {what} within {limit:.1f} s "
                "(feasibility_timeout + feasibility_margin)") from None
        self.last_ok = time.monotonic()
        self.on_answer()
        if not resp.ok and resp.message.startswith(NO_ANSWER):  # its safety net ran out: asked again, never g_U
            raise PlannerUnavailable(f"no feasibility answer for {what}: {resp.message[len(NO_ANSWER):]}")
        if not resp.ok:
            raise ValueError(f"motion planner refused the query for {what}: {resp.message}")
        return resp


def push_answer(label: Label, action: str, message: str, end: Any) -> PushAnswer:
    """A PlanFeasibility response to a push question as a PushAnswer (end: its end_pose.position)."""
    if label == Label.UNFEASIBLE:
        return PushAnswer(False, message, None)
    if action != PUSH:
        return PushAnswer(False, f"the motion planner answered a {action or 'pick'}, not a push (it does not plan "
                          f"pushes): {message}", None)
    return PushAnswer(True, message, (float(end.x), float(end.y)))


T = TypeVar("T")


def through_outages(fn: Callable[[], T], goal_handle: ServerGoalHandle, fb: TrainPlanner.Feedback,
                    oracle: ReplicaOracle, log: RcutilsLogger, wait: float, kept: Callable[[], str]) -> T:
    """fn() through planner outages (qtree_task_planner.executive.outage: up to `wait` s each, `kept()` says where the
    work is kept), with the goal's feedback phase "waiting for planner" while waiting."""
    phase = fb.phase

    def on_outage(message: str) -> None:
        log.warning(message)
        fb.phase = "waiting for planner"
        goal_handle.publish_feedback(fb)

    services = " or ".join(r.name for r in oracle.replicas)

    def on_back() -> None:
        fb.phase = phase
        log.info(f"motion planner {services} is back: resuming")

    return until_available(fn, service_up=oracle.ready, stop=lambda: goal_handle.is_cancel_requested or not rclpy.ok(),
                           wait=wait, last_answer=lambda: oracle.last_ok, kept=kept, service=services,
                           on_outage=on_outage, on_back=on_back)


SCENE_NONE = "none yet"  # goal_health's "scene" before the first scene came
GOAL_STATUS = "task_planner: goal"  # the name of the task planner's DiagnosticStatus (goal_health)
MOTION_WAIT = "waiting for the motion planner's relocation in flight"  # a goal's first phase while an earlier goal's
# relocation still moves the arm (its task planner died: docs/reliability.md, "A node that dies")


def goal_health(fb: TrainPlanner.Feedback | None, execution: dict[str, Any],
                scene_age: float | None) -> tuple[int, str, dict[str, str]]:
    """The task planner's status (relocation_common.node.Health): idle, or the goal's phase with its episode and
    planner calls, and the execution so far (relocated, re-plans); WARN while waiting for a lost planner. Always
    "scene": how old the latest scene is (SCENE_NONE before the first: a client that sends a goal only once the
    task planner has a scene does not race its discovery of the scene's publisher, `scene_wait`)."""
    scene = SCENE_NONE if scene_age is None else f"{scene_age:.1f} s old"
    if fb is None:
        return 0, "idle: no goal", {"phase": "idle", "scene": scene}
    replans = execution.get("replans", [])
    values = {"phase": fb.phase, "episode": str(fb.episode), "planner calls": str(fb.planner_calls),
              "re-plans": str(len(replans)), "relocated": " ".join(execution.get("relocated", [])), "scene": scene}
    if replans:
        last = replans[-1]
        values["last re-plan"] = f"{last['reason'][:200]} -> {' '.join(last['sequence'] or []) or last.get('failure')}"
    return (1 if fb.phase == "waiting for planner" else 0), f"{fb.phase[:200]}; re-plans: {len(replans)}", values


NODE_DEFAULT_FIELDS = ("alpha", "gamma", "epsilon0", "epsilon_min", "beta", "max_episodes", "max_steps",
                       "quiet_episodes", "seed")  # numeric goal fields: negative = the node's parameter


def train_goal(**fields: object) -> TrainPlanner.Goal:
    """A TrainPlanner goal whose numeric settings say "use the node's parameter" (negative) unless given."""
    goal = TrainPlanner.Goal()
    for f in NODE_DEFAULT_FIELDS:
        setattr(goal, f, type(getattr(goal, f))(-1))
    for k, v in fields.items():
        setattr(goal, k, v)
    return goal


def goal_params(node: TrainingParams, goal: TrainPlanner.Goal) -> TrainingParams:
    """The node's training parameters with what the goal sets (policy, search; numeric fields that are not
    negative). ParameterError / ValueError for values out of range (NaN included)."""
    changes = {f: getattr(goal, f) for f in ("policy", "search") if getattr(goal, f)}
    for f in NODE_DEFAULT_FIELDS:
        v = getattr(goal, f)
        if not v < 0:  # negative: the node's parameter; NaN goes on to validation and is refused
            changes[f] = v
    return node.replace(**changes)


def fill_training_result(result: TrainPlanner.Result, trained: TrainingResult, planner_calls: int) -> None:
    """The training's outcome (training.TrainingResult) in the TrainPlanner result (-1: no sequence, no e_1st)."""
    result.sequence = list(trained.sequence or ())
    result.total_weight = float(trained.total_weight if trained.total_weight is not None else -1.0)
    result.e_ss, result.mp_q = trained.e_ss, trained.mp_q
    result.e_first = trained.e_1st if trained.e_1st is not None else -1
    result.planner_calls, result.episodes = planner_calls, trained.episodes
    result.q_sum_history = [float(x) for x in trained.q_sum_history]


def fill_optimum(result: TrainPlanner.Result, exact: ExactResult) -> None:
    """The exact optimum (exact.ExactResult) in the TrainPlanner result (-1: none)."""
    result.optimal_sequence = list(exact.sequence or ())
    result.optimal_weight = float(exact.total_weight if exact.total_weight is not None else -1.0)


class Relocator:
    """RelocateObject goals (pick, carry to the bottom shelf, release, home) sent through `client`, each watched
    until its result: never blind to the node stopping, the planner gone or silent, a cancel or the time limit."""

    def __init__(self, client: ActionClient, server_wait: float, limit: float, silence: float,
                 ok: Callable[[], bool], resume_wait: float = 0.0) -> None:
        """server_wait: s to wait for the action server; limit: relocate_timeout; silence: relocate_silence (a
        moving motion planner reports at 10 Hz); ok(): rclpy.ok of the node's context; resume_wait: s to wait for
        a motion planner that went away before the goal is sent again (0: never; the node: planner_wait)."""
        self.client, self.server_wait, self.limit, self.silence, self.ok = client, server_wait, limit, silence, ok
        self.resume_wait = resume_wait

    def relocate(self, object_id: str, removed: list[str], cancelled: Callable[[], bool], action: str = "",
                 clear_for: str = "") -> tuple[bool, str]:
        """Relocate one object after `removed` (action "push": push it out of the grasp lanes of `clear_for`):
        (success, message). A motion planner that went away (its server
        gone, or silent and deaf to the cancel) is waited for up to `resume_wait` s from then and the same goal
        sent again: a restarted motion planner answers it for the interrupted relocation (its journal; the
        message then says it was lost). Else the message is why it stopped."""
        lost_at: float | None = None
        while True:
            ok, message, lost = self._once(object_id, removed, cancelled, action, clear_for)
            if not lost or self.resume_wait <= 0:
                break
            lost_at = lost_at if lost_at is not None else time.monotonic()
            if not self._back(lost_at, cancelled):
                return ok, f"{message}; not back within {self.resume_wait:g} s (planner_wait)"
        if lost_at is not None:
            message += f" (the motion planner was lost for {time.monotonic() - lost_at:.0f} s and came back)"
        return ok, message

    def _back(self, lost_at: float, cancelled: Callable[[], bool]) -> bool:
        """Wait for the relocate action server until resume_wait s after lost_at; False on cancel or shutdown."""
        while time.monotonic() - lost_at < self.resume_wait:
            if cancelled() or not self.ok():
                return False
            if self.client.wait_for_server(timeout_sec=0.5):
                return True
        return False

    def _once(self, object_id: str, removed: list[str], cancelled: Callable[[], bool], action: str,
              clear_for: str) -> tuple[bool, str, bool]:
        """One RelocateObject goal, watched until its result (relocation_stop): (success, message, the motion
        planner went away: its server gone, or silent and no result after the cancel)."""
        if not self.client.wait_for_server(timeout_sec=self.server_wait):
            return False, "relocate action server not available", False
        done = threading.Event()
        box: dict[str, Any] = {}  # "result": the GetResult response (an rclpy message: untyped); "rejected": True

        def on_result(fut: Future) -> None:
            box["result"] = fut.result()
            done.set()

        def on_goal(fut: Future) -> None:
            h = fut.result()
            if not h.accepted:
                box["rejected"] = True
                done.set()
                return
            h.get_result_async().add_done_callback(on_result)

        heard = [time.monotonic()]  # the last feedback

        def on_feedback(_: object) -> None:
            heard[0] = time.monotonic()

        goal = RelocateObject.Goal(object_id=object_id, removed_ids=list(removed), action=action, clear_for=clear_for)
        sent = self.client.send_goal_async(goal, feedback_callback=on_feedback)
        sent.add_done_callback(on_goal)
        start = time.monotonic()
        while not done.wait(0.1):
            now = time.monotonic()
            why = relocation_stop(shutting_down=not self.ok(), server_up=self.client.server_is_ready,
                                  silent_s=now - heard[0], silence=self.silence, cancelled=cancelled(),
                                  elapsed_s=now - start, limit=self.limit)
            if why is not None:
                if sent.done() and sent.result() is not None and sent.result().accepted and self.ok():
                    cancel = sent.result().cancel_goal_async()  # the arm stops (the motion planner's cancel)
                    if why.startswith(SILENT) and self._recovered(cancel, done) and "result" in box:
                        return False, f"{why}; after the cancel: {box['result'].result.message}", False
                return False, why, why.startswith(GONE)
        if box.get("rejected"):
            return False, "goal rejected by the motion planner", False
        res = box["result"].result
        return res.success, res.message, False

    def _recovered(self, cancel: Future, done: threading.Event) -> bool:
        """After cancelling a silent relocation: True once its result came. A silent planner may be a starved one
        (load): its cancelled goal ends after the recovery that brings the arm home, waited for up to `silence` s.
        A dead one never acknowledges the cancel: given up after CANCEL_ACK_WAIT s without the acknowledgement."""
        start = time.monotonic()
        while not done.wait(0.1):
            waited = time.monotonic() - start
            if waited > self.silence or not self.ok() or not self.client.server_is_ready():
                return False
            if not cancel.done() and waited > CANCEL_ACK_WAIT:
                return False
        return True


def seen_scene(msg: ObjectArray) -> dict[str, SeenObject]:
    """An ObjectArray as closed_loop's scene (world.seen_object of each of msg_to_objects); ScenarioError (a
    ValueError: the closed loop gives up with it) for a message that is not a scene."""
    return {o.id: seen_object(o) for o in msg_to_objects(msg, require_target=False)}


class SceneWatch:
    """The latest scene message and the monotonic time it arrived (`put` from the subscription)."""

    def __init__(self) -> None:
        self.latest: tuple[ObjectArray, float] | None = None  # (msg, received)
        self._changed = threading.Condition()

    def age(self) -> float | None:
        """Seconds since the latest scene arrived (None before the first)."""
        latest = self.latest
        return None if latest is None else time.monotonic() - latest[1]

    def put(self, msg: ObjectArray) -> None:
        """A scene arrived."""
        with self._changed:
            self.latest = (msg, time.monotonic())
            self._changed.notify_all()

    def after(self, since: float, timeout: float, settled: Callable[[ObjectArray], bool] = lambda msg: True,
              outage: float = 0.0) -> ObjectArray:
        """The latest scene received after `since` (monotonic) for which `settled(msg)` holds; once `timeout` s
        pass, the latest one received after `since` anyway. When none at all came within `timeout` (the scene's
        source silent: perception restarting), the first one that comes within `outage` s in all. TimeoutError
        when none came."""
        start = time.monotonic()
        deadline, last = start + timeout, start + max(timeout, outage)
        with self._changed:
            while True:
                fresh = self.latest if self.latest is not None and self.latest[1] > since else None
                now = time.monotonic()
                if fresh is not None and (settled(fresh[0]) or now >= deadline):
                    return fresh[0]
                if now >= (deadline if fresh is not None else last):
                    waited = f" (and {outage:g} s for the source to come back: scene_outage_wait)" \
                        if outage > timeout else ""
                    raise TimeoutError(f"no scene received within {timeout:g} s (scene_after_wait){waited}"
                                       f"{self._last()}")
                self._changed.wait(min(max(deadline if fresh is not None else last, now + 0.01) - now, 0.1))

    def checked(self, topic: str, max_age: float, wait: float, now: Callable[[], Time]
                ) -> tuple[ObjectArray, str | None]:
        """(the latest scene, a warning or None) after waiting up to `wait` s for a first one (just started:
        discovery may be going on); ScenarioError when it is missing, stale or empty (retrieval.check_scene, with
        its ages on the monotonic clock and on the node's clock `now()`)."""
        deadline = time.monotonic() + wait
        while self.latest is None and time.monotonic() < deadline:
            time.sleep(0.05)
        msg, t = self.latest if self.latest is not None else (None, 0.0)
        stamp = Time.from_msg(msg.header.stamp) if msg is not None else None
        warning = check_scene(topic, max_age, time.monotonic() - t if msg is not None else None,
                              (now() - stamp).nanoseconds * 1e-9 if stamp and stamp.nanoseconds else None,
                              len(msg.objects) if msg is not None else 0)
        return msg, warning

    def _last(self) -> str:
        """When the last scene came, for the timeout's line."""
        if self.latest is None:
            return "; none at all on this topic"
        return f"; the last one came {time.monotonic() - self.latest[1]:.0f} s ago"


def _standing_on(msg: ObjectArray, object_id: str, z: float, tol: float) -> bool:
    """The message shows object_id standing on the board at height z (within tol); a malformed message, no."""
    try:
        objects = msg_to_objects(msg, require_target=False)
    except ScenarioError:
        return False
    return any(o.id == object_id and not o.lying and abs(float(o.support_z or 0.0) - z) < tol for o in objects)


def left_top(object_id: str, top_z: float, tol: float = 0.02) -> Callable[[ObjectArray], bool]:
    """A scene settled after relocating object_id: it no longer shows the bottle standing on the top shelf
    (perception holds an unseen bottle at its last pose for hold_frames frames)."""
    def settled(msg: ObjectArray) -> bool:
        return not _standing_on(msg, object_id, top_z, tol)
    return settled


SILENT = "the motion planner went away (no feedback"  # retrieval.relocation_stop's words for relocate_silence
GONE = "the motion planner went away"  # ... for relocate_silence and for its server gone
CANCEL_ACK_WAIT = 3.0  # s: a live (even starved) motion planner acknowledges a cancel within it; a dead one never
UNSEEN_TARGET = (". Perception publishes no scene while it does not see the target (tipped over, fallen or hidden: "
                 "/diagnostics names the missing bottles and why)")  # docs/perception.md, "Hidden objects": a
# lying bottle fits no standing cylinder, so a tipped target is the usual cause after a relocation

Relocate = Callable[[str, list[str]], tuple[bool, str]]  # relocate(object_id, removed) -> (success, message)


Push = Callable[[str, str, list[str]], tuple[bool, str]]  # push(object_id, clear_for, removed) -> (success, message)


class Watched:
    """relocate / push / perceive for the closed loop: perceive() is the latest scene received after the last
    relocation or push ended, waiting up to `wait` s for one that shows a relocated bottle gone from the top shelf
    (left_top; after a push, the first one: the pushed object stays on the top shelf), and, when no scene comes at
    all (perception restarting), up to `outage` s for the first one (SceneWatch.after). The target is checked like
    any bottle: perception publishes its scene without the target once the motion planner says it placed it
    (perception_node, relocated_topic). `perception`: the timeout's line says that perception publishes no scene
    while it does not see the target (else it does not hold). push_one: the push executed (Relocator, action
    "push"); None: the node does not push."""

    def __init__(self, relocate_one: Relocate, scenes: SceneWatch, wait: float, top_z: float, perception: bool = False,
                 outage: float = 0.0, push_one: Push | None = None) -> None:
        self.relocate_one, self.push_one, self.scenes = relocate_one, push_one, scenes
        self.wait, self.top_z, self.perception, self.outage = wait, top_z, perception, outage
        self.ended, self.left = time.monotonic(), ""  # when the last relocation or push ended; the bottle that left

    def relocate(self, object_id: str, removed: list[str]) -> tuple[bool, str]:
        """One relocation (relocate_one), its end noted."""
        self.left = object_id
        try:
            return self.relocate_one(object_id, removed)
        finally:
            self.ended = time.monotonic()

    def push(self, object_id: str, clear_for: str, removed: list[str]) -> tuple[bool, str]:
        """One push (push_one), its end noted."""
        if self.push_one is None:
            raise ValueError("this task planner does not push (no push_one)")
        self.left = ""  # nothing leaves the top shelf: the first scene after it is the one
        try:
            return self.push_one(object_id, clear_for, removed)
        finally:
            self.ended = time.monotonic()

    def perceive(self) -> dict[str, SeenObject]:
        """The scene after the last relocation or push (the class doc)."""
        try:
            return seen_scene(self.scenes.after(self.ended, self.wait, left_top(self.left, self.top_z), self.outage))
        except TimeoutError as e:
            raise TimeoutError(f"{e}{UNSEEN_TARGET if self.perception else ''}") from None


def watched(relocate_one: Relocate, scenes: SceneWatch, wait: float, top_z: float, perception: bool = False,
            outage: float = 0.0) -> tuple[Relocate, Callable[[], dict[str, SeenObject]]]:
    """(relocate, perceive) of a Watched (its doc) that does not push."""
    w = Watched(relocate_one, scenes, wait, top_z, perception, outage)
    return w.relocate, w.perceive
