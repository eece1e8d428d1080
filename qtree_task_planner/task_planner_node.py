"""task_planner node: the Q-Tree training action over the motion planner's feasibility service, then execution.

Thin shell over qtree_task_planner.training / exact: it converts the scene message into a RelocationProblem,
asks PlanFeasibility through a service-client oracle, reports Eq. 15 per episode as action feedback, and
relocates the learned sequence with the motion planner's RelocateObject action.

Interfaces: action ~/train (TrainPlanner); subscribes the scene (`scene_topic`, transient local);
publishes ~/markers (visualization_msgs/MarkerArray: the scene, the learned order) and ~/relocating (std_msgs/String,
latched: the object being relocated); its PlanFeasibility queries and answers are service events (client
introspection, contents) on <feasibility_service>/_service_event, for recording.

Reliability (docs/reliability.md):
- Checkpoints: with `checkpoint_path` set, the Q-Tree and the training counters are written there atomically every
  `checkpoint_every` episodes, when training stops, and when the planner is lost; a goal whose scene and
  parameters match an existing checkpoint resumes from it; a corrupt or mismatched checkpoint aborts the goal
  with the reason (never a silent restart from scratch).
- Dead planner: a query unanswered within feasibility_timeout + feasibility_margin (or a service that vanished)
  rolls the current episode back, keeps every answer, and waits up to `planner_wait` s for the service to come
  back, then resumes; after that the goal aborts saying what to do.
- Stale or empty scene: the goal aborts with the reason before training starts (scene_max_age, by receive time
  and by header stamp).
- Bad parameters at start: one line on stderr, exit status 2.
"""
from __future__ import annotations

import copy
import dataclasses
import math
import tempfile
import threading
import time
from pathlib import Path

import rclpy
from qtree_relocation_msgs.action import RelocateObject, TrainPlanner
from qtree_relocation_msgs.msg import ObjectArray
from qtree_relocation_msgs.srv import PlanFeasibility
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile
from rclpy.service_introspection import ServiceIntrospectionState
from rclpy.time import Time
from std_msgs.msg import String
from visualization_msgs.msg import Marker, MarkerArray

from relocation_common.config import ParameterError
from relocation_common.feasibility import FeasibilityAnswer, Label, replica_services
from relocation_common.node import ActionClient, call, declare_parameters, end_goal, node_main, stop_reason, stopping_as
from relocation_common.ros_conversions import NO_ANSWER, blockers_from_msgs, lanes_from_msgs, msg_to_bottles
from relocation_common.scenario import PALETTE, TARGET_RGB, ScenarioError
from relocation_common.scene_check import foreign_ids

from .checkpoint import Checkpoint, CheckpointError, load_checkpoint, save_checkpoint
from .markers import tree_markers
from .oracles import CachedOracle
from .outage import Cancelled, PlannerUnavailable, until_available
from .params import TrainingParams
from .problem import RelocationProblem
from .replicas import ReplicaOracle
from .retrieval import execute_sequence, solve_then_train

SCENE_QOS = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
STAMP_PLAUSIBLE = 86400.0  # s: a scene stamp further from this node's clock is on another clock
SCENE_SOURCES = {"perception": "/scene/objects", "sim": "/sim/objects"}  # scene_source -> topic


def check_checkpoint_path(path: str) -> None:
    """ParameterError at start for a checkpoint_path that cannot hold a checkpoint: a directory, something that is
    not a regular file (a FIFO would block the goal forever), or a directory where no file can be created (a
    read-only filesystem; tried for real, as permission bits do not stop root)."""
    if not path:
        return
    p = Path(path)
    if p.is_dir():
        raise ParameterError(f"checkpoint_path {path!r} is a directory: give a file name")
    if p.exists() and not p.is_file():
        raise ParameterError(f"checkpoint_path {path!r} exists and is not a regular file")
    try:
        p.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=p.parent, prefix=f".{p.name}.probe-"):
            pass
    except OSError as e:
        raise ParameterError(f"checkpoint_path {path!r}: cannot write in {str(p.parent)!r} ({e.strerror or e}); "
                             "give a writable location") from None


class ServiceOracle:
    """FeasibilityOracle over the PlanFeasibility service (blocking call from a worker thread).

    Raises PlannerUnavailable as soon as the service is missing (after `connect_wait` s), when it disappears from
    the graph while a query is pending (a clean shutdown), or when no answer came within timeout + margin (a
    killed or wedged planner). `last_ok` is the monotonic time of the last answer. Raises Cancelled before a query
    when `stop()` is true (goal cancelled, node shutting down); `on_answer()` is called after each answer."""

    def __init__(self, client, timeout: float, margin: float, connect_wait: float = 1.0,
                 stop=lambda: False, on_answer=lambda: None) -> None:
        self.client, self.timeout, self.margin, self.connect_wait = client, timeout, margin, connect_wait
        self.stop, self.on_answer = stop, on_answer
        self.last_ok = time.monotonic()
        self.name = client.srv_name

    def ready(self, timeout: float) -> bool:
        with stopping_as(Cancelled):  # the node stopping: Cancelled with the reason, never rclpy's RCLError
            return self.client.service_is_ready() or (timeout > 0 and self.client.wait_for_service(timeout_sec=timeout))

    def feasibility(self, object_id: str, removed: frozenset[str]) -> FeasibilityAnswer:
        # the label only: training never uses the trajectory (about 5 ms of a feasible answer's round trip)
        req = PlanFeasibility.Request(object_id=object_id, removed_ids=sorted(removed), timeout=self.timeout,
                                      label_only=True)
        resp = self._call(req, repr(object_id))
        return FeasibilityAnswer(Label(resp.label), resp.planning_time, resp.attempts, resp.message,
                                 blockers=blockers_from_msgs(resp.blockers))

    def lane_blockers(self, removed: frozenset[str]) -> dict:
        """Every remaining object's lane blockers at once (the planner's screen, no planning: all_lanes); None
        from a planner that refuses the question (one without lane blockers: the A* then learns from answers)."""
        req = PlanFeasibility.Request(object_id="", removed_ids=sorted(removed), timeout=self.timeout, all_lanes=True)
        try:
            return lanes_from_msgs(self._call(req, "the lane blockers").lanes)
        except ValueError:
            return None

    def _call(self, req, what: str):
        with stopping_as(Cancelled):  # the node stopping mid-query: Cancelled with the reason, never RCLError
            return self._call_once(req, what)

    def _call_once(self, req, what: str):
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


NODE_DEFAULT_FIELDS = ("alpha", "gamma", "epsilon0", "epsilon_min", "beta", "max_episodes", "max_steps",
                       "quiet_episodes", "seed")  # numeric goal fields: negative = the node's parameter


def train_goal(**fields) -> TrainPlanner.Goal:
    """A TrainPlanner goal whose numeric settings say "use the node's parameter" (negative) unless given."""
    goal = TrainPlanner.Goal()
    for f in NODE_DEFAULT_FIELDS:
        setattr(goal, f, type(getattr(goal, f))(-1))
    for k, v in fields.items():
        setattr(goal, k, v)
    return goal


class TaskPlannerNode(Node):
    def __init__(self) -> None:
        super().__init__("task_planner")
        declare_parameters(self)  # config/task_planner.yaml: training parameters and the node's own
        self._check_parameters()

        self._scene: tuple[ObjectArray, float] | None = None
        self._memory_ckpt: Checkpoint | None = None  # the last checkpoint, also when checkpoint_path is empty
        self._written: tuple[int, str] | None = None  # (episode, "") of the last one on disk, or (episode, error)
        self._reserve = threading.Lock()
        self._reserved = False  # a training goal is accepted and not finished
        reentrant = ReentrantCallbackGroup()
        self._feas = [self.create_client(PlanFeasibility, name, callback_group=MutuallyExclusiveCallbackGroup())
                      for name in replica_services(self.p("feasibility_service"), self.p("replicas"))]
        for c in self._feas:
            c.configure_introspection(self.get_clock(), QoSProfile(depth=1000), ServiceIntrospectionState.CONTENTS)
        self._relocate = ActionClient(self, RelocateObject, self.p("relocate_action"), callback_group=reentrant)
        self._scene_topic = SCENE_SOURCES.get(self.p("scene_source")) or self.p("scene_topic")
        self.create_subscription(ObjectArray, self._scene_topic, self._on_scene, SCENE_QOS)
        self._markers = self.create_publisher(MarkerArray, "~/markers", SCENE_QOS)
        self._relocating = self.create_publisher(String, "~/relocating", SCENE_QOS)
        self._server = ActionServer(self, TrainPlanner, "~/train", execute_callback=self._execute,
                                    goal_callback=self._on_goal, cancel_callback=lambda _: CancelResponse.ACCEPT,
                                    callback_group=reentrant)
        self.get_logger().info(f"ready: action {self.resolve_topic_name('~/train')}, scene from "
                               f"{self._scene_topic}")

    def p(self, name: str):
        return self.get_parameter(name).value

    def _check_parameters(self) -> None:
        """ParameterError naming the first unusable parameter (main() prints it as one line and exits 2)."""
        TrainingParams.from_dict({f: self.p(f) for f in TrainingParams.fields()})
        for name, lo in (("scene_max_age", 0.0), ("scene_wait", 0.0), ("feasibility_timeout", 1e-3),
                         ("feasibility_margin", 0.0), ("planner_wait", 0.0), ("relocate_timeout", 1e-3),
                         ("relocate_silence", 1e-3)):
            v = self.p(name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v < lo:
                raise ParameterError(f"{name} must be a finite number >= {lo:g}, got {v!r}")
        if self.p("scene_source") not in ("", *SCENE_SOURCES):
            raise ParameterError(f"scene_source must be one of {', '.join(SCENE_SOURCES)} (or empty: scene_topic), "
                                 f"got {self.p('scene_source')!r}")
        n = self.p("replicas")
        if isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= 64:
            raise ParameterError(f"replicas must be an integer in 1..64 (motion planners), got {n!r}")
        every = self.p("checkpoint_every")
        if isinstance(every, bool) or not isinstance(every, int) or every < 1:
            raise ParameterError(f"checkpoint_every must be an integer >= 1 (episodes), got {every!r}")
        check_checkpoint_path(self.p("checkpoint_path"))

    # -- inputs ---------------------------------------------------------------------------------------------
    def _on_scene(self, msg: ObjectArray) -> None:
        self._scene = (msg, time.monotonic())

    def _problem(self) -> tuple[RelocationProblem, tuple]:
        """The scene as a problem; raises ScenarioError when it is missing, stale, empty or invalid.

        Stale: received longer than scene_max_age ago, or (a stamped message) stamped longer ago than that, which
        catches an old scene handed over by transient-local durability from a perception that stopped."""
        topic, max_age = self._scene_topic, self.p("scene_max_age")
        deadline = time.monotonic() + self.p("scene_wait")
        while self._scene is None and time.monotonic() < deadline:  # just started: discovery may still be going on
            time.sleep(0.05)
        if self._scene is None:
            raise ScenarioError(f"no scene received on {topic}: is perception (or the driver) up?")
        msg, t = self._scene
        age = time.monotonic() - t
        if max_age > 0 and age > max_age:
            raise ScenarioError(f"the scene on {topic} is stale: received {age:.1f} s ago > scene_max_age "
                                f"{max_age:g} s; is perception still running?")
        stamp = Time.from_msg(msg.header.stamp)
        if max_age > 0 and stamp.nanoseconds > 0:
            stamp_age = (self.get_clock().now() - stamp).nanoseconds * 1e-9
            if not -1.0 < stamp_age < STAMP_PLAUSIBLE:  # another clock (simulated time vs wall time): not comparable
                self.get_logger().warning(f"scene stamp {stamp_age:.0f} s away from this node's clock: is one of them "
                                          "on use_sim_time? Checking the scene's age by receive time only",
                                          throttle_duration_sec=60.0)
            elif stamp_age > max_age:
                raise ScenarioError(f"the scene on {topic} is stale: stamped {stamp_age:.1f} s ago > scene_max_age "
                                    f"{max_age:g} s; is perception still running?")
        if not msg.objects:
            raise ScenarioError(f"the scene on {topic} is empty: perception sees no objects (camera, marker, "
                                "lighting?)")
        bottles = msg_to_bottles(msg)
        obstacles = [b for b in bottles if not b.is_target]
        target = next(b.id for b in bottles if b.is_target)
        return RelocationProblem(tuple(b.id for b in obstacles), {b.id: b.weight for b in obstacles}, target), msg

    def _params(self, goal) -> TrainingParams:
        node = TrainingParams.from_dict({f: self.p(f) for f in TrainingParams.fields()})
        changes = {f: getattr(goal, f) for f in ("policy", "search") if getattr(goal, f)}
        for f in NODE_DEFAULT_FIELDS:
            v = getattr(goal, f)
            if not v < 0:  # negative: the node's parameter; NaN goes on to validation and is refused
                changes[f] = v
        return node.replace(**changes)

    def _on_goal(self, goal) -> GoalResponse:
        """Only a second goal is rejected here. Bad training parameters and the scene are checked when the goal
        starts: it aborts with the reason in the result (as nav2 does; a rejection carries no reason)."""
        with self._reserve:  # reserved here, not when execution starts: two goals sent back to back
            if self._reserved:
                self.get_logger().error("training goal rejected: a training is already running")
                return GoalResponse.REJECT
            self._reserved = True
        return GoalResponse.ACCEPT

    # -- the action -----------------------------------------------------------------------------------------
    def _execute(self, goal_handle):
        result = TrainPlanner.Result()
        try:
            self._train_and_execute(goal_handle, result)
        except (PlannerUnavailable, Cancelled, CheckpointError, ParameterError, ScenarioError, ValueError, KeyError,
                OSError) as e:
            result.success, result.message = False, str(e)
            self.get_logger().error(f"training aborted: {e}")
        finally:
            self._reserved = False
        end_goal(goal_handle, "canceled" if goal_handle.is_cancel_requested else
                 "succeed" if result.success else "abort")
        return result

    # -- checkpoints and a lost planner ---------------------------------------------------------------------
    def _resume_point(self, problem, params, cache) -> Checkpoint | None:
        """The checkpoint this goal resumes from: the file at checkpoint_path when it exists (CheckpointError if
        it is corrupt or for another scene/params), else an unfinished in-memory one of the same goal."""
        path = self.p("checkpoint_path")
        if path and Path(path).is_file():
            ck = load_checkpoint(path)
            ck.check_matches(problem, params, f"checkpoint {path}")
        elif self._memory_ckpt is not None and self._memory_ckpt.reason.startswith("interrupted"):
            # no file (never written, or removed): what this node kept in memory still counts
            ck = self._memory_ckpt
            try:
                ck.check_matches(problem, params)
            except CheckpointError:
                return None
        else:
            return None
        ck.fill_cache(cache)
        self.get_logger().info(f"resuming from checkpoint {path if ck is not self._memory_ckpt else '(in memory)'}: "
                               f"episode {ck.episode}, "
                               f"{len(ck.tree['nodes'])} tree nodes, {len(ck.feasibility)} feasibility answers")
        return ck

    def _keep(self, ck: Checkpoint) -> None:
        if ck.reason == "cancelled" and not rclpy.ok():  # the training stopped because the node is stopping
            ck = dataclasses.replace(ck, reason=stop_reason())
        self._memory_ckpt = ck
        path = self.p("checkpoint_path")
        if path:
            try:
                save_checkpoint(ck, path)
                self._written = (ck.episode, "")
            except OSError as e:  # training goes on; the in-memory copy still holds it
                self._written = (self._written[0] if self._written else -1, f"{e.strerror or e}")
                self.get_logger().error(f"cannot write checkpoint {path}: {e}", throttle_duration_sec=10.0)

    def _kept_where(self) -> str:
        """Where what was learned is, exactly: never a file that was not written, never a newer episode."""
        ck, path = self._memory_ckpt, self.p("checkpoint_path")
        memory = f"in memory at episode {ck.episode}" if ck is not None else "in memory"
        if not path:
            return f"{memory} only (set checkpoint_path to keep it across restarts)"
        episode, error = self._written if self._written else (-1, "")
        on_disk = f"checkpoint {path} at episode {episode}" if episode >= 0 else ""
        if ck is not None and ck.episode == episode and not error:
            return on_disk
        failed = f" (writing {path} failed: {error})" if error else ""
        return "; ".join(filter(None, [on_disk, memory + failed]))

    def _until_planner(self, fn, goal_handle, oracle: ReplicaOracle, fb):
        """fn() through planner outages (qtree_task_planner.outage), with feedback while waiting."""
        phase = fb.phase

        def on_outage(message: str) -> None:
            self.get_logger().warning(message)
            fb.phase = "waiting for planner"
            goal_handle.publish_feedback(fb)

        services = " or ".join(c.srv_name for c in self._feas)

        def on_back() -> None:
            fb.phase = phase
            self.get_logger().info(f"motion planner {services} is back: resuming")

        return until_available(fn, service_up=oracle.ready,
                               stop=lambda: goal_handle.is_cancel_requested or not rclpy.ok(),
                               wait=self.p("planner_wait"), last_answer=lambda: oracle.last_ok,
                               kept=self._kept_where, service=services, on_outage=on_outage, on_back=on_back)

    def _train_and_execute(self, goal_handle, result) -> None:
        params = self._params(goal_handle.request)
        problem, scene = self._problem()
        self._publish_scene(scene, ())
        fb = TrainPlanner.Feedback(phase="exact optimum")
        last = [0.0]

        def on_answer() -> None:  # progress of the exact solve (no episodes yet): planner calls, twice a second
            if fb.phase == "exact optimum" and time.monotonic() - last[0] > 0.5:
                last[0], fb.planner_calls = time.monotonic(), len(oracle.table) + 1
                goal_handle.publish_feedback(fb)

        service = ReplicaOracle([  # training itself stops at the end of an episode
            ServiceOracle(c, self.p("feasibility_timeout"), self.p("feasibility_margin"), on_answer=on_answer,
                          stop=lambda: fb.phase == "exact optimum" and (goal_handle.is_cancel_requested
                                                                       or not rclpy.ok())) for c in self._feas])
        oracle = CachedOracle(service)
        missing = [c.srv_name for c in self._feas if not c.service_is_ready()]
        if missing:  # asked anyway (it may be starting); the others answer meanwhile
            self.get_logger().warning(f"feasibility service(s) not available at the start of the goal: "
                                      f"{', '.join(missing)} (replicas: {len(self._feas)})")
        resume = self._resume_point(problem, params, oracle)
        self._memory_ckpt = resume

        def on_solved(optimum) -> None:
            result.optimal_sequence = list(optimum.sequence or ())
            result.optimal_weight = float(optimum.total_weight if optimum.total_weight is not None else -1.0)
            self.get_logger().info(f"exact optimum: {optimum.sequence} weight {optimum.total_weight} "
                                   f"({oracle.calls} planner calls; {service.summary()})")
            fb.phase = "training"

        def on_episode(stats) -> bool:
            fb.episode, fb.q_sum, fb.tree_nodes = stats.episode, stats.q_sum, stats.tree_nodes
            fb.mp_queries, fb.planner_calls = stats.mp_q, len(oracle.table)
            goal_handle.publish_feedback(fb)
            return rclpy.ok() and not goal_handle.is_cancel_requested

        _, r = solve_then_train(problem, oracle, params, resume=resume, keep=self._keep, on_episode=on_episode,
                                until_planner=lambda fn: self._until_planner(fn, goal_handle, service, fb),
                                checkpoint_every=self.p("checkpoint_every"), on_solved=on_solved)
        result.sequence = list(r.sequence or ())
        result.total_weight = float(r.total_weight if r.total_weight is not None else -1.0)
        result.e_ss, result.mp_q, result.e_first = r.e_ss, r.mp_q, r.e_1st if r.e_1st is not None else -1
        result.planner_calls, result.episodes = len(oracle.table), r.episodes
        result.q_sum_history = [float(x) for x in r.q_sum_history]
        if r.cancelled or not r.found:
            result.success = False
            result.message = "cancelled" if r.cancelled else "training did not find a sequence to the target" + \
                self._foreign_ids(service, problem)
            return
        self.get_logger().info(f"learned {r.sequence} weight {r.total_weight:.2f} in {r.episodes} episodes "
                               f"({service.summary()})")
        self._publish_scene(scene, r.sequence, r.tree, problem.ids)
        if not goal_handle.request.execute:
            result.success, result.message = True, "trained (not executed)"
            return
        fb.phase = "executing"
        sequence = result.optimal_sequence if goal_handle.request.execute_optimum else r.sequence
        result.success, result.message, _ = execute_sequence(
            sequence, lambda i, removed: self._relocate_one(goal_handle, i, removed),
            cancelled=lambda: goal_handle.is_cancel_requested, before_each=lambda: goal_handle.publish_feedback(fb))

    def _foreign_ids(self, oracle, problem) -> str:
        """scene_check.foreign_ids: the motion planner's bottles (its lanes, all_lanes) this scene does not have."""
        try:
            return foreign_ids(oracle.lane_blockers(frozenset()) or {}, problem.ids)
        except Exception:  # a diagnosis only: the planner gone or refusing the question says nothing
            return ""

    def _relocate_one(self, goal_handle, object_id: str, removed: list[str]) -> tuple[bool, str]:
        if not self._relocate.wait_for_server(timeout_sec=self.p("planner_wait")):
            return False, "relocate action server not available"
        done = threading.Event()
        box = {}

        def on_result(fut):
            box["result"] = fut.result()
            done.set()

        def on_goal(fut):
            h = fut.result()
            if not h.accepted:
                box["rejected"] = True
                done.set()
                return
            h.get_result_async().add_done_callback(on_result)

        self.get_logger().info(f"relocating {object_id} (removed so far: {removed})")
        self._relocating.publish(String(data=object_id))
        heard = [time.monotonic()]  # the last feedback: a moving motion planner reports at 10 Hz

        def on_feedback(_) -> None:
            heard[0] = time.monotonic()

        sent = self._relocate.send_goal_async(RelocateObject.Goal(object_id=object_id, removed_ids=list(removed)),
                                              feedback_callback=on_feedback)
        sent.add_done_callback(on_goal)
        limit, silence = self.p("relocate_timeout"), self.p("relocate_silence")
        deadline = time.monotonic() + limit
        while not done.wait(0.1):  # never blind: the node stopping, the planner gone, the goal cancelled
            now = time.monotonic()
            why = ("the task planner is shutting down" if not rclpy.ok() else
                   "the motion planner went away (relocate action server gone)" if not self._relocate.server_is_ready()
                   else f"the motion planner went away (no feedback for {now - heard[0]:.0f} s > relocate_silence)"
                   if now - heard[0] > silence else "cancelled" if goal_handle.is_cancel_requested else
                   f"no result within {limit:g} s (relocate_timeout)" if now > deadline else None)
            if why is not None:
                if sent.done() and sent.result() is not None and sent.result().accepted and rclpy.ok():
                    sent.result().cancel_goal_async()  # the arm stops (the motion planner's cancel)
                return False, why
        if box.get("rejected"):
            return False, "goal rejected by the motion planner"
        res = box["result"].result
        return res.success, res.message

    # -- visualisation --------------------------------------------------------------------------------------
    def _publish_scene(self, scene: ObjectArray, sequence, tree=None, ids=()) -> None:
        """The scene's bottles as cylinders in their colour, each labelled with its place in the learned order;
        with a trained tree, the Q-Tree beside the shelf (qtree_task_planner.markers)."""
        arr = MarkerArray()
        if tree is not None:
            arr.markers += tree_markers(tree.to_state(), tuple(ids), tuple(sequence), scene.header.frame_id).markers
        order = {o: k + 1 for k, o in enumerate(sequence)}
        for k, o in enumerate(scene.objects):
            m = Marker(ns="scene", id=k, type=Marker.CYLINDER, action=Marker.ADD, header=scene.header)
            m.pose = copy.deepcopy(o.pose)
            m.pose.position.z += o.height / 2
            m.scale.x = m.scale.y = 2 * o.radius
            m.scale.z = o.height
            m.color.r, m.color.g, m.color.b, m.color.a = (*PALETTE.get(o.label, TARGET_RGB), 1.0)
            t = Marker(ns="order", id=k, type=Marker.TEXT_VIEW_FACING, action=Marker.ADD, header=scene.header)
            t.pose = copy.deepcopy(o.pose)
            t.pose.position.z += o.height + 0.04
            t.scale.z = 0.03
            t.color.r = t.color.g = t.color.b = t.color.a = 1.0
            t.text = f"{o.id} ({order[o.id]})" if o.id in order else o.id
            arr.markers += [m, t]
        self._markers.publish(arr)


def main(args=None) -> None:
    node_main("task_planner", TaskPlannerNode, args, errors=(CheckpointError,))


if __name__ == "__main__":
    main()
