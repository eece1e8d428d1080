"""The push (docs/motion_planner.md, "The push"): a standing cylinder X slid along the top shelf by the closed hand,
out of the grasp lanes of another object C, when the side grasp of either needs the other gone; a cylinder lying flat
slid along its axis (push.slide: on; sideways with the hand pointing into the shelf, push.hand_turns) or rolled
across it (push.roll: off, it wedges the hand; MuJoCo: docs/bench/push.md).

1. Where to: for each distance of push.distances (least first) and each direction of push.directions (an angle from
   straight back, +x, turned away from C; both ways when C is straight in front or behind), X translated by d
   (quasi-static, model/push.py) must stay on the shelf and sweep clear of every object present by
   push.sweep_margin, and open a lane of C: a lane (model/blockers.py's screen) that X blocks where it stands and no
   longer blocks where it ends, with no blocker it did not have before (removed objects gone). The candidates are
   ordered lexicographically: first those whose opened lane is then free of every other object (C's side grasp
   needs no further relocation), then the least distance, then the directions' order.
2. The motion, for the candidates in that order until one plans: home -> pre-contact pose (the pick's Cartesian
   path: the direct path first, then RRT-Connect, for the closed hand's proxy) -> contact pose (the finger tips
   push.contact_gap short of X, at push.contact_height of its height, no lower than the palm's clearance over the
   board allows) -> the straight push by the gap plus d at push.speed -> straight back to the pre-contact pose with X
   at its end pose -> home back along the first leg. A sideways slide's hand points into the shelf (motion.hand_yaws;
   rolled half a turn for a push to its left): it comes in and backs out along its own axis, the push along X's.
   Every leg is tracked by STPIK (Eq. 9-10) with the closed hand's capsules (collision.closed_fingers) against every
   object present; the hand may touch X from the pre-contact pose on (the approach, the push, the retreat), and
   during the push X is no obstacle of the arm (it moves with the tips).
The answer is g_O with the whole motion (home -> ... -> home; the gripper shut before it, opened after it), the end
pose of X, and the lane it opens (then free, or still held by whom); or g_U with the reason: X leaning, or lying
with both kinds off, neither a cylinder nor a box, blocking no lane of C, no direction and distance that opens one,
or no motion for any that does.
"""
from stpik_motion_planner.planning.push.motion import PushPlan, plan_push, push_feasibility

__all__ = ["PushPlan", "plan_push", "push_feasibility"]
