"""Lazy certification and reuse across answers (docs/qtree.md, "Certified sequences"; relocation_common.feasibility):
the CachedOracle's reuse rules, a failed certification turning an answer unfeasible while training goes on to
another learned sequence, and the A*'s optimum certified end to end. Fake oracles (a declared relation with a
certification that fails where told): the Q-Tree layer alone."""
from __future__ import annotations

import pytest

from qtree_task_planner.learning.params import TrainingParams
from qtree_task_planner.learning.q_tree import QTree
from qtree_task_planner.learning.training import train
from qtree_task_planner.oracles import BlockingOracle, CachedOracle
from qtree_task_planner.problem import RelocationProblem
from qtree_task_planner.search import astar
from relocation_common.feasibility import BlockerSet, FeasibilityAnswer, Label
from relocation_common.paths import scenarios_dir
from relocation_common.scenario import load_scenario

F = frozenset


class Scripted:
    """Answers from a dict (object, removed) -> answer; every question counted in `asked`."""

    def __init__(self, answers: dict) -> None:
        self.answers, self.asked = answers, []

    def feasibility(self, object_id, removed):
        self.asked.append((object_id, F(removed)))
        return self.answers[(object_id, F(removed))]


def ok(near=None):
    return FeasibilityAnswer(Label.OBSTACLE, message="picked", near=None if near is None else F(near))


def no(*sets, certain=True):
    return FeasibilityAnswer(Label.UNFEASIBLE, message="blocked",
                             blockers=tuple(BlockerSet(F(s), certain) for s in sets))


# -- reuse: a feasible answer holds for (o, R') when R' >= R & near ------------------------------------------------
@pytest.mark.parametrize("asked, reused", [
    ({"b", "x"}, True),            # b (near, removed then) removed now; x far: anything
    ({"b", "c", "y"}, True),       # c near but present then too: may go or stay
    (set(), False),                # b near and removed then, present now: asked
    ({"c", "x"}, False),           # idem
])
def test_a_feasible_answer_is_reused_only_where_every_near_object_removed_then_is_removed_now(asked, reused):
    oracle = Scripted({("o", F({"a", "b"})): ok(near={"b", "c"}), ("o", F(asked)): ok(near=set())})
    cache = CachedOracle(oracle, reuse=True)
    cache.feasibility("o", F({"a", "b"}))  # a: far from the motion, removed then
    got = cache.feasibility("o", F(asked))
    assert (len(oracle.asked) == 1) == reused and (("o", F(asked)) in cache.reused) == reused
    assert got.label == Label.OBSTACLE and cache.calls == 2 - reused


def test_an_answer_without_a_near_set_or_a_cache_without_reuse_asks_every_new_question():
    answers = {("o", F({"a"})): ok(), ("o", F()): ok(), ("p", F({"a"})): ok(near=set()), ("p", F()): ok()}
    for reuse, calls in ((True, 3), (False, 4)):
        oracle = Scripted(answers)
        cache = CachedOracle(oracle, reuse=reuse)
        for q in answers:
            cache.feasibility(*q)
        assert cache.calls == calls and len(cache.reused) == 4 - calls  # only p's answer (near known) is reused


# -- reuse: an unfeasible answer holds while its certain lanes stay uncleared -------------------------------------
@pytest.mark.parametrize("asked, reused", [
    ({"a", "z"}, True),            # a superset, neither lane cleared
    ({"a", "b", "d"}, True),       # lane {b, c} half cleared, lane {d, e} half cleared
    ({"a", "b", "c"}, False),      # lane {b, c} cleared: asked
    ({"z"}, False),                # not a superset of {a}: asked
])
def test_an_unfeasible_answer_is_reused_while_no_certain_lane_is_cleared(asked, reused):
    oracle = Scripted({("o", F({"a"})): no({"b", "c"}, {"d", "e"}), ("o", F(asked)): ok()})
    cache = CachedOracle(oracle, reuse=True)
    cache.feasibility("o", F({"a"}))
    got = cache.feasibility("o", F(asked))
    assert (len(oracle.asked) == 1) == reused
    if reused:  # the lanes' blockers still there, still certain
        assert got.label == Label.UNFEASIBLE and all(b.certain for b in got.blockers)
        assert {b.objects for b in got.blockers} == {F({"b", "c"}) - F(asked), F({"d", "e"}) - F(asked)}


def test_an_uncertain_blocker_set_is_never_reused():
    oracle = Scripted({("o", F({"a"})): FeasibilityAnswer(Label.UNFEASIBLE, blockers=(
        BlockerSet(F({"b"}), True), BlockerSet(F({"c"}), False))), ("o", F({"a", "z"})): ok()})
    cache = CachedOracle(oracle, reuse=True)
    cache.feasibility("o", F({"a"}))
    assert cache.feasibility("o", F({"a", "z"})).label == Label.OBSTACLE and len(oracle.asked) == 2


# -- certification -------------------------------------------------------------------------------------------------
class Certifying(BlockingOracle):
    """A declared relation whose certification fails for the edges in `fails` (the rest certify); certifications
    counted in `certified`."""

    def __init__(self, scenario, fails) -> None:
        super().__init__(scenario)
        self.fails, self.certified = set(fails), []

    def feasibility(self, object_id, removed):  # a pick alone (it names its near set: every object, no reuse)
        a = super().feasibility(object_id, removed)
        return a if a.label == Label.UNFEASIBLE else FeasibilityAnswer(a.label, near=F(self.ids))

    def certify(self, object_id, removed):
        self.certified.append((object_id, F(removed)))
        if (object_id, F(removed)) in self.fails:
            return FeasibilityAnswer(Label.UNFEASIBLE, message="carry: no path to the slot")
        return super().feasibility(object_id, removed)


def edges(seq):
    return [(o, F(seq[:k])) for k, o in enumerate(seq)]


SCENE = load_scenario(scenarios_dir() / "blocking_10.yaml")
PARAMS = TrainingParams.defaults().replace(seed=1, max_episodes=3000)


def test_a_failed_certification_turns_the_answer_unfeasible_and_training_goes_on_to_another_sequence():
    first = train(SCENE, CachedOracle(Certifying(SCENE, ())), PARAMS)
    assert first.found and first.relabelled == 0
    bad = edges(first.sequence)[1]  # the learned sequence's second relocation cannot be carried away
    oracle = Certifying(SCENE, {bad})
    cache = CachedOracle(oracle)
    r = train(SCENE, cache, PARAMS)
    assert r.found and r.sequence != first.sequence and bad not in edges(r.sequence), r.sequence
    assert r.relabelled >= 1 and r.certify_calls >= len(first.sequence) + len(r.sequence) - 1
    assert cache.table[bad].label == Label.UNFEASIBLE and "certification" in cache.table[bad].message
    assert all(cache.certified[e].label != Label.UNFEASIBLE for e in edges(r.sequence))  # certified end to end
    assert set(edges(r.sequence)) <= set(oracle.certified)
    best = astar.solve(SCENE, CachedOracle(Certifying(SCENE, {bad})))
    assert r.total_weight >= best.total_weight - 1e-9 and r.episodes > first.episodes
    # the relabelled tree is a valid Q-Tree (the checkpoint's load validates it): the failed edge unfeasible,
    # nothing below it, MP_q and Eq. 15's sum matching the edges
    state = r.tree.to_state()
    fresh = QTree(RelocationProblem.from_scenario(SCENE), cache, PARAMS.alpha, PARAMS.gamma)
    fresh.load_state(state)
    a = fresh.ids.index(bad[0])
    at = [n for n in fresh.nodes if F(fresh.ids[i] for i in n.seq) == bad[1] and a in n.label]
    assert at and all(n.label[a] == Label.UNFEASIBLE and a not in n.child for n in at)


def test_the_astar_optimum_is_certified_end_to_end():
    first = astar.solve(SCENE, CachedOracle(Certifying(SCENE, ())))
    bad = edges(first.sequence)[-1]  # the target cannot be carried away after the first optimum's obstacles
    oracle = Certifying(SCENE, {bad})
    cache = CachedOracle(oracle)
    r = astar.solve(SCENE, cache)
    assert r.found and bad not in edges(r.sequence) and r.total_weight >= first.total_weight - 1e-9
    assert set(edges(r.sequence)) <= set(oracle.certified)
    assert all(cache.certified[e].label != Label.UNFEASIBLE for e in edges(r.sequence))
    assert cache.table[bad].label == Label.UNFEASIBLE


class Near(BlockingOracle):
    """A declared relation whose feasible answers name their near set: the object's declared blockers (its motion
    passes where they stood), so reuse holds exactly where the relation agrees. Questions counted in `asked`."""

    def __init__(self, scenario) -> None:
        super().__init__(scenario)
        self.asked = []

    def feasibility(self, object_id, removed):
        self.asked.append((object_id, F(removed)))
        a = super().feasibility(object_id, removed)
        if a.label == Label.UNFEASIBLE:
            return a
        return FeasibilityAnswer(a.label, near=self.blocking.get(object_id, F()))


def test_a_training_resumed_from_a_checkpoint_reuses_as_the_uninterrupted_one():
    """The checkpoint keeps the planner's answers with their near sets, not the reused ones: a resumed training
    reuses what the uninterrupted one reused and asks nothing it did not ask."""
    whole, kept = CachedOracle(Near(SCENE), reuse=True), []
    r = train(SCENE, whole, PARAMS, checkpoint_every=25, on_checkpoint=kept.append)
    assert whole.reused and r.found
    mid = next(ck for ck in kept if ck.episode >= 50)
    assert len(mid.feasibility) == mid.planner_calls  # the reused answers are not stored
    fresh = CachedOracle(Near(SCENE), reuse=True)
    again = train(SCENE, fresh, PARAMS, resume=mid)
    assert (again.sequence, again.episodes, again.q_sum_history) == (r.sequence, r.episodes, r.q_sum_history)
    assert again.planner_calls == r.planner_calls and set(fresh.oracle.asked) <= set(whole.oracle.asked)
    assert len(fresh.oracle.asked) == len(whole.oracle.asked) - mid.planner_calls
