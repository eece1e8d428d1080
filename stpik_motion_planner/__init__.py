"""The STPIK motion planner (paper Sect. 4.1): feasibility and trajectories of a relocation (docs/motion_planner.md)."""
