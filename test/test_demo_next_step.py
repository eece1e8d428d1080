"""The demo's one-line next step after a failure (relocation_app.demo._next_step): the reason decides it."""
from pathlib import Path

from relocation_app.demo import _next_step

OUT = Path("/tmp/out")


def test_planning_timeouts_are_not_reported_as_an_unreachable_target():
    """The default demo under load: every relocation ran into the planner's safety net and the closed loop gave up
    with 'no sequence remains'; the next step said 'no collision-free way to the target remains on this shelf'."""
    message = ("no sequence remains: T cannot be reached: every sequence left needs a failed option (re-planned "
               "because relocating o4 failed: internal error: SafetyNetTimeout: wall-clock safety net reached)")
    assert "carry_timeout" in _next_step(message, OUT)


def test_no_sequence_at_all_and_a_target_off_the_shelf_have_their_own_steps():
    assert "motion_planner.md" in _next_step("the target cannot be retrieved: no sequence: T has no grasp lane", OUT)
    assert "fell off" in _next_step("target T is off the shelf at (0.1, 0.2, 0.0): it cannot be retrieved from there",
                                    OUT)
    assert "--execute-optimum" in _next_step("training did not find a sequence to the target in 10000 episodes", OUT)
