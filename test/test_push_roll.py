"""The push's hand rolled half a turn about its axis (grasp.tool_rotation's roll, planning/push/motion.hand_yaws and
rolled_home): checked against Pinocchio's kinematics of joint 7 and against the unrolled hand mirrored. The physics
of a rolled push is test_push_lying.py's (across_layout)."""
from __future__ import annotations

import math

import numpy as np
from push_layouts import across_layout
from test_push import PARAMS

from relocation_common import robot_description as rd
from stpik_motion_planner.model.collision import ArmGeometry, closed_fingers
from stpik_motion_planner.model.grasp import check_pose, pose_matrix, tool_rotation
from stpik_motion_planner.model.kinematics import Kinematics
from stpik_motion_planner.model.push import leading
from stpik_motion_planner.planning.planner import MotionPlanner
from stpik_motion_planner.planning.push.motion import hand_yaws, rolled_home


def test_a_half_turn_of_joint_7_is_the_roll_of_pi():
    """At home, joint 7 turned by pi moves the tool about its own axis only: Pinocchio's tool pose there is the home
    pose with roll pi (position unchanged, tool x and y reversed), for tool_rotation and for a 6-number pose."""
    kin = Kinematics()
    kin.update(rd.Q_HOME)
    r0, p0 = kin.tool_pose()
    q = rd.Q_HOME.copy()
    q[6] += math.pi
    kin.update(q)
    r1, p1 = kin.tool_pose()
    assert np.allclose(p0, p1, atol=1e-9)
    assert np.allclose(r1, tool_rotation(0.0, 0.0, math.pi), atol=1e-4)  # home: within 6e-6
    rot, pos = pose_matrix(check_pose([*p0, 0.0, 0.0, math.pi]))
    assert np.allclose(rot, r1, atol=1e-4) and np.allclose(pos, p1)
    assert np.array_equal(tool_rotation(0.3, 0.0), tool_rotation(0.3, 0.0, 0.0))  # roll 0: the old rotation


def test_rolled_the_hand_leads_to_its_left_with_fingers_2_and_3():
    """A push 0.9 rad to the hand's left: unrolled, finger 1 leads alone at the tool axis' height; rolled half a
    turn, two tips lead, one 22 mm below the axis: the mirror image of the push 0.9 rad to the unrolled hand's
    right (the same tips' heights, the same lead over the hinges and palm)."""
    one, _ = leading(0.9, 0.0, 0.0)
    two, ahead = leading(0.9, 0.0, math.pi)
    right, ahead_right = leading(-0.9, 0.0, 0.0)
    assert len(one) == 1 and abs(one[0, 2]) < 0.005
    assert len(two) == 2 and len(right) == 2
    assert np.allclose(sorted(two[:, 2]), sorted(right[:, 2]), atol=1e-9) and min(two[:, 2]) < -0.02
    assert np.allclose(two[:, 1], -right[:, 1], atol=1e-9) and math.isclose(ahead, ahead_right, abs_tol=1e-9)


def test_only_a_slide_to_the_hands_left_is_tried_rolled():
    """hand_yaws of across_layout(3)'s lying X: for a slide to the left of straight in, each turned hand unrolled,
    then rolled; to the right, unrolled only."""
    planner = MotionPlanner(across_layout(3), PARAMS)
    x = planner.scenario.object("X")
    left = math.remainder(x.yaw if math.sin(x.yaw) > 0 else x.yaw + math.pi, 2 * math.pi)
    hands = hand_yaws(planner, "X", left)
    turns = PARAMS.push.hand_turns
    assert [h for h, r in hands if r == 0.0] == [math.remainder(left - t, 2 * math.pi) for t in turns]
    assert [h for h, r in hands if r] == [math.remainder(left - t, 2 * math.pi) for t in turns if t > 0]
    assert all(r == 0.0 for _, r in hand_yaws(planner, "X", math.remainder(left + math.pi, 2 * math.pi)))


def test_the_rolled_hand_starts_from_home_with_joint_7_turned():
    """rolled_home: the unrolled hand starts at home with no motion; the rolled one at home with joint 7 turned by
    pi, its start pose that configuration's tool pose, reached by joint 7 alone."""
    planner = MotionPlanner(across_layout(3), PARAMS)
    arm = ArmGeometry(planner.kin, fingers=closed_fingers())
    obs = planner.scene.obstacles(frozenset())
    q, start, turn = rolled_home(planner, 0.0, obs, arm)
    assert np.array_equal(q, rd.Q_HOME) and turn is None
    q, start, turn = rolled_home(planner, math.pi, obs, arm)
    assert turn is not None and np.allclose(q - rd.Q_HOME, [0, 0, 0, 0, 0, 0, math.pi])
    steps = turn.positions
    assert np.allclose(steps[0], rd.Q_HOME) and np.allclose(steps[-1], q)
    assert np.allclose(steps[:, :6], rd.Q_HOME[:6])
    kin = Kinematics()
    kin.update(q)
    rot, pos = kin.tool_pose()
    assert np.allclose(pose_matrix(start)[0], rot, atol=1e-4) and np.allclose(start[:3], pos, atol=1e-4)
