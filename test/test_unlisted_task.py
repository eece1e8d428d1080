"""The task planner's problem is the scene's objects, listed or not, and what it says of them
(qtree_task_planner.problem.RelocationProblem.from_bottles, executive.retrieval.scene_notes), over the real motion
planner: an unlisted object is an obstacle with its estimated weight; an object the hand cannot grasp stays an
obstacle, never relocated, with the planner's reason. Before, the log and the result said neither.
"""
from __future__ import annotations

import pytest

from jaco2_sim_driver.messages import objects_msg, time_msg
from jaco2_sim_driver.sim import Jaco2Sim
from qtree_task_planner.executive.retrieval import scene_notes
from qtree_task_planner.oracles import CachedOracle
from qtree_task_planner.problem import ProblemError, RelocationProblem
from qtree_task_planner.search import astar
from relocation_common.ros_conversions import msg_to_objects
from relocation_common.scenario import load_scenario
from stpik_motion_planner.planning.params import PlannerParams
from stpik_motion_planner.planning.planner import MotionPlanner

UNLISTED = load_scenario("config/scenarios/world/paper_experiment_10_unlisted.yaml")
BOXES = load_scenario("config/scenarios/world/shapes_box_10.yaml")


def test_the_problem_of_a_scene_holds_its_unlisted_objects_with_their_estimates():
    scene = msg_to_objects(objects_msg(UNLISTED, Jaco2Sim(UNLISTED).object_poses(), time_msg(0.0)))
    p = RelocationProblem.from_bottles(scene)
    assert "x1" in p.obstacles and p.target == "T" and len(p.obstacles) == 11
    assert p.estimated == {"x1": "0.45 L x 600 kg/m3 = 0.27 kg"} and p.weights["x1"] == pytest.approx(0.2714, abs=1e-4)
    assert p.unlisted_line() == "unlisted (obstacles, weight estimated): x1 phi 0.27 (0.45 L x 600 kg/m3 = 0.27 kg)"
    assert RelocationProblem.from_scenario(UNLISTED).unlisted_line() == ""
    with pytest.raises(ProblemError, match="estimated weights must be of obstacles"):
        RelocationProblem(("a",), {"a": 0.5}, "T", {"T": "x"})


def test_the_notes_name_what_the_hand_cannot_grasp_with_the_planner_s_reason():
    """shapes_box_10: o9 stays an obstacle (its faces within the yaw range are 80 mm across, wider than the open
    hand); each of T's lanes holds o9 or a box or bottle held by it (o7's one lane needs o4, o6 or o9 gone; o8 has no
    lane: at its mid-height the hand meets the board), which the A* proves from the lanes alone (before, the boxes
    were answered as bottles of radius 0, some feasible; then every box was refused)."""
    planner = MotionPlanner(BOXES, PlannerParams.load())
    problem = RelocationProblem.from_scenario(BOXES)
    oracle = CachedOracle(planner)
    optimum = astar.solve(problem, oracle)  # o9 has no lane: every lane through it is closed for good
    assert not optimum.found and optimum.oracle_calls == 0 and "o9 has no lane" in optimum.reason, optimum.reason
    assert "o7 needs one of {o4, o6, o9} moved" in optimum.reason, optimum.reason
    notes = scene_notes(problem, oracle)
    assert notes.startswith("never relocated, the hand cannot grasp them: o9 (no grasp: o9 is a box (box 0.08 x "
                            "0.06 x 0.18 m): the narrowest face within 0.80 rad of straight in is 80 mm across"), notes
    assert "o7" not in notes and "o8" not in notes
