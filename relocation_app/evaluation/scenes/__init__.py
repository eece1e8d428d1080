"""The evaluation's scene makers: generated, paper-size and random scenes searched with the real
planner."""
