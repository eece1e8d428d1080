"""The demo's one-line next step after a failure (relocation_app.run_report.next_step): the reason decides it."""
from pathlib import Path

from relocation_app.run_report import next_step as _next_step
from relocation_app.run_report import timeout_hint as _timeout_hint

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


def test_a_lying_bottle_in_the_way_is_to_be_stood_up():
    """The benchmark's most common give-up (replan.held_reason, the motion planner's headroom): the step named the
    docs only."""
    message = ("no sequence remains: T cannot be reached: no feasible relocation sequence over the 4 obstacles on the "
               "top shelf (3 planner calls); every lane of T holds an object the hand cannot grasp (o1); never "
               "relocated, the hand cannot grasp it: o1 (no grasp: o1 lies on the top shelf with 0.26 m of headroom; "
               "a grasp from above needs 0.45 m (the hand straight down, its finger tips 19 mm over the bottle before "
               "it comes down and 19 mm under the board above)) (re-planned because relocating o4 failed: relocated o4 "
               "to slot 0, but the scene shows: o1 moved 49 mm (no longer standing on its board))")
    assert "stand it up by hand" in _next_step(message, OUT)
    assert "stand it up" not in _next_step("no sequence remains: T cannot be reached: no feasible relocation "
                                           "sequence over the 4 obstacles on the top shelf (3 planner calls)", OUT)


def test_no_scene_while_the_target_is_not_seen_suggests_a_tipped_target():
    """The demo with the RealSense model, T tipped after the first relocation: perception stopped publishing (no
    bottle fit for a lying target) and the next step said only to check the camera."""
    message = ("no scene after relocating o1: no scene received within 10 s (scene_after_wait); the last one came "
               "12 s ago. Perception publishes no scene while it does not see the target (tipped over, fallen or "
               "hidden: /diagnostics names the missing bottles and why)")
    assert "stand it up by hand" in _next_step(message, OUT)
    assert "stand it up" not in _next_step("no scene after relocating o1: the scene is empty", OUT)


def test_a_demo_out_of_time_says_that_the_same_command_resumes_it():
    """scenario3_15 with perception at load 7 ended "[demo] error: no result within 900 s" and nothing else, with its
    training in the checkpoint that the same command resumes."""
    hint = _timeout_hint("no result within 900 s", OUT / "run" / "qtree.ckpt")
    assert "/tmp/out/run/qtree.ckpt: the same command resumes it" in hint and "--timeout" in hint
    assert _timeout_hint("the train goal was rejected: bad policy", OUT) == ""


def test_a_task_planner_that_died_during_the_execution_gets_its_own_step():
    """The chaos benchmark's task planner SIGKILLed during a carry: the demo's message says "the task planner died
    during the execution"; the old step read "a node kept dying (max_respawns ...)", which it had not (one respawn)."""
    message = ("the task planner died during the execution (exit -9; phase: check 1: o4 relocated as planned): the "
               "goal and the execution's state died with it")
    step = _next_step(message, OUT, "node_died")
    assert "task planner died during the execution" in step and "kept dying" not in step, step
    assert "kept dying" in _next_step("perception died 4 times (max_respawns 3)", OUT, "node_died")


def test_the_drivers_death_names_the_relocation_in_flight():
    """The task planner's phase lags a relocation that has started ("check 1: ..." while the motion planner carries
    the next object): the end's message names the relocation the motion planner was running (before: the phase
    alone, so a driver killed during T's carry read "phase: check 1: o4 relocated as planned")."""
    from types import SimpleNamespace

    from relocation_app.demo import _died
    from relocation_app.graph import NodeDied
    w = SimpleNamespace(phase="check 1: o4 relocated as planned", relocating=["o4", "T"],
                        relocation_in_flight=lambda: True)
    end = _died(NodeDied("jaco2_sim_driver", -9, ""), w)
    assert "the motion planner relocating T" in end.message and "check 1" in end.message
    w.relocation_in_flight = lambda: False
    assert "relocating" not in _died(NodeDied("jaco2_sim_driver", -9, ""), w).message
