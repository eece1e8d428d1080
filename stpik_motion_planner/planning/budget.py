"""The wall-clock safety net of a planning query (the budget itself is work: validity checks and IK steps).

Reached, it raises SafetyNetTimeout: no answer, never "unfeasible" (docs/motion_planner.md). Shared by STPIK and
RRT-Connect without tying either to the other.
"""
from __future__ import annotations

import time


class SafetyNetTimeout(RuntimeError):
    """The wall-clock safety net ran out before the work budget was spent: the query has no answer (it is not
    "unfeasible"; ask again, on a less loaded machine or with a longer timeout)."""


def check_deadline(deadline: float, what: str) -> None:
    """Raise SafetyNetTimeout once time.perf_counter() is past `deadline`."""
    if time.perf_counter() > deadline:
        raise SafetyNetTimeout(f"wall-clock safety net reached during {what}, before the work budget was spent")
