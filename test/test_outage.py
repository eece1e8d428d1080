"""qtree_task_planner.executive.outage: training through a planner that goes away (ROS-free, on a fake clock)."""
import pytest

from qtree_task_planner.executive.outage import PlannerGone, PlannerUnavailable, until_available


class World:
    """A fake clock, a service that is up or down, and a step that fails a given number of times."""

    def __init__(self, failures: int, up_after: float = 0.0):
        self.t, self.failures, self.up_after, self.calls, self.log = 0.0, failures, up_after, 0, []

    def step(self):
        self.calls += 1
        if self.calls <= self.failures:
            raise PlannerUnavailable("no answer")
        return "done"

    def service_up(self, timeout):
        if self.t >= self.up_after:
            return True
        self.t += timeout
        return False

    def run(self, wait=30.0, stop=lambda: False):
        return until_available(self.step, service_up=self.service_up, stop=stop, wait=wait,
                               last_answer=lambda: -1.0, kept=lambda: "in memory", service="/srv",
                               on_outage=self.log.append, clock=lambda: self.t)


def test_a_planner_that_comes_back_in_time_resumes():
    w = World(failures=2, up_after=12.0)
    assert w.run(wait=30.0) == "done" and w.calls == 3
    assert "motion planner lost" in w.log[0] and "in memory" in w.log[0]


def test_a_planner_away_longer_than_planner_wait_ends_the_goal_saying_what_to_do():
    w = World(failures=1, up_after=100.0)
    with pytest.raises(PlannerGone, match=r"unavailable for 30 s .*Start \(or restart\) the motion_planner"):
        w.run(wait=30.0)
    assert w.t == pytest.approx(30.2, abs=0.3)


def test_a_wedged_planner_that_never_answers_ends_the_goal():
    w = World(failures=10**6, up_after=0.0)  # the service is there, every query times out
    w.service_up = lambda timeout: (setattr(w, "t", w.t + 5.0) or True)
    with pytest.raises(PlannerGone, match="not answering"):
        w.run(wait=30.0)


def test_cancel_while_waiting_ends_the_goal_at_once():
    w = World(failures=1, up_after=100.0)
    with pytest.raises(PlannerGone, match="cancelled"):
        w.run(wait=30.0, stop=lambda: w.t > 1.0)
    assert w.t < 2.0
