"""Training through a motion planner that may go away (docs/reliability.md, "Dead motion planner").

A query unanswered within its limit, or a service that vanished, raises PlannerUnavailable inside the training;
`until_available` then waits up to `wait` s for the planner to come back and runs the step again (the training
rolled its episode back and kept every answer). After `wait` s, or on cancel or shutdown, it raises PlannerGone
with what to do. ROS-free: the node passes how to see the service and how to report.
"""
from __future__ import annotations

import time
from typing import Callable, Protocol, TypeVar

T = TypeVar("T")


class UntilPlanner(Protocol):
    """step() through planner outages (until_available with the caller's settings), for steps of any result."""

    def __call__(self, step: Callable[[], T]) -> T:
        """step()'s result once the planner answered it all."""
        ...


class PlannerUnavailable(RuntimeError):
    """The feasibility service did not answer in time (planner dead or overloaded)."""


class PlannerGone(PlannerUnavailable):
    """The planner stayed unavailable for longer than planner_wait (or the wait was cancelled): the goal ends."""


def until_available(step: Callable[[], T], *, service_up: Callable[[float], bool], stop: Callable[[], bool],
                    wait: float, last_answer: Callable[[], float], kept: Callable[[], str], service: str,
                    on_outage: Callable[[str], None] = lambda _: None, on_back: Callable[[], None] = lambda: None,
                    clock: Callable[[], float] = time.monotonic) -> T:
    """step() again and again while the planner is unavailable, waiting up to `wait` s for it each outage.

    `service_up(timeout)` blocks up to timeout for the service; `stop()` is true on cancel or shutdown;
    `last_answer()` is the clock time of the planner's last answer (an answer after an outage began ends it);
    `kept()` says where what was learned is kept (for the messages)."""
    since = None
    while True:
        try:
            return step()
        except PlannerGone:
            raise
        except PlannerUnavailable as e:
            if since is None or last_answer() > since:
                since = clock()
            on_outage(f"motion planner lost: {e}; learned so far kept ({kept()}); waiting up to {wait:g} s for "
                      f"{service}")
            advice = (f"What was learned is kept ({kept()}). Start (or restart) the motion_planner node (service "
                      f"{service}) and send the same goal again to resume.")
            while not service_up(0.2):
                if stop():
                    raise PlannerGone(f"cancelled while waiting for the motion planner; learned so far kept "
                                      f"({kept()})") from None
                if clock() - since > wait:
                    raise PlannerGone(f"motion planner unavailable for {wait:g} s (planner_wait): {e}. {advice}") \
                        from None
            if clock() - since > wait:  # it is there but does not answer (wedged)
                raise PlannerGone(f"motion planner not answering for {wait:g} s (planner_wait): {e}. {advice}") \
                    from None
            on_back()


class Cancelled(RuntimeError):
    """The goal was cancelled, or the node is shutting down, while waiting on the planner."""
