"""The planner's model of the world: kinematics, collision geometry, grasp poses, grasp-lane blockers
and scene updates from perception."""
