"""motion_planner node: a thin ROS 2 shell over stpik_motion_planner.service.MotionPlannerService (paper Sect. 4.1).

- service `~/plan_feasibility` (PlanFeasibility): Eq. 11's answer g_U / g_O / g_T for (object, removed set),
  with the home -> grasp trajectory unless the request asks for the label only, the action a feasible answer is for
  (`action`: side_grasp or top_grasp) and the objects the pick comes near (`near_ids`); with `certify`, the
  certification of the whole relocation (docs/motion_planner.md, "Lazy certification"); a bad request answers
  ok=false with the reason, the node keeps serving. Served by its own executor thread (SideNode), not the main
  executor.
- action `~/relocate` (RelocateObject): plan the pick, stream joint velocities at 100 Hz with feedback from the
  joint states, close the gripper, plan and stream the carry to the next slot of the bottom shelf, release,
  retreat, plan and stream the way home (service.py, streaming.py). Feedback by phase; cancel stops the arm; a
  silent driver aborts the goal with the reason. The driver's surface: config/arm_interface.yaml, shared with the
  driver (relocation_common.arm_interface, docs/kinova.md; ros_interface.RosArmLink).
- `~/path` (visualization_msgs/Marker, latched): the tool path of the motion being executed, as a line strip.
- the scene: the scenario file (shelf, slots, initial bottles), updated from `scene_topic` (ObjectArray,
  transient local; a scene without the target too: perception's once the target is relocated). Bottles no longer
  on the top shelf are ignored; bottles not seen keep their last pose.
- `~/relocated` (std_msgs/String, latched): JSON {"relocated": {id: slot}}, the bottles this node placed on the
  bottom shelf (perception publishes its scene without a relocated target, out of the camera's view).
- `journal_path`: the relocation (and push) journal; started after a process that died mid-relocation or mid-push,
  the node first brings the arm back from it (service.py), goals waiting meanwhile.
- /diagnostics: "motion_planner: ..." (relocation_common.node.Health): feasibility questions in flight and answered,
  the last answer, the relocation running, the recovery after a restart, the age of the last joint state.
"""
from __future__ import annotations

import json
import os
import threading
import time

import rclpy
from qtree_relocation_msgs.action import RelocateObject
from qtree_relocation_msgs.msg import ObjectArray
from qtree_relocation_msgs.srv import PlanFeasibility
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.action.server import ServerGoalHandle
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.node import Node
from rclpy.qos import QoSDurabilityPolicy, QoSProfile
from std_msgs.msg import String
from visualization_msgs.msg import Marker

from relocation_common import arm_interface
from relocation_common.arm_interface import ArmInterface
from relocation_common.config import ParameterError
from relocation_common.feasibility import PUSH
from relocation_common.node import Health, SideNode, declare_parameters, node_main
from relocation_common.ros_conversions import (
    NO_ANSWER,
    blockers_to_msgs,
    lanes_to_msgs,
    moved_from_fields,
    msg_to_objects,
    near_to_fields,
)
from relocation_common.scenario import ScenarioError, UnknownObjectError, load_scenario
from stpik_motion_planner.execution import goal_check
from stpik_motion_planner.execution.journal import Journal
from stpik_motion_planner.execution.streaming import StreamedArm, StreamParams
from stpik_motion_planner.planning.budget import SafetyNetTimeout
from stpik_motion_planner.planning.params import PlannerParams
from stpik_motion_planner.ros_interface import RosArmLink, trajectory_to_msg
from stpik_motion_planner.service import RESTART_STATE_WAIT, MotionPlannerService, Outcome

SCENE_QOS = QoSProfile(depth=1, durability=QoSDurabilityPolicy.TRANSIENT_LOCAL)
# Requests queue here while one is planned: the default depth 10 dropped all but 11 of 50 concurrent requests
# silently (their clients waited forever); 1000 answers a burst of a whole tree level.
SERVICE_QOS = QoSProfile(depth=1000)
EXIT_NO_STATE = 75  # EX_TEMPFAIL: no joint state heard while one was needed (_check_first_state): start it again


class MotionPlannerNode(Node):
    """The motion planner node (the module docstring)."""

    def __init__(self) -> None:
        super().__init__("motion_planner")
        # config/motion_planner.yaml (planner, follower.* and node keys) and config/arm_interface.yaml
        params = declare_parameters(self, shared=(arm_interface.FILE,))
        planner_params = PlannerParams.from_mapping({k: v for k, v in params.items() if k in PlannerParams.keys()})
        arm = ArmInterface.from_mapping(params)  # the surface, shared with the driver; ParameterError
        self.core = MotionPlannerService(load_scenario(params["scenario"] or None), planner_params,
                                         float(params["home_tol"]), log=self._log,
                                         journal=Journal(params["journal_path"] if params["serve_relocation"] else ""),
                                         recover_near=float(params["recover_near"]),
                                         phantom_scenes=params["phantom_scenes"])
        self.link: RosArmLink | None = None  # nothing in a feasibility-only replica (serve_relocation false)
        self.asked, self.answered, self.last_answer = 0, 0, (0.0, "none yet")  # feasibility, for the health
        self.scene_seen = threading.Event()  # a scene came on scene_topic (_on_scene)
        self.relocation = "idle"  # what the relocate action does now, for the health
        if params["serve_relocation"]:
            goal_check.check_parameters({k: params[k] for k in goal_check.PARAMETERS})
            self.core.checks = {k: float(params[k]) for k in goal_check.PARAMETERS}
            self.stream_params = StreamParams.from_mapping(params)
            self.link = RosArmLink(self, arm, self.create_publisher(Marker, "~/path", SCENE_QOS))
            self._relocated = self.create_publisher(String, "~/relocated", SCENE_QOS)
            self.core.on_relocated = self._publish_relocated
            self._publish_relocated(self.core.relocated)
            first_wait = float(params["first_state_wait"])
            if not 0.0 < first_wait < RESTART_STATE_WAIT:
                raise ParameterError(f"parameter first_state_wait must be > 0 s and below the {RESTART_STATE_WAIT:g} s "
                                     f"a restart's recovery waits for joint states, got {params['first_state_wait']}")
            self._first_state = self.create_timer(first_wait, self._check_first_state)
            if self.core.interrupted is not None:  # a previous process died mid-relocation: the arm back first
                run = self.core.interrupted
                self.relocation = (f"recovering the {'relocation' if run.push is None else 'push'} of "
                                   f"{run.progress.object_id}")
                threading.Thread(target=self._recover_interrupted, name="restart recovery", daemon=True).start()
        self.create_subscription(ObjectArray, params["scene_topic"], self._on_scene, SCENE_QOS,
                                 callback_group=MutuallyExclusiveCallbackGroup())
        # the feasibility service on a node of its own, spun by its own single-threaded executor (a thread): an
        # answer waits for no thread of the main executor (held by relocations) and scans a wait set of one service
        self._feas = SideNode("motion_planner_feasibility", context=self.context)
        self._feas.node.create_service(PlanFeasibility, self.resolve_service_name("~/plan_feasibility"),
                                       self._on_feasibility, qos_profile=SERVICE_QOS)
        if self.link is not None:
            self._server = ActionServer(self, RelocateObject, "~/relocate", execute_callback=self._execute,
                                        goal_callback=self._on_goal, cancel_callback=lambda _: CancelResponse.ACCEPT,
                                        callback_group=ReentrantCallbackGroup())
        self.scene_topic = params["scene_topic"]
        self.scene_wait = float(params["scene_wait"])
        if not self.scene_wait >= 0.0:
            raise ParameterError(f"parameter scene_wait must be >= 0 s, got {params['scene_wait']}")
        base = self.core.base
        driver = arm.driver_prefix if arm.kinova else "ros2_control"
        self.get_logger().info(f"ready: scenario {base.name} ({len(base.objects)} objects), service "
                               f"{self.resolve_service_name('~/plan_feasibility')}, scene from {self.scene_topic}, "
                               + (f"driver {driver}" if self.link else "feasibility only (serve_relocation false)"))
        if base.slot_note:
            self.get_logger().warning(base.slot_note)
        self.health = Health(self, f"{self.get_fully_qualified_name().lstrip('/')}: planning", "motion planner",
                             self._health)

    def _health(self) -> tuple[int, str, dict[str, str]]:
        """The node's status (relocation_common.node.Health): WARN while recovering after a restart."""
        at, what = self.last_answer
        values = {"feasibility questions in flight": str(self.asked - self.answered),
                  "feasibility answers": str(self.answered),
                  "last answer": f"{what} ({time.monotonic() - at:.0f} s ago)" if at else what,
                  "relocation": self.relocation, "relocated": json.dumps(self.core.relocated)}
        if self.link is not None:
            state = self.link.joint_state_age()
            values["joint state"] = "none yet" if state is None else f"{state:.1f} s ago"
        level = 1 if self.relocation.startswith("recovering") else 0
        return level, f"relocation: {self.relocation}; {self.asked - self.answered} feasibility questions in flight", \
            values

    def _check_first_state(self) -> None:
        """One look, first_state_wait s after start-up: no joint state came, and the driver's joint-state publisher
        is in the graph or the journal has a relocation to recover. This process's DDS transport then receives
        nothing (its discovery may be as deaf: the publisher need not be seen). Seen once in ten full test runs: a
        motion planner respawned after a SIGKILL, with Fast DDS's shared-memory errors "Failed init_port ...:
        open_and_lock_file failed" in its log (eProsima/Fast-DDS#1144, Fast-DDS#6117), heard no joint state for
        30 s and its recovery failed. The process exits EXIT_NO_STATE at once, its journal kept, so that its
        launcher starts it again (config/graph.yaml) and the new process, with new transport ports, recovers the
        arm. A hard exit: a shutdown would end the recovery waiting meanwhile, and that clears the journal."""
        self._first_state.cancel()
        assert self.link is not None
        needed = ("an interrupted relocation to recover" if self.core.interrupted is not None else
                  "the driver publishes them" if self.link.driver_present() else "")
        if self.link.joint_state_age() is not None or not needed:
            return  # states come, or none is expected: a planner without a driver answers feasibility questions
        self.get_logger().fatal(
            f"no joint state on {self.link.state_topic} within first_state_wait and {needed}: this process hears "
            f"nothing over DDS; exiting {EXIT_NO_STATE} for the launcher to start it again (docs/reliability.md, "
            "\"A node that hears nothing\")")
        os._exit(EXIT_NO_STATE)

    def _publish_relocated(self, relocated: dict[str, int]) -> None:
        self._relocated.publish(String(data=json.dumps({"relocated": relocated})))

    def _recover_interrupted(self) -> None:
        assert self.link is not None
        arm = StreamedArm(self.link, self.stream_params, log=self._log)
        self.relocation = f"recovered after a restart: {self.core.recover_interrupted(arm)}"

    def _log(self, level: str, text: str) -> None:
        """The cores' log lines. One call site per severity: rclpy refuses a call site whose severity changes."""
        if level == "error":
            self.get_logger().error(text)
        elif level == "warning":
            self.get_logger().warning(text, throttle_duration_sec=1.0)
        else:
            self.get_logger().info(text)

    def close(self) -> None:
        """Stop the side executors (feasibility service, joint states)."""
        self._feas.close()
        if self.link is not None:
            self.link.close()

    def _on_scene(self, msg: ObjectArray) -> None:
        """Bottles on the top shelf (standing or lying) replace the planner's, bottles off the shelf leave it; the
        rest of the scene stays (service.update_scene)."""
        try:  # without the target too: perception's scene once the target is relocated, out of its view
            stamp = (msg.header.stamp.sec, msg.header.stamp.nanosec)
            changed = self.core.update_scene(msg_to_objects(msg, require_target=False), f"scene on {self.scene_topic}",
                                             stamp if stamp != (0, 0) else None)
        except ScenarioError as e:
            self.get_logger().warning(f"scene ignored: {e}", throttle_duration_sec=5.0)
            return
        self.scene_seen.set()
        if changed:
            self.get_logger().info(f"scene updated from {self.scene_topic}: {changed}")

    def _on_feasibility(self, req: PlanFeasibility.Request, res: PlanFeasibility.Response) -> PlanFeasibility.Response:
        """PlanFeasibility -> MotionPlannerService.feasibility (Eq. 11); ok=false with the reason for a bad one."""
        res.ok = False
        self.asked += 1
        try:
            res = self._answer(req, res)
        finally:
            self.answered += 1
            self.last_answer = (time.monotonic(), f"{req.object_id or 'lanes'}: " + (
                f"label {res.label}" if res.ok else res.message[:80]))
        return res

    def _feasibility(self, req: PlanFeasibility.Request) -> tuple:
        """core.feasibility of the request ((lanes, answer, the push's plan or None)), or core.push_feasibility for
        action "push", on the scene with the objects of moved_ids at moved_to when given (what would follow a
        push). A question naming an object the planner does not know, asked before any scene came (a client that
        discovered the scene's publisher sooner: an unlisted object it saw), waits up to scene_wait for that scene
        and is asked again."""
        if req.action not in ("", PUSH):
            raise ValueError(f"action must be '' (a pick) or 'push', got {req.action!r}")
        moved = moved_from_fields(req.moved_ids, req.moved_to)

        def ask() -> tuple:
            if req.action == PUSH:
                lanes = self.core.feasibility("", list(req.removed_ids), None, True, moved=moved)[0] \
                    if req.all_lanes else {}
                return (lanes, *self.core.push_feasibility(req.object_id, list(req.removed_ids), req.clear_for,
                                                           req.timeout, moved))
            return (*self.core.feasibility(req.object_id, list(req.removed_ids), req.timeout, req.all_lanes,
                                           req.certify, moved), None)

        try:
            return ask()
        except UnknownObjectError:
            if self.scene_seen.is_set() or not self.scene_seen.wait(self.scene_wait):
                raise
            return ask()

    def _answer(self, req: PlanFeasibility.Request, res: PlanFeasibility.Response) -> PlanFeasibility.Response:
        try:
            lanes, ans, push = self._feasibility(req)
        except (UnknownObjectError, ScenarioError, ValueError, TypeError) as e:
            res.message = str(e)
            self.get_logger().warning(f"feasibility request refused: {e}")
            return res
        except SafetyNetTimeout as e:
            res.message = f"{NO_ANSWER}{e}"
            self.get_logger().warning(res.message)
            return res
        except Exception as e:  # a planner bug must not take the node down
            res.message = f"internal planner error: {type(e).__name__}: {e}"
            self.get_logger().error(res.message)
            return res
        res.ok, res.lanes = True, lanes_to_msgs(lanes)
        if ans is None:
            res.message = "lanes only"
            return res
        res.label, res.planning_time = int(ans.label), float(ans.planning_time)
        res.attempts, res.message, res.action = int(ans.attempts), ans.message, ans.action
        if not req.label_only:  # training asks for the label only; execution for the trajectory too
            res.trajectory = trajectory_to_msg(ans.trajectory)
        res.blockers = blockers_to_msgs(ans.blockers)
        res.near_known, res.near_ids = near_to_fields(ans.near)
        if push is not None:  # a feasible push: its action and the pushed object's predicted pose
            res.action = PUSH
            res.end_pose.position.x, res.end_pose.position.y, res.end_pose.position.z = map(float, push.end)
            res.end_pose.orientation.w = 1.0  # standing, as it stood (quasi-static, no rotation kept)
        return res

    def _on_goal(self, goal: RelocateObject.Goal) -> GoalResponse:
        """Only a second goal is rejected; a goal the scene refuses is accepted, then aborted with the reason."""
        if self.core.busy():
            self.get_logger().error("relocation goal rejected: a relocation is already running")
            return GoalResponse.REJECT
        return GoalResponse.ACCEPT

    def _execute(self, goal_handle: ServerGoalHandle) -> RelocateObject.Result:
        """RelocateObject -> MotionPlannerService.relocate on this goal's arm; the outcome ends the goal."""
        assert self.link is not None  # the action server exists only with a link
        arm = StreamedArm(self.link, self.stream_params, lambda: goal_handle.is_cancel_requested,
                          lambda phase, p: goal_handle.publish_feedback(RelocateObject.Feedback(phase=phase,
                                                                                                progress=p)),
                          self._log)
        req = goal_handle.request
        self.relocation = f"relocating {req.object_id} (removed {list(req.removed_ids)})"
        source = f"the scene on {self.scene_topic}"
        if req.action == PUSH:
            self.relocation = f"pushing {req.object_id} out of the lanes of {req.clear_for}"
            outcome = self.core.push(arm, req.object_id, list(req.removed_ids), req.clear_for, source, rclpy.ok)
        elif req.action:
            outcome = Outcome("aborted", f"relocation goal refused: action must be '' (pick and place) or 'push', "
                                         f"got {req.action!r}")
        else:
            outcome = self.core.relocate(arm, req.object_id, list(req.removed_ids), source, rclpy.ok)
        self.relocation = f"idle; last: {req.object_id} {outcome.status}: {outcome.message[:120]}"
        {"succeeded": goal_handle.succeed, "canceled": goal_handle.canceled, "aborted": goal_handle.abort}[
            outcome.status]()
        return RelocateObject.Result(success=outcome.status == "succeeded", message=outcome.message)


def main(args: list[str] | None = None) -> None:
    """The motion_planner executable."""
    node_main("motion_planner", MotionPlannerNode, args, threads=6)


if __name__ == "__main__":
    main()
