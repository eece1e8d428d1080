"""task_planner node: the Q-Tree training action over the motion planner's feasibility service, then execution.

Thin shell: parameters, the scene subscription and the TrainPlanner action in; calls to the core out. The job (exact
optimum, training, relocations in order, scene checks) is qtree_task_planner.executive.retrieval, the checkpoint
bookkeeping qtree_task_planner.executive.keeper, the ROS clients (feasibility oracle over PlanFeasibility, the watched
RelocateObject goal) qtree_task_planner.ros_clients. Eq. 15 is reported as action feedback every few episodes. The
scene's objects the scenario does not list and what the hand cannot grasp are said in the log and the result.

Interfaces: action ~/train (TrainPlanner); subscribes the scene (`scene_topic`, transient local); publishes
~/markers (visualization_msgs/MarkerArray: the scene, the learned order), ~/relocating (std_msgs/String, latched: the
object being relocated), ~/execution (std_msgs/String, latched: the execution's JSON, closed_loop.ExecutionResult
with `execution_s`, `relocate_s` and `running`, after each relocation and re-plan: what was done outlives the goal)
and /diagnostics ("task_planner: goal": ros_clients.goal_health); its PlanFeasibility queries and answers are
service events on <feasibility_service>/_service_event. Execution: closed-loop (docs/closed_loop.md) or open-loop.

Reliability (docs/reliability.md): checkpoints (`checkpoint_path`, every `checkpoint_every` episodes, on stop and
on a lost planner; a matching goal resumes, a corrupt or mismatched one aborts with the reason); a dead planner
(no answer within feasibility_timeout + feasibility_margin) rolls the episode back, keeps every answer and waits up
to `planner_wait` s, then the goal aborts saying what to do (re-plans during the execution too); a motion planner
lost during a relocation is waited for as long and the goal sent again (ros_clients.Relocator); a scene source that
goes silent after a relocation is waited for up to `scene_outage_wait` s; a stale or empty scene aborts the goal
before training (scene_max_age); bad parameters at start: one line on stderr, exit status 2. A goal sent again after
this node was respawned during an execution (executive.resume): a relocate goal still running (the motion planner's
action status) is waited for before the scene is read; the bottles the motion planner placed (`relocated_topic`,
latched) and the scene does not show on the top shelf are relocated before the goal, left out of its problem and
named removed in every question and relocation; a checkpoint of the earlier scene is not reused (said in the log).
"""
from __future__ import annotations

import dataclasses
import json
import threading
import time
from typing import Any, Sequence

import rclpy
from action_msgs.msg import GoalStatus, GoalStatusArray
from qtree_relocation_msgs.action import RelocateObject, TrainPlanner
from qtree_relocation_msgs.msg import ObjectArray
from qtree_relocation_msgs.srv import PlanFeasibility
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.action.server import ServerGoalHandle
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile
from rclpy.service_introspection import ServiceIntrospectionState
from std_msgs.msg import String
from visualization_msgs.msg import MarkerArray

from qtree_task_planner.executive.closed_loop import ExecutionResult
from qtree_task_planner.executive.keeper import CheckpointKeeper
from qtree_task_planner.executive.outage import Cancelled, PlannerUnavailable, UntilPlanner
from qtree_task_planner.executive.push import PUSH, PushActions
from qtree_task_planner.executive.replicas import ReplicaOracle
from qtree_task_planner.executive.resume import StartPoint, WithGone, start_point
from qtree_task_planner.executive.retrieval import (
    chosen_sequence,
    execute,
    planner_foreign_ids,
    scene_notes,
    solve_then_train,
    training_outcome,
)
from qtree_task_planner.executive.settings import (
    SCENE_SOURCES,
    check_node_parameters,
    pushes_on,
)
from qtree_task_planner.executive.world import Tolerances
from qtree_task_planner.learning.checkpoint import Checkpoint, CheckpointError
from qtree_task_planner.learning.params import TrainingParams
from qtree_task_planner.learning.q_tree import QTree
from qtree_task_planner.learning.training import EpisodeStats
from qtree_task_planner.markers import scene_markers
from qtree_task_planner.oracles import CachedOracle
from qtree_task_planner.problem import ActionCosts, RelocationProblem
from qtree_task_planner.ros_clients import (
    GOAL_STATUS,
    MOTION_WAIT,
    Relocator,
    SceneWatch,
    ServiceOracle,
    Watched,
    fill_optimum,
    fill_training_result,
    goal_health,
    goal_params,
    seen_scene,
    through_outages,
    train_goal,
)
from qtree_task_planner.search.astar import AStarResult
from relocation_common.config import ParameterError
from relocation_common.feasibility import replica_services
from relocation_common.node import ActionClient, Health, declare_parameters, end_goal, node_main, stop_reason
from relocation_common.ros_conversions import msg_to_objects
from relocation_common.scenario import ScenarioError, load_scenario

__all__ = ["TaskPlannerNode", "ServiceOracle", "train_goal", "main"]  # ServiceOracle, train_goal: ros_clients
SCENE_QOS = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
ACTIVE = (GoalStatus.STATUS_ACCEPTED, GoalStatus.STATUS_EXECUTING, GoalStatus.STATUS_CANCELING)  # a goal running
FEEDBACK_EVERY = 10  # episodes between training feedbacks (and after a slow planner answer: training.CALLBACK_S)


class TaskPlannerNode(Node):
    """The task_planner node: ~/train (TrainPlanner) over the scene, ~/markers and ~/relocating out."""

    def __init__(self) -> None:
        """Parameters from config/task_planner.yaml (ParameterError naming a bad one), clients, the action."""
        super().__init__("task_planner")
        declare_parameters(self)  # config/task_planner.yaml: training parameters and the node's own
        check_node_parameters(self.p)  # ParameterError naming the first unusable one (main(): one line, exit 2)
        self._action_cost = ActionCosts.from_parameters(self.p)  # relocating i costs phi_i x its action's factor
        self._tolerances = Tolerances.from_parameters(self.p)  # the closed loop's "as planned"

        self._scenes = SceneWatch()  # the latest scene and when it came
        log = self.get_logger()
        self._keeper = CheckpointKeeper(self.p("checkpoint_path"), info=log.info,
                                        error=lambda m: log.error(m, throttle_duration_sec=10.0))
        self._reserve = threading.Lock()
        self._reserved = False  # a training goal is accepted and not finished
        reentrant = ReentrantCallbackGroup()
        self._feas = [self.create_client(PlanFeasibility, name, callback_group=MutuallyExclusiveCallbackGroup())
                      for name in replica_services(self.p("feasibility_service"), self.p("replicas"))]
        for c in self._feas:
            c.configure_introspection(self.get_clock(), QoSProfile(depth=1000), ServiceIntrospectionState.CONTENTS)
        self._relocator = Relocator(
            ActionClient(self, RelocateObject, self.p("relocate_action"), callback_group=reentrant),
            self.p("planner_wait"), self.p("relocate_timeout"), self.p("relocate_silence"), ok=rclpy.ok,
            resume_wait=self.p("planner_wait"))
        self._scene_topic = SCENE_SOURCES.get(self.p("scene_source")) or self.p("scene_topic")
        self.create_subscription(ObjectArray, self._scene_topic, self._scenes.put, SCENE_QOS)
        self._placed: dict[str, int] | None = None  # the motion planner's ~/relocated (None before the first)
        self.create_subscription(String, self.p("relocated_topic"), self._on_placed, SCENE_QOS)
        self._motions: list[int] = []  # the statuses of the motion planner's relocate goals (its action's status)
        self.create_subscription(GoalStatusArray, self.p("relocate_action") + "/_action/status", self._on_motions,
                                 SCENE_QOS)
        self._markers = self.create_publisher(MarkerArray, "~/markers", SCENE_QOS)
        self._relocating = self.create_publisher(String, "~/relocating", SCENE_QOS)
        self._execution = self.create_publisher(String, "~/execution", SCENE_QOS)  # ExecutionResult.to_dict() JSON
        self._server = ActionServer(self, TrainPlanner, "~/train", execute_callback=self._execute,
                                    goal_callback=self._on_goal, cancel_callback=lambda _: CancelResponse.ACCEPT,
                                    callback_group=reentrant)
        self._fb: TrainPlanner.Feedback | None = None  # the running goal's feedback, for the health
        self._progress: dict[str, Any] = {}  # the execution so far
        self.health = Health(self, GOAL_STATUS, "task planner",
                             lambda: goal_health(self._fb, self._progress, self._scenes.age()))
        self.get_logger().info(f"ready: action {self.resolve_topic_name('~/train')}, scene from {self._scene_topic}")

    def p(self, name: str) -> Any:
        """The value of parameter `name` (of the type config/task_planner.yaml gives it)."""
        return self.get_parameter(name).value

    # -- inputs ---------------------------------------------------------------------------------------------
    def _on_placed(self, msg: String) -> None:
        try:
            self._placed = {str(k): int(v) for k, v in dict(json.loads(msg.data)["relocated"]).items()}
        except (ValueError, KeyError, TypeError) as e:
            self.get_logger().error(f"{self.p('relocated_topic')}: not {{\"relocated\": {{id: slot}}}}: {e}")

    def _on_motions(self, msg: GoalStatusArray) -> None:
        self._motions = [st.status for st in msg.status_list]

    def _motion_ended(self, goal_handle: ServerGoalHandle, fb: TrainPlanner.Feedback) -> None:
        """Before a goal reads its scene: a relocate goal of the motion planner still running (its client, an earlier
        task planner, died) is waited for up to relocate_timeout, so no second motion starts while the arm moves and
        the goal plans on a scene perceived after it (up to scene_after_wait s for one); said in the feedback."""
        if not any(st in ACTIVE for st in self._motions):
            return
        fb.phase = MOTION_WAIT
        self.get_logger().warning(f"{fb.phase} (an earlier goal's): no motion is started before it ends")
        goal_handle.publish_feedback(fb)
        deadline = time.monotonic() + self.p("relocate_timeout")
        while any(st in ACTIVE for st in self._motions):
            if time.monotonic() > deadline or goal_handle.is_cancel_requested or not rclpy.ok():
                raise Cancelled(f"the motion planner's relocation in flight did not end within relocate_timeout "
                                f"{self.p('relocate_timeout'):g} s" if time.monotonic() > deadline else "cancelled")
            time.sleep(0.1)
        try:
            self._scenes.after(time.monotonic(), self.p("scene_after_wait"))
        except TimeoutError as e:
            self.get_logger().warning(f"after the relocation in flight: {e}")

    def _problem(self) -> tuple[RelocationProblem | None, ObjectArray, StartPoint | None]:
        """The scene as a problem, and where the goal starts when the world changed before it (executive.resume:
        bottles the motion planner placed, objects off the top shelf; then the problem is the top shelf's, None
        when the target was already retrieved or none is left); ScenarioError when the scene is missing, stale,
        empty or invalid (retrieval.check_scene)."""
        msg, warning = self._scenes.checked(self._scene_topic, self.p("scene_max_age"), self.p("scene_wait"),
                                            self.get_clock().now)
        if warning:
            self.get_logger().warning(warning, throttle_duration_sec=60.0)
        topic, deadline = self.p("relocated_topic"), time.monotonic() + self.p("scene_wait")
        while self._placed is None and self.count_publishers(topic) and time.monotonic() < deadline:
            time.sleep(0.05)  # the latched ~/relocated of a motion planner just discovered, as the first scene
        if self._placed is None and self.count_publishers(topic):
            self.get_logger().warning(f"nothing on {topic} within scene_wait: taken as no bottle placed by the motion "
                                      "planner")
        objects, scenario = msg_to_objects(msg, require_target=False), load_scenario(self.p("scenario") or None)
        if any(o.is_target for o in objects):  # else (a relocated target out of view) the scenario's own objects
            scenario = scenario.with_objects(objects)
        start = start_point(scenario, seen_scene(msg), self._placed or {}, self._action_cost, self._tolerances)
        if start is None:
            return RelocationProblem.from_bottles(msg_to_objects(msg), self._action_cost), msg, None
        self.get_logger().info(start.line)
        return start.problem, msg, start

    def _params(self, goal: TrainPlanner.Goal) -> TrainingParams:
        return goal_params(TrainingParams.from_dict({f: self.p(f) for f in TrainingParams.fields()}), goal)

    def _on_goal(self, goal: TrainPlanner.Goal) -> GoalResponse:
        """Only a second goal is rejected here. Bad training parameters and the scene are checked when the goal
        starts: it aborts with the reason in the result (as nav2 does; a rejection carries no reason)."""
        with self._reserve:  # reserved here, not when execution starts: two goals sent back to back
            if self._reserved:
                self.get_logger().error("training goal rejected: a training is already running")
                return GoalResponse.REJECT
            self._reserved = True
        return GoalResponse.ACCEPT

    # -- the action -----------------------------------------------------------------------------------------
    def _execute(self, goal_handle: ServerGoalHandle) -> TrainPlanner.Result:
        result = TrainPlanner.Result()
        try:
            notes = self._train_and_execute(goal_handle, result)  # unlisted objects, what the hand cannot grasp
            result.message += f" ({notes})" if notes else ""
        except (PlannerUnavailable, Cancelled, CheckpointError, ParameterError, ScenarioError, ValueError, KeyError,
                OSError) as e:
            result.success, result.message = False, str(e)
            self.get_logger().error(f"training aborted: {e}")
        finally:
            self._reserved, self._fb = False, None
        end_goal(goal_handle, "canceled" if goal_handle.is_cancel_requested else
                 "succeed" if result.success else "abort")
        return result

    def _train_and_execute(self, goal_handle: ServerGoalHandle, result: TrainPlanner.Result) -> str:
        params = self._params(goal_handle.request)
        fb = self._fb = TrainPlanner.Feedback(phase="exact optimum")
        self._motion_ended(goal_handle, fb)
        problem, scene, start = self._problem()
        self._publish_scene(scene, ())
        fb.phase = "exact optimum"
        self._progress = {}
        before = start.before if start is not None else ()
        if problem is None:  # the target retrieved before this goal, or no problem left (start.line says which)
            assert start is not None
            self._publish_start(start)
            result.success, result.message = start.retrieved, start.line
            return ""
        last = [0.0]

        def on_answer() -> None:  # progress of the exact solve (no episodes yet): planner calls, twice a second
            if fb.phase == "exact optimum" and time.monotonic() - last[0] > 0.5:
                last[0], fb.planner_calls = time.monotonic(), oracle.planner_answers + 1
                goal_handle.publish_feedback(fb)

        service = ReplicaOracle([  # training itself stops at the end of an episode
            ServiceOracle(c, self.p("feasibility_timeout"), self.p("feasibility_margin"), on_answer=on_answer,
                          stop=lambda: fb.phase == "exact optimum" and (goal_handle.is_cancel_requested
                                                                       or not rclpy.ok())) for c in self._feas])
        asked = service if not before else WithGone(service, frozenset(before))  # the planners, told what is gone
        oracle = CachedOracle(asked, reuse=self.p("reuse_answers"))  # answers reused across questions
        missing = [c.srv_name for c in self._feas if not c.service_is_ready()]
        if missing:  # asked anyway (it may be starting); the others answer meanwhile
            self.get_logger().warning(f"feasibility service(s) not available at the start of the goal: "
                                      f"{', '.join(missing)} (replicas: {len(self._feas)})")
        resume = self._keeper.resume_point(problem, params, oracle, changed="the relocations done before this goal"
                                           if start is not None else "")

        until: UntilPlanner = lambda fn: through_outages(  # noqa: E731 (through planner outages: training, re-plans)
            fn, goal_handle, fb, service, self.get_logger(), self.p("planner_wait"), self._keeper.kept_where)
        notes = [""]  # retrieval.scene_notes, after the exact solve

        def on_solved(exact: AStarResult) -> None:
            fill_optimum(result, exact)
            notes[0] = scene_notes(problem, oracle)
            cost = f" cost {exact.total_cost}" if exact.total_cost is not None else ""
            self.get_logger().info(f"exact optimum: {exact.sequence} weight {exact.total_weight}{cost} ({oracle.calls} "
                                   f"planner calls; {service.summary()}){'; ' * bool(notes[0])}{notes[0]}")
            fb.phase = "training"

        def on_episode(stats: EpisodeStats) -> bool:
            fb.episode, fb.q_sum, fb.tree_nodes = stats.episode, stats.q_sum, stats.tree_nodes
            fb.mp_queries, fb.planner_calls = stats.mp_q, oracle.planner_answers
            goal_handle.publish_feedback(fb)
            return rclpy.ok() and not goal_handle.is_cancel_requested

        optimum, r = solve_then_train(problem, oracle, params, resume=resume, keep=self._keep, on_episode=on_episode,
                                      until_planner=until,
                                      checkpoint_every=self.p("checkpoint_every"), on_solved=on_solved,
                                      episode_every=FEEDBACK_EVERY)
        fill_training_result(result, r, oracle.planner_answers)
        if not r.cancelled and (r.found or optimum.found):  # the learned path on the markers, executed or not
            self.get_logger().info(f"learned {r.sequence} weight {r.total_weight:.2f} in {r.episodes} episodes "
                                   f"({service.summary()})" if r.found else
                                   f"training found no sequence in {r.episodes} episodes (the exact optimum exists)")
            self._publish_scene(scene, r.sequence or result.optimal_sequence, r.tree, problem.ids)
        stop = training_outcome(r, optimum, execute=goal_handle.request.execute,  # the exact solver's why_none
                                push=self._pushes())  # ... or the closed loop's pushes go on
        if stop is not None:
            result.success, result.message = stop
            if not stop[0] and not r.cancelled and not optimum.found:
                result.message += planner_foreign_ids(service, problem.ids)
            return notes[0]
        fb.phase = "executing"  # then each check and re-plan (_run)
        self._run(goal_handle, fb, result, scene, oracle, service, params, until, before, *chosen_sequence(
            r.sequence, r.total_weight, result.optimal_sequence, result.optimal_weight if result.optimal_sequence
            else None, execute_optimum=goal_handle.request.execute_optimum, execute_learned=self.p("execute_learned"),
            learned_cost=r.total_cost, optimal_cost=optimum.total_cost))
        if not result.success and not optimum.found and not r.found:  # no sequence at the start, pushes tried
            result.message += planner_foreign_ids(service, problem.ids)
        return notes[0]

    def _pushes(self) -> bool:
        """Whether the execution pushes when no pick sequence remains (settings.pushes_on)."""
        return pushes_on(self.p)

    def _run(self, goal_handle: ServerGoalHandle, fb: TrainPlanner.Feedback, result: TrainPlanner.Result,
             scene: ObjectArray, oracle: CachedOracle, service: ReplicaOracle, params: TrainingParams,
             until: UntilPlanner, before: Sequence[str], sequence: list[str], note: str) -> None:
        """Execute (retrieval.execute, `closed_loop`; `replan_q_tree`: each re-plan also retrains the Q-Tree with the
        goal's params): checks, re-plans in the feedback; the outcome on ~/execution
        with `execution_s` (the whole execution) and `relocate_s` (the relocations' own part; the rest is the
        executor's: for the closed loop, its scene waits, checks and re-plans). Pushes (`max_pushes`, closed loop
        only): asked of `service`, executed through the Relocator (action "push"). `before`: the relocations done
        before this goal (executive.resume), sent as removed."""
        base, objects = load_scenario(self.p("scenario") or None), msg_to_objects(scene)
        ids = {o.id for o in objects}  # and the listed bottles relocated before this goal that the scene leaves out
        scenario = base.with_objects(objects + tuple(base.object(o) for o in before if o in base.ids and o not in ids))
        seen = self._scene_topic == SCENE_SOURCES["sim"]  # ground truth shows the bottom shelf, perception does not
        spent = {"relocate_s": 0.0}  # the relocations' own time: the rest of the execution is the executor's

        def relocate_timed(object_id: str, removed: list[str]) -> tuple[bool, str]:
            t = time.monotonic()
            try:
                return self._relocate_one(goal_handle, object_id, removed)
            finally:
                spent["relocate_s"] += time.monotonic() - t

        def push_timed(object_id: str, clear_for: str, removed: list[str]) -> tuple[bool, str]:
            t = time.monotonic()
            try:
                return self._push_one(goal_handle, object_id, clear_for, removed)
            finally:
                spent["relocate_s"] += time.monotonic() - t

        w = Watched(relocate_timed, self._scenes, self.p("scene_after_wait"), scenario.shelf.top_z,
                    perception=not seen, outage=self.p("scene_outage_wait"), push_one=push_timed)

        def phase(text: str) -> None:
            fb.phase = text
            self.get_logger().info(text)
            goal_handle.publish_feedback(fb)

        pushes = PushActions(service.push, w.push, lambda: self._action_cost.push, self.p("max_pushes"),
                             service.what_if, phase) if self._pushes() else None

        def publish(out: ExecutionResult, running: bool = True) -> None:
            self._progress = out.to_dict()
            if rclpy.ok():  # a goal ended by the node stopping: its publisher's context is gone
                self._execution.publish(String(data=json.dumps({**self._progress, "sequence": sequence, "note": note,
                                                                "running": running,
                                                                "execution_s": time.monotonic() - t0, **spent})))

        t0 = time.monotonic()
        out = execute(scenario, sequence, seen_scene(scene), w.relocate, w.perceive, oracle,
                      closed_loop=self.p("closed_loop"), cancelled=lambda: goal_handle.is_cancel_requested,
                      before_each=lambda: goal_handle.publish_feedback(fb), on_step=lambda st: phase(st.line()),
                      on_replan=lambda rr: phase(rr.line()), bottom_seen=seen,
                      retrain=params if self.p("replan_q_tree") else None, on_progress=publish, until_planner=until,
                      action_cost=self._action_cost, pushes=pushes, on_push=lambda record: phase(record.line()),
                      tolerances=self._tolerances, before=before)
        result.success, result.message = out.success, out.message + (f" ({note})" if note else "")
        publish(out, running=False)

    def _publish_start(self, start: StartPoint) -> None:
        """~/execution for a goal that relocates nothing (its start point ended it): what was relocated before."""
        out = ExecutionResult(start.retrieved, start.line, list(start.before))
        self._progress = out.to_dict()
        self._execution.publish(String(data=json.dumps({**self._progress, "sequence": [], "note": "", "running": False,
                                                        "execution_s": 0.0, "relocate_s": 0.0})))

    def _keep(self, ck: Checkpoint) -> None:
        """The keeper's keep; a training cancelled because the node is stopping says so (stop_reason)."""
        if ck.reason == "cancelled" and not rclpy.ok():
            ck = dataclasses.replace(ck, reason=stop_reason())
        self._keeper.keep(ck)

    def _relocate_one(self, goal_handle: ServerGoalHandle, object_id: str, removed: list[str]) -> tuple[bool, str]:
        self.get_logger().info(f"relocating {object_id} (removed so far: {removed})")
        self._relocating.publish(String(data=object_id))
        return self._relocator.relocate(object_id, removed, cancelled=lambda: goal_handle.is_cancel_requested)

    def _push_one(self, goal_handle: ServerGoalHandle, object_id: str, clear_for: str, removed: list[str]
                  ) -> tuple[bool, str]:
        self.get_logger().info(f"pushing {object_id} out of {clear_for}'s lanes (removed so far: {removed})")
        self._relocating.publish(String(data=object_id))
        return self._relocator.relocate(object_id, removed, cancelled=lambda: goal_handle.is_cancel_requested,
                                        action=PUSH, clear_for=clear_for)

    # -- visualisation --------------------------------------------------------------------------------------
    def _publish_scene(self, scene: ObjectArray, sequence: Sequence[str], tree: QTree | None = None,
                       ids: Sequence[str] = ()) -> None:
        """The scene and the learned order (and the trained Q-Tree) as markers (qtree_task_planner.markers)."""
        self._markers.publish(scene_markers(scene, tuple(sequence), tree.to_state() if tree is not None else None,
                                            tuple(ids)))


def main(args: list[str] | None = None) -> None:
    """Run the node (relocation_common.node.node_main: exit 2 with one line on a bad parameter)."""
    node_main("task_planner", TaskPlannerNode, args, errors=(CheckpointError,))


if __name__ == "__main__":
    main()
