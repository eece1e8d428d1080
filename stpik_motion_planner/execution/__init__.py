"""Executing planned motions on an arm: the trajectory follower, the 100 Hz stream, the relocation
sequence over the Arm protocol and the goal checks."""
