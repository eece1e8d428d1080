"""The evaluation of the paper's Sect. 5 with this project's motion planner (docs/evaluation.md)."""
