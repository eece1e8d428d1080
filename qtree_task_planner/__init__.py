"""Q-Tree task planner (paper Sect. 4.2): the ROS-free core and the task_planner node shell."""
