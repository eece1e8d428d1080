"""A goal sent again to a task planner respawned during an execution starts from the world as it is
(qtree_task_planner.executive.resume, the executor's `relocated`, the keeper's `changed`), ROS-free."""
import pytest
from test_closed_loop import BOTTOM, SCENARIO, FakeShelf, executor, first_plan

from qtree_task_planner.executive.keeper import CheckpointKeeper
from qtree_task_planner.executive.replan import GeometryCache
from qtree_task_planner.executive.resume import WithGone, relocated_before, start_point
from qtree_task_planner.learning.checkpoint import Checkpoint, CheckpointError
from qtree_task_planner.learning.params import TrainingParams
from qtree_task_planner.oracles import CachedOracle
from qtree_task_planner.problem import RelocationProblem
from relocation_common.feasibility import FeasibilityAnswer, Label

PARAMS = TrainingParams.defaults().replace(seed=1, max_episodes=50)


def shelf_after_b():
    """The lanes shelf after the motion planner placed b in slot 0 (the first task planner died after it)."""
    shelf = FakeShelf()
    shelf.put("b", *SCENARIO.slots[0], BOTTOM)
    return shelf


def test_a_fresh_scene_is_no_start_point():
    shelf = FakeShelf()
    assert start_point(SCENARIO, shelf.perceive(), {}, None) is None
    shelf.put("b", *SCENARIO.slots[0], BOTTOM)  # off the top shelf, but nobody placed it: the scene as given
    assert start_point(SCENARIO, shelf.perceive(), {}, None) is None


@pytest.mark.parametrize("bottom_seen", [True, False])
def test_the_relocated_bottles_are_out_of_the_problem_and_sent_as_removed(bottom_seen):
    """b placed before the goal (seen on the bottom shelf, or out of view): the problem is the top shelf's, b is
    relocated before, and the executor sends it as removed, so the motion planner's slot numbering goes on (slot 1
    for T); the old executor started with nothing relocated and sent T with nothing removed."""
    shelf = shelf_after_b()
    shelf.hide_bottom = not bottom_seen
    start = start_point(SCENARIO, shelf.perceive(), {"b": 0}, None)
    assert start is not None and start.before == ("b",) and not start.retrieved
    assert start.problem is not None and "b" not in start.problem.obstacles and start.problem.target == "T"
    assert "relocated before this goal: b" in start.line and "re-planned from the scene as it is now" in start.line
    cache = GeometryCache(shelf)
    seq, _, _ = first_plan(shelf, cache)
    assert seq == ("T",)
    result = executor(shelf, cache, bottom_seen=bottom_seen).run(seq, None, start.before)
    assert result.success, result.message
    assert shelf.relocations == [("T", ("b",))] and result.relocated == ["b", "T"]
    assert result.steps[0].slot == 1


def test_a_target_placed_before_the_goal_is_retrieved_and_nothing_is_relocated():
    shelf = shelf_after_b()
    shelf.put("T", *SCENARIO.slots[1], BOTTOM)
    start = start_point(SCENARIO, shelf.perceive(), {"b": 0, "T": 1}, None)  # seen on the bottom shelf
    assert start is not None and start.retrieved and start.problem is None and start.before == ("b", "T")
    shelf.hide_bottom = True  # out of view: placed by the motion planner and gone from the top shelf
    start = start_point(SCENARIO, shelf.perceive(), {"b": 0, "T": 1}, None)
    assert start is not None and start.retrieved and "relocated" in start.line


def test_a_bottle_placed_then_seen_back_on_the_top_shelf_is_not_relocated():
    shelf = FakeShelf()  # b back at its place (the motion planner's list says it placed it)
    assert relocated_before(SCENARIO, shelf.perceive(), {"b": 0}) == ()
    assert start_point(SCENARIO, shelf.perceive(), {"b": 0}, None) is None


def test_the_first_training_s_checkpoint_is_not_reused_on_the_changed_scene_and_the_log_says_so(tmp_path):
    """The checkpoint of the scenario's scene (final: the execution had started) meets the problem left after b:
    refused without `changed` (a user's goal for another scene), not reused with it, said in one line."""
    path = tmp_path / "qtree.ckpt"
    CheckpointKeeper(str(path)).keep(Checkpoint.initial(RelocationProblem.from_scenario(SCENARIO), PARAMS,
                                                        reason="final"))
    start = start_point(SCENARIO, shelf_after_b().perceive(), {"b": 0}, None)
    assert start is not None and start.problem is not None
    with pytest.raises(CheckpointError, match="another scene"):
        CheckpointKeeper(str(path)).resume_point(start.problem, PARAMS, CachedOracle(FakeShelf()))
    said = []
    k = CheckpointKeeper(str(path), info=said.append)
    assert k.resume_point(start.problem, PARAMS, CachedOracle(FakeShelf()), changed="b was relocated") is None
    assert len(said) == 1 and "not reused" in said[0] and "trains afresh" in said[0] and "4 obstacles" in said[0]
    with pytest.raises(CheckpointError, match="other training parameters"):  # the same scene: still checked
        CheckpointKeeper(str(path)).resume_point(RelocationProblem.from_scenario(SCENARIO), PARAMS.replace(seed=2),
                                                 CachedOracle(FakeShelf()), changed="b was relocated")


class Recorder:
    """A planner that keeps a bottle it placed as an obstacle unless the question names it removed (as the motion
    planner does): T is blocked by b unless b is removed."""

    def __init__(self):
        self.asked = []

    def feasibility(self, object_id, removed):
        self.asked.append((object_id, frozenset(removed)))
        blocked = object_id == "T" and "b" not in removed
        return FeasibilityAnswer(Label.UNFEASIBLE if blocked else Label.TARGET if object_id == "T" else Label.OBSTACLE)


def test_the_resumed_goal_s_questions_name_the_bottles_relocated_before():
    """The first plan of a goal after b was placed: asked plainly, T looks blocked by b (the resumed demo relocated
    o1 and o5 for T, whose lane o4 had left); through WithGone, T is free, and the cache keeps the problem's keys."""
    plain = CachedOracle(Recorder())
    assert plain.feasibility("T", frozenset()).label == Label.UNFEASIBLE
    inner = Recorder()
    cache = CachedOracle(WithGone(inner, frozenset({"b"})))
    assert cache.feasibility("T", frozenset()).label == Label.TARGET
    assert inner.asked == [("T", frozenset({"b"}))] and set(cache.table) == {("T", frozenset())}
    got = []
    answers = WithGone(inner, frozenset({"b"})).feasibility_many([("a", frozenset()), ("T", frozenset({"a"}))],
                                                                 lambda q, a: got.append(q))
    assert [a.label for a in answers] == [Label.OBSTACLE, Label.TARGET]
    assert got == [("a", frozenset()), ("T", frozenset({"a"}))]  # told back as asked of it
    assert inner.asked[-2:] == [("a", frozenset({"b"})), ("T", frozenset({"a", "b"}))]
