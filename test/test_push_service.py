"""The push through the motion planner's service (ROS-free; the node only translates messages): the feasibility
answer of action "push" (its end pose, its refusals with reasons) and the RelocateObject action "push" carried out
on a streamed arm (test_streaming.FakeLink), after which the planner models the pushed object at its end pose."""
from __future__ import annotations

import dataclasses
import math
import time
from pathlib import Path

import numpy as np
import pytest
from push_layouts import beside_layout
from test_streaming import FakeLink, arm

from relocation_common import robot_description as rd
from relocation_common.feasibility import Label
from relocation_common.kinova import joint_to_turns
from stpik_motion_planner.execution.goal_check import OUTCOME_SETTLE
from stpik_motion_planner.execution.journal import Journal
from stpik_motion_planner.execution.relocation import PUSH_PHASES
from stpik_motion_planner.execution.streaming import StreamParams
from stpik_motion_planner.planning.params import PlannerParams
from stpik_motion_planner.service import MotionPlannerService

PARAMS = dataclasses.replace(PlannerParams.load(), timeout=300.0, carry_timeout=300.0)


@pytest.fixture(scope="module")
def service():
    return MotionPlannerService(beside_layout(0), PARAMS)


def test_a_push_answer_names_the_end_pose_and_a_refusal_its_reason(service):
    ans, plan = service.push_feasibility("X", [], "T")
    x = service.planner.scenario.object("X")
    assert ans.label == Label.OBSTACLE and plan is not None and ans.trajectory is not None
    assert plan.end[2] == service.base.shelf.top_z and plan.distance > 0
    assert plan.end[0] == pytest.approx(x.x + plan.distance * math.cos(plan.yaw))
    lanes = service.planner.lane_blockers([])
    far = next(i for i, ls in lanes.items() if i not in ("X", "T") and ls and not any("X" in b.objects for b in ls))
    ans, plan = service.push_feasibility("X", [], far)
    assert ans.label == Label.UNFEASIBLE and plan is None
    assert f"no grasp lane of {far} is blocked by X" in ans.message
    with pytest.raises(ValueError, match="another object"):
        service.push_feasibility("X", [], "X")
    with pytest.raises(ValueError, match="clear_for"):
        service.push_feasibility("X", [], "")


def test_what_would_follow_a_push_is_asked_on_the_moved_scene_and_the_scene_is_kept(service):
    """The feasibility question with `moved` (PlanFeasibility moved_ids, moved_to) is answered on the scene with X
    at the push's predicted end, as a planner given that scene answers it; the planner's own scene, and its answers,
    are unchanged; a bad what-if scene is refused with the reason."""
    from stpik_motion_planner.model.push import moved
    from stpik_motion_planner.planning.planner import MotionPlanner
    _, plan = service.push_feasibility("X", [], "T")
    end = {"X": plan.end[:2]}
    before = service.feasibility("T", [])[1]
    _, after = service.feasibility("T", [], moved=end)
    fresh = MotionPlanner(moved(service.planner.scenario, "X", *plan.end[:2]), PARAMS).feasibility("T", [])
    assert before.label == Label.UNFEASIBLE and after.label == Label.TARGET == fresh.label, after.message
    lanes, _ = service.feasibility("", [], all_lanes=True, moved=end)
    opened = [b for b in lanes["T"] if b.lane == plan.lane]
    assert opened and not any("X" in b.objects for b in opened), lanes["T"]  # the lane the push opens, open
    again = service.feasibility("T", [])[1]
    assert (again.label, again.blockers) == (before.label, before.blockers)
    assert service.planner.scenario.object("X").x != pytest.approx(plan.end[0])
    t = service.planner.scenario.object("T")
    for bad, why in [({"nope": (0.7, 0.0)}, "unknown object"), ({"X": (math.nan, 0.0)}, "finite"),
                     ({"X": (3.0, 0.0)}, "not on the top shelf"), ({"X": (t.x, t.y + 0.01)}, "overlaps T")]:
        with pytest.raises((KeyError, ValueError), match=why):
            service.feasibility("T", [], moved=bad)
    assert service.feasibility("T", [], moved=end)[1].label == Label.TARGET  # the planner keeps serving


def test_a_push_goal_moves_the_object_in_the_planners_scene_and_checks_the_outcome(service):
    _, plan = service.push_feasibility("X", [], "T")
    start = {b.id: b for b in service.bottles.values()}
    z = service.base.shelf.top_z
    service.update_scene([dataclasses.replace(b, support_z=z) for b in start.values()])
    link = FakeLink(kinova=True)
    a, feedback, _ = arm(link)
    posted = []

    modelled = []

    def perceive():  # the scene after the motion (OUTCOME_SETTLE later): X where the push predicted, 3 mm off
        posted.append(time.monotonic())
        o = service.planner.scenario.object("X")
        modelled.append((o.x, o.y))
        if posted[-1] - posted[0] > 2 * OUTCOME_SETTLE:
            service.update_scene([dataclasses.replace(b, x=plan.end[0] + 0.003, y=plan.end[1], support_z=z)
                                  if b.id == "X" else dataclasses.replace(b, support_z=z) for b in start.values()])
        return True

    assert service.planner.scenario.object("X").x == start["X"].x
    out = service.push(a, "X", [], "T", ok=perceive)
    assert out.status == "succeeded", out.message
    assert "pushed X" in out.message
    assert [p for p, _ in feedback if p in PUSH_PHASES and p != "recover_push"][0] == "plan_push"
    assert {"shut", "approach_push", "push", "retreat_push", "home_push", "open", "pushed"} <= {p for p, _ in feedback}
    assert modelled[0] == pytest.approx(plan.end[:2])  # after the push, before a scene: modelled at its end pose
    assert service.planner.scenario.object("X").x == pytest.approx(plan.end[0] + 0.003)  # the scene's, seen after


def test_a_push_whose_object_ends_elsewhere_fails_its_outcome(service):
    _, plan = service.push_feasibility("X", [], "T")
    z = service.base.shelf.top_z
    start = {b.id: b for b in service.bottles.values()}
    link = FakeLink(kinova=True)
    a, _, _ = arm(link)
    posted = []

    def perceive():  # X did not move at all
        posted.append(time.monotonic())
        if posted[-1] - posted[0] > 2 * OUTCOME_SETTLE:
            service.update_scene([dataclasses.replace(b, support_z=z) for b in start.values()])
        return True

    out = service.push(a, "X", [], "T", ok=perceive)
    assert out.status == "aborted" and "from its predicted end pose" in out.message, out.message


def test_a_lying_object_whose_slide_opens_nothing_is_not_pushed_and_says_why():
    """headroom_lying_6's o1 lies in T's lanes: each slide along its axis would bring it near o2 or o3 or leave T's
    lanes blocked; the service answers g_U with those reasons (with push.slide off: "o1 lies (push.slide ...")."""
    from relocation_common.paths import config_file
    from relocation_common.scenario import load_scenario

    s = MotionPlannerService(load_scenario(config_file("scenarios/headroom_lying_6.yaml")), PARAMS)
    ans, plan = s.push_feasibility("o1", [], "T")
    assert ans.label == Label.UNFEASIBLE and plan is None, ans.message
    assert ans.message.startswith("no push direction clears T's lanes: T's lanes still blocked by o1"), ans.message


def test_a_push_cancelled_during_the_push_goes_back_and_opens_the_gripper(service):
    link = FakeLink(kinova=True)
    a, feedback, _ = arm(link, cancelled=lambda: "push" in link.paths)  # cancelled once the push starts
    out = service.push(a, "X", [], "T")
    assert out.status == "canceled", out.message
    assert "recovered: arm back home along the push of X, gripper open" in out.message
    assert link.paths[:2] == ["approach_push", "push"] and link.paths[2:] == ["recover_push"] * 2
    assert float(np.max(np.abs(link.q - rd.Q_HOME))) < 0.02


def _killed_during(phase: str, after: float, journal: Path) -> tuple[FakeLink, str]:
    """A push carried out by a service with a journal at `journal`, its process "killed" `after` s into `phase`:
    the link goes dead then (no recovery runs: the node is shutting down), and the journal is taken as it was at that
    moment (what a SIGKILL leaves). (the dead link: where the arm and the fingers stopped; that journal's text)."""
    s = MotionPlannerService(beside_layout(0), PARAMS, journal=Journal(journal))
    link = FakeLink()
    left: list[str] = []
    started: list[float] = []

    def dying() -> bool:  # polled by the arm every command
        if phase in link.paths and not left:
            started.append(time.monotonic())
            if started[-1] - started[0] >= after:
                left.append(journal.read_text() if journal.exists() else "")  # none yet: none left
                link.alive = False
        return False

    a, _, _ = arm(link, cancelled=dying)
    out = s.push(a, "X", [], "T")
    assert out.status == "aborted" and left, out.message
    return link, left[0]


def _restarted(dead: FakeLink, text: str, journal: Path) -> tuple[MotionPlannerService, FakeLink]:
    """A new process on the journal `text`, the arm and the fingers where the dead one left them."""
    if text:
        journal.write_text(text)
    link = FakeLink()
    link.q, link.fingers, link.target = dead.q.copy(), dead.fingers.copy(), dead.target
    return MotionPlannerService(beside_layout(0), PARAMS, journal=Journal(journal)), link


def _open(link: FakeLink) -> bool:
    return bool(np.all(joint_to_turns(link.fingers) < 0.1 * StreamParams.load().finger_closed))


def test_a_planner_killed_mid_push_brings_the_arm_home_with_the_fingers_open(tmp_path):
    """Killed 0.5 s into the push itself (the arm in the shelf, the fingers shut): the push is in the journal, and
    the new process brings the arm home from where it is (back along the push and the approach) and opens the
    fingers before any goal; the push goal sent again is aborted, saying so (the object's end is not known: the
    task planner re-plans from the scene). Before, a push was not journalled: the new process had nothing to
    recover and its next goal started with the arm in the shelf, the fingers shut."""
    dead, text = _killed_during("push", 0.5, tmp_path / "j")
    assert not _open(dead) and float(np.max(np.abs(dead.q - rd.Q_HOME))) > 0.1
    s, link = _restarted(dead, text, tmp_path / "j2")
    assert s.interrupted is not None, "the push was not in the journal"
    a, _, _ = arm(link)
    what = s.recover_interrupted(a)
    assert "arm back home along the push of X, gripper open" in what, what
    assert float(np.max(np.abs(link.q - rd.Q_HOME))) < 0.02 and _open(link)
    assert set(link.paths) == {"recover_push"}
    assert Journal(tmp_path / "j2").load()[1] is None
    out = s.push(a, "X", [], "T")
    assert out.status == "aborted" and "interrupted: the motion planner restarted during this push" in out.message


def test_a_planner_killed_on_the_retreat_goes_on_home_and_models_the_object_pushed(tmp_path):
    """Killed 0.3 s into the retreat (the object at its predicted end pose): the new process goes on along the
    planned retreat and way home (never back into the object), opens the fingers, and models the object at the
    push's predicted end pose until a scene says where it is; the push goal sent again is answered by the scene
    now (X seen 3 mm from its predicted end: succeeded, saying the planner restarted)."""
    dead, text = _killed_during("retreat_push", 0.3, tmp_path / "j")
    s, link = _restarted(dead, text, tmp_path / "j2")
    assert s.interrupted is not None and s.interrupted.push is not None, "the push was not in the journal"
    end = s.interrupted.push.end
    a, _, _ = arm(link)
    what = s.recover_interrupted(a)
    assert "X was pushed; arm on along its way home, gripper open" in what, what
    assert float(np.max(np.abs(link.q - rd.Q_HOME))) < 0.02 and _open(link)
    x = s.planner.scenario.object("X")
    assert (x.x, x.y) == pytest.approx(end[:2])
    z = s.base.shelf.top_z
    seen = [dataclasses.replace(b, x=end[0] + 0.003, y=end[1], support_z=z) if b.id == "X" else
            dataclasses.replace(b, support_z=z) for b in beside_layout(0).objects]
    posted: list[float] = []

    def perceive():  # the first scene after the goal, OUTCOME_SETTLE later
        posted.append(time.monotonic())
        if posted[-1] - posted[0] > 2 * OUTCOME_SETTLE:
            s.update_scene(seen)
        return True

    out = s.push(a, "X", [], "T", ok=perceive)
    assert out.status == "succeeded" and "restarted during this push" in out.message, out.message
