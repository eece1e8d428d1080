"""task_planner node: the Q-Tree training action over the motion planner's feasibility service, then execution.

Thin shell over qtree_task_planner.training / exact: it converts the scene message into a RelocationProblem,
asks PlanFeasibility through a service-client oracle, reports Eq. 15 per episode as action feedback, and
relocates the learned sequence with the motion planner's RelocateObject action.

Interfaces: action ~/train (TrainPlanner); subscribes the scene (`scene_topic`, transient local);
publishes ~/markers (visualization_msgs/MarkerArray: the scene, the learned order).
"""
from __future__ import annotations

import copy
import threading
import time

import rclpy
from rclpy.action import ActionClient, ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile
from visualization_msgs.msg import Marker, MarkerArray

from qtree_relocation_msgs.action import RelocateObject, TrainPlanner
from qtree_relocation_msgs.msg import ObjectArray
from qtree_relocation_msgs.srv import PlanFeasibility
from stpik_motion_planner.scenario import PALETTE, TARGET_RGB, ScenarioError
from stpik_motion_planner.scene_msgs import msg_to_bottles

from . import exact
from .feasibility import CachedOracle, FeasibilityAnswer, Label
from .params import ParameterError, TrainingParams
from .problem import RelocationProblem
from .spin import run_node
from .training import train

SCENE_QOS = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)


class PlannerUnavailable(RuntimeError):
    """The feasibility service did not answer in time (planner dead or overloaded)."""


class ServiceOracle:
    """FeasibilityOracle over the PlanFeasibility service (blocking call from a worker thread)."""

    def __init__(self, client, timeout: float, wait: float) -> None:
        self.client, self.timeout, self.wait = client, timeout, wait

    def feasibility(self, object_id: str, removed: frozenset[str]) -> FeasibilityAnswer:
        if not self.client.wait_for_service(timeout_sec=self.wait):
            raise PlannerUnavailable(f"feasibility service {self.client.srv_name} not available "
                                     f"after {self.wait:.1f} s: is the motion_planner node running?")
        req = PlanFeasibility.Request(object_id=object_id, removed_ids=sorted(removed), timeout=self.timeout)
        done = threading.Event()
        fut = self.client.call_async(req)
        fut.add_done_callback(lambda _: done.set())
        if not done.wait(self.timeout + self.wait):
            self.client.remove_pending_request(fut)
            raise PlannerUnavailable(f"no feasibility answer for {object_id!r} within "
                                     f"{self.timeout + self.wait:.1f} s")
        resp = fut.result()
        if not resp.ok:
            raise ValueError(f"motion planner refused the query for {object_id!r}: {resp.message}")
        return FeasibilityAnswer(Label(resp.label), resp.planning_time, resp.attempts, resp.message)


class TaskPlannerNode(Node):
    def __init__(self) -> None:
        super().__init__("task_planner")
        defaults = TrainingParams.defaults()  # config/task_planner.yaml: the one place for the defaults
        for name, value in defaults.to_dict().items():
            self.declare_parameter(name, value)
        self.declare_parameter("scenario", "")  # accepted for a uniform command line; the scene comes from the topic
        self.declare_parameter("scene_topic", "/scene/objects")
        self.declare_parameter("scene_max_age", 10.0)  # s; older scenes are refused (stale perception)
        self.declare_parameter("feasibility_service", "/motion_planner/plan_feasibility")
        self.declare_parameter("relocate_action", "/motion_planner/relocate")
        self.declare_parameter("feasibility_timeout", 5.0)  # s per query, passed to the planner
        self.declare_parameter("planner_wait", 10.0)  # s to wait for a missing planner before giving up
        self.declare_parameter("relocate_timeout", 180.0)  # s per relocation

        self._scene: tuple[ObjectArray, float] | None = None
        self._busy = threading.Lock()
        reentrant = ReentrantCallbackGroup()
        self._feas = self.create_client(PlanFeasibility, self.p("feasibility_service"),
                                        callback_group=MutuallyExclusiveCallbackGroup())
        self._relocate = ActionClient(self, RelocateObject, self.p("relocate_action"), callback_group=reentrant)
        self.create_subscription(ObjectArray, self.p("scene_topic"), self._on_scene, SCENE_QOS)
        self._markers = self.create_publisher(MarkerArray, "~/markers", SCENE_QOS)
        self._server = ActionServer(self, TrainPlanner, "~/train", execute_callback=self._execute,
                                    goal_callback=self._on_goal, cancel_callback=lambda _: CancelResponse.ACCEPT,
                                    callback_group=reentrant)
        self.get_logger().info(f"ready: action {self.resolve_topic_name('~/train')}, scene from "
                               f"{self.p('scene_topic')}")

    def p(self, name: str):
        return self.get_parameter(name).value

    # -- inputs ---------------------------------------------------------------------------------------------
    def _on_scene(self, msg: ObjectArray) -> None:
        self._scene = (msg, time.monotonic())

    def _problem(self) -> tuple[RelocationProblem, tuple]:
        """The scene as a problem; raises ScenarioError when it is missing, stale, empty or invalid."""
        if self._scene is None:
            raise ScenarioError(f"no scene received on {self.p('scene_topic')}: is perception (or the driver) up?")
        msg, t = self._scene
        age = time.monotonic() - t
        if self.p("scene_max_age") > 0 and age > self.p("scene_max_age"):
            raise ScenarioError(f"the scene is stale ({age:.1f} s old > scene_max_age)")
        bottles = msg_to_bottles(msg)
        obstacles = [b for b in bottles if not b.is_target]
        target = next(b.id for b in bottles if b.is_target)
        return RelocationProblem(tuple(b.id for b in obstacles), {b.id: b.weight for b in obstacles}, target), msg

    def _params(self, goal) -> TrainingParams:
        node = TrainingParams.from_dict({f: self.p(f) for f in TrainingParams.fields()})
        changes = {f: getattr(goal, f) for f in ("policy", "search") if getattr(goal, f)}
        for f in ("alpha", "gamma", "epsilon0", "epsilon_min", "beta", "max_episodes", "max_steps",
                  "quiet_episodes", "seed"):
            v = getattr(goal, f)
            if not v < 0:  # negative: the node's parameter; NaN goes on to validation and is refused
                changes[f] = v
        return node.replace(**changes)

    def _on_goal(self, goal) -> GoalResponse:
        try:
            self._params(goal)
            self._problem()
        except (ParameterError, ScenarioError, ValueError) as e:
            self.get_logger().error(f"training goal rejected: {e}")
            return GoalResponse.REJECT
        if self._busy.locked():
            self.get_logger().error("training goal rejected: a training is already running")
            return GoalResponse.REJECT
        return GoalResponse.ACCEPT

    # -- the action -----------------------------------------------------------------------------------------
    def _execute(self, goal_handle):
        with self._busy:
            result = TrainPlanner.Result()
            try:
                self._train_and_execute(goal_handle, result)
            except (PlannerUnavailable, ParameterError, ScenarioError, ValueError, KeyError) as e:
                result.success, result.message = False, str(e)
                self.get_logger().error(f"training aborted: {e}")
            if goal_handle.is_cancel_requested:
                goal_handle.canceled()
            elif result.success:
                goal_handle.succeed()
            else:
                goal_handle.abort()
            return result

    def _train_and_execute(self, goal_handle, result) -> None:
        params = self._params(goal_handle.request)
        problem, scene = self._problem()
        self._publish_scene(scene, ())
        oracle = CachedOracle(ServiceOracle(self._feas, self.p("feasibility_timeout"), self.p("planner_wait")))
        optimum = exact.solve(problem, oracle)
        result.optimal_sequence = list(optimum.sequence or ())
        result.optimal_weight = float(optimum.total_weight if optimum.total_weight is not None else -1.0)
        self.get_logger().info(f"exact optimum: {optimum.sequence} weight {optimum.total_weight} "
                               f"({oracle.calls} planner calls)")
        fb = TrainPlanner.Feedback(phase="training")

        def on_episode(stats) -> bool:
            fb.episode, fb.q_sum, fb.tree_nodes = stats.episode, stats.q_sum, stats.tree_nodes
            fb.mp_queries, fb.planner_calls = stats.mp_q, oracle.calls
            goal_handle.publish_feedback(fb)
            return rclpy.ok() and not goal_handle.is_cancel_requested

        r = train(problem, oracle, params, optimal_weight=optimum.total_weight, callback=on_episode)
        result.sequence = list(r.sequence or ())
        result.total_weight = float(r.total_weight if r.total_weight is not None else -1.0)
        result.e_ss, result.mp_q, result.e_first = r.e_ss, r.mp_q, r.e_1st if r.e_1st is not None else -1
        result.planner_calls, result.episodes = oracle.calls, r.episodes
        result.q_sum_history = [float(x) for x in r.q_sum_history]
        if r.cancelled or not r.found:
            result.success = False
            result.message = "cancelled" if r.cancelled else "training did not find a sequence to the target"
            return
        self.get_logger().info(f"learned {r.sequence} weight {r.total_weight:.2f} in {r.episodes} episodes")
        self._publish_scene(scene, r.sequence)
        if not goal_handle.request.execute:
            result.success, result.message = True, "trained (not executed)"
            return
        fb.phase = "executing"
        removed: list[str] = []
        for object_id in r.sequence:
            goal_handle.publish_feedback(fb)
            if goal_handle.is_cancel_requested:
                result.message = f"cancelled after relocating {removed}"
                return
            ok, message = self._relocate_one(object_id, removed)
            if not ok:
                result.success, result.message = False, f"relocating {object_id!r} failed: {message}"
                return
            removed.append(object_id)
        result.success, result.message = True, f"target {problem.target!r} retrieved after {len(removed) - 1} relocations"

    def _relocate_one(self, object_id: str, removed: list[str]) -> tuple[bool, str]:
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
        self._relocate.send_goal_async(RelocateObject.Goal(object_id=object_id, removed_ids=list(removed))
                                       ).add_done_callback(on_goal)
        if not done.wait(self.p("relocate_timeout")):
            return False, f"no result within {self.p('relocate_timeout')} s"
        if box.get("rejected"):
            return False, "goal rejected by the motion planner"
        res = box["result"].result
        return res.success, res.message

    # -- visualisation --------------------------------------------------------------------------------------
    def _publish_scene(self, scene: ObjectArray, sequence) -> None:
        """The scene's bottles as cylinders in their colour, each labelled with its place in the learned order."""
        arr = MarkerArray()
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
    run_node(TaskPlannerNode, args)


if __name__ == "__main__":
    main()
