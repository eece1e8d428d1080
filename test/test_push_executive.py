"""The task planner's side of a push (qtree_task_planner.executive.push, the closed loop, retrieval.execute and the
ROS clients) against a fake motion planner.

The fake shelf (test_closed_loop.LyingBlocks: relocations, perception and feasibility from its lanes, with the lane
screen) also answers the push question and executes a push: the pushed object slides 10 cm along y, out of the
lanes of the object it clears (that object's lanes lose it), unless `ineffective`. Its
lanes make the proof's blocking cycle "b needs T moved": T's only lane holds b and b's only lane holds T (or also a,
which the picks alone can take away first; `needs_gone`: a push the motion planner refuses until those are gone)."""
import math
from types import SimpleNamespace

import pytest
from test_closed_loop import OBJECTS, SCENARIO, TOP, LyingBlocks

from qtree_task_planner.executive.closed_loop import ClosedLoopExecutor
from qtree_task_planner.executive.push import PushActions, PushAnswer, Pusher, PushProof, candidates, pick_order
from qtree_task_planner.executive.replan import GeometryCache, blocking_pairs, replan
from qtree_task_planner.executive.retrieval import execute, training_outcome
from qtree_task_planner.executive.settings import pushes_on
from qtree_task_planner.executive.world import remaining_problem, scene_from_scenario
from qtree_task_planner.oracles import CachedOracle
from qtree_task_planner.search.exact import ExactResult, blocking_needs, can_leave
from relocation_common.config import ParameterError
from relocation_common.feasibility import FeasibilityAnswer, Label

CYCLE = {"T": [{"b"}], "b": [{"T"}]}  # "b needs T moved"
WEIGHTS = {o["id"]: o.get("weight", 1.0) for o in OBJECTS}
SLIDE = 0.10  # m along y


class PushShelf(LyingBlocks):
    """LyingBlocks that answers and executes pushes (module doc)."""

    def __init__(self, lanes=None, refuse=(), ineffective=False, needs_gone=None):
        super().__init__(lanes={k: [set(b) for b in v] for k, v in (lanes or CYCLE).items()})
        self.refuse, self.ineffective = set(refuse), ineffective
        self.needs_gone = needs_gone or {}  # object -> the objects its push needs gone (its contact pose, say)
        self.push_questions, self.pushes = [], []

    def push(self, obj, clear_for, removed):
        self.push_questions.append((obj, clear_for, frozenset(removed)))
        if obj in self.refuse:
            return PushAnswer(False, f"no push: {obj} is against the back wall", None)
        if not set(self.needs_gone.get(obj, ())) <= set(removed):
            return PushAnswer(False, f"no push: the hand's contact pose for {obj} collides with "
                              f"{', '.join(sorted(set(self.needs_gone[obj]) - set(removed)))}", None)
        o = self.scene[obj]
        return PushAnswer(True, "push planned", (o.x, o.y + SLIDE))

    def do_push(self, obj, clear_for, removed):
        self.pushes.append((obj, clear_for, tuple(removed)))
        o = self.scene[obj]
        self.put(obj, o.x, o.y + SLIDE, o.z, o.tilt)
        if not self.ineffective:
            self.lanes[clear_for] = [b - {obj} for b in self.lanes.get(clear_for, [set()])]
        return True, "pushed"


def actions(shelf, max_pushes=2, factor=2.0):
    return PushActions(shelf.push, shelf.do_push, lambda: factor, max_pushes)


def run(shelf, sequence, max_pushes=2, closed_loop=True):
    return execute(SCENARIO, sequence, scene_from_scenario(SCENARIO), shelf.relocate, shelf.perceive,
                   CachedOracle(shelf), closed_loop=closed_loop, cancelled=lambda: False,
                   pushes=actions(shelf, max_pushes))


def proof(shelf) -> tuple:
    """(the re-plan's answer on the fake shelf as it is now, the blocking pairs its proof names)."""
    cache = GeometryCache(shelf)
    rp = remaining_problem(SCENARIO, shelf.perceive(), ())
    return replan(rp, (), cache), blocking_pairs(rp, cache)


def test_the_proof_names_its_blocking_pairs_as_data():
    """exact.blocking_needs is the cycle the "no sequence" line names ("b needs T moved"), and replan.blocking_pairs
    finds it over the re-plan's cache."""
    lanes = {"T": [(frozenset(), (frozenset({"b"}),))], "b": [(frozenset(), (frozenset({"T"}),))]}
    assert blocking_needs("T", lanes) == (("b", ("T",)),)
    assert blocking_needs("T", {"T": [(frozenset(), (frozenset({"b"}),))]}) == ()  # b can leave: no cycle
    with_a = dict(lanes, T=[(frozenset(), (frozenset({"a", "b"}),))], a=[(frozenset(), (frozenset({"c"}),))])
    assert can_leave("T", with_a) == ("a", "c") and can_leave("T", lanes) == () and can_leave("x", lanes) == ()
    answer, pairs = proof(PushShelf())
    assert isinstance(answer, str) and "b needs T moved" in answer, answer
    assert pairs == (("b", "T"),)


def test_candidates_are_both_directions_cheapest_first():
    assert candidates([("b", "T")], WEIGHTS, 2.0) == [(1.0, "b", "T"), (2.0, "T", "b")]
    assert candidates([("T", "a"), ("b", "T")], WEIGHTS, 1.0) == [(0.3, "a", "T"), (0.5, "b", "T"), (1.0, "T", "a"),
                                                                   (1.0, "T", "b")]


def test_no_sequence_at_the_start_leads_to_one_push_then_a_re_plan_that_succeeds():
    """The first plan proves no sequence ("b needs T moved"): before, the goal ended there. Now the closed loop asks
    for a push of b clearing T's lanes, executes it, perceives b where it ended and re-plans: T alone."""
    shelf = PushShelf()
    out = run(shelf, [])
    assert out.success, out.message
    assert shelf.push_questions == [("b", "T", frozenset())] and shelf.pushes == [("b", "T", ())]
    assert [o for o, _ in shelf.relocations] == ["T"]
    (p,) = out.pushes
    assert p.line() == "pushed b out of T's lanes (predicted end (0.550, 0.100)); re-planned"
    assert p.cost == pytest.approx(0.5 * 2.0) and p.seen == pytest.approx((0.55, 0.10))
    assert [r.reason for r in out.replans] == ["the first plan found no sequence",
                                               "pushed b out of T's lanes (predicted end (0.550, 0.100))"]
    assert out.replans[0].sequence is None and "b needs T moved" in out.replans[0].failure
    assert out.replans[1].sequence == ("T",)
    assert out.to_dict()["pushes"][0]["line"] == p.line()


def test_a_lying_bottle_in_every_lane_of_t_is_pushed_out_of_them():
    """e lies in T's only lane and has no lane of its own (the motion planner's screen: no grasp takes a bottle
    lying under 0.26 m of headroom): the proof says "e has no lane", no pair "X needs T moved". Before, the Pusher
    found no pair and the goal ended; now the proof's pairs name (e, T) and the closed loop asks the push of e out
    of T's lanes, executes it and re-plans: T alone."""
    shelf = PushShelf(lanes={"T": [{"e"}], "e": []})
    shelf.put("e", 0.66, 0.08, TOP + 0.033, tilt=math.pi / 2)
    answer, pairs = proof(shelf)
    assert "cannot grasp it: e" in answer and pairs == (("e", "T"),), answer
    out = run(shelf, [])
    assert shelf.push_questions[0] == ("e", "T", frozenset()) and shelf.pushes == [("e", "T", ())], out.message
    assert out.success, out.message
    assert [o for o, _ in shelf.relocations] == ["T"]


class FailedLane(PushShelf):
    """T's lanes hold the laneless e, or a (free); T's pick along a's lane fails in the motion planner (unfeasible,
    no blocker: STPIK did not converge, as on the grid's paper_random5_09) until e was pushed out of T's lanes."""

    def __init__(self):
        super().__init__(lanes={"T": [{"e"}, {"a"}], "e": []})
        self.pushed = set()

    def feasibility(self, obj, removed):
        if obj == "T" and "e" not in self.pushed:
            self.questions.append((obj, frozenset(removed)))
            return FeasibilityAnswer(Label.UNFEASIBLE, message="STPIK rejected the approach: did not converge")
        return super().feasibility(obj, removed)

    def do_push(self, obj, clear_for, removed):
        self.pushed.add(obj)
        return super().do_push(obj, clear_for, removed)


def test_a_laneless_bottle_in_t_s_lanes_is_pushed_when_t_s_free_lane_fails():
    """No blocking cycle: a can leave, but T is unfeasible from every set reached (its lane through a fails in the
    motion planner), and e, which no grasp takes, is in T's other lane. The old proof named no pair, so no push was
    asked ("the proof names no pair"); now (e, T) is a pair (exact.laneless_in_lanes), the push of e out of T's
    lanes is asked and executed, and the re-plan retrieves T."""
    shelf = FailedLane()
    why, pairs = proof(shelf)
    assert isinstance(why, str) and "T unfeasible from every set reached" in why, why
    assert pairs == (("e", "T"),)
    out = run(shelf, [])
    assert shelf.pushes == [("e", "T", ())], out.message
    assert out.success, out.message
    assert [o for o, _ in shelf.relocations] == ["T"]


def test_no_sequence_in_a_re_plan_leads_to_a_push():
    """The closed loop's re-plan after a failed relocation (b blocked by T) proves no sequence: a push, then T."""
    shelf = PushShelf()
    out = run(shelf, ["b", "T"])
    assert out.success, out.message
    assert [o for o, _ in shelf.relocations] == ["b", "T"] and not out.steps[0].ok
    assert shelf.pushes == [("b", "T", ())]
    assert out.replans[0].reason.startswith("relocating b failed") and out.replans[0].sequence is None


def test_a_refused_push_of_x_leads_to_a_push_of_t():
    shelf = PushShelf(refuse={"b"})
    out = run(shelf, [])
    assert out.success, out.message
    free = frozenset("acde")  # the picks alone take them away first: b's push is asked with them gone too
    assert shelf.push_questions == [("b", "T", frozenset()), ("b", "T", free), ("T", "b", frozenset())]
    assert [p[:2] for p in shelf.pushes] == [("T", "b")]
    assert [o for o, _ in shelf.relocations] == ["b", "T"]  # T out of b's lanes: b, then T
    assert out.pushes[0].refused == ("b out of T's lanes (no push: b is against the back wall; with a, c, d, e gone: "
                                     "no push: b is against the back wall)",)


PREP_CYCLE = {"T": [{"a", "b"}], "b": [{"T"}]}  # "b needs T moved"; a (and c, d, e) the picks alone take away first


def test_a_push_that_needs_a_free_object_gone_relocates_it_first():
    """The demo's failure on a perturbed layout: the proof is "lane {a, b}: b needs T moved" with a still on the
    shelf, and the push of b plans only with a gone. Before, the push was asked with nothing removed and every push
    was refused (T's push too: it needs a gone as well). Now it is asked again with the objects the picks alone take
    away first gone (a, c, d, e), shrunk to those it needs (heaviest first: e, a, c, d), a relocated (verified), b
    pushed, T relocated."""
    shelf = PushShelf(lanes=PREP_CYCLE, needs_gone={"b": {"a"}, "T": {"a"}})
    out = run(shelf, [])
    assert out.success, out.message
    f = frozenset
    assert shelf.push_questions == [("b", "T", f()), ("b", "T", f("acde")), ("b", "T", f("acd")), ("b", "T", f("cd")),
                                    ("b", "T", f("ad")), ("b", "T", f("a"))]  # T's push (cost 2.0) never asked
    assert [o for o, _ in shelf.relocations] == ["a", "T"] and out.steps[0].ok and out.steps[0].verification.ok
    assert shelf.pushes == [("b", "T", ("a",))]
    (p,) = out.pushes
    assert p.prep == ("a",) and p.cost == pytest.approx(0.5 * 2.0 + 0.3)
    assert p.line() == "relocated a to free the push; pushed b out of T's lanes (predicted end (0.550, 0.100)); " \
        "re-planned"
    assert out.to_dict()["pushes"][0]["prep"] == ["a"]
    assert out.message == "target T retrieved after 1 relocations, 1 push and 2 re-plans"


def test_a_push_with_prep_relocations_costs_them_and_a_cheaper_push_goes_first():
    """Push factor 1: b's push (0.5) needs a and e gone (0.7): 1.2, T's push alone 1.0: T is pushed, nothing
    relocated first."""
    shelf = PushShelf(lanes=PREP_CYCLE, needs_gone={"b": {"a", "e"}})
    out = execute(SCENARIO, [], scene_from_scenario(SCENARIO), shelf.relocate, shelf.perceive, CachedOracle(shelf),
                  closed_loop=True, cancelled=lambda: False, pushes=actions(shelf, factor=1.0))
    assert out.success, out.message
    assert [q[:2] for q in shelf.push_questions][-1] == ("T", "b") and shelf.pushes == [("T", "b", ())]
    assert out.pushes[0].prep == () and out.pushes[0].cost == pytest.approx(1.0)


def test_a_prep_relocation_that_fails_is_re_planned_and_the_push_freed_in_another_order():
    """a's relocation fails (its option with nothing removed is marked): the rest is re-planned, no sequence, the
    push is chosen again: a is pickable only after another object, so d goes first (d, a), then b's push, then T."""
    shelf = PushShelf(lanes=PREP_CYCLE, needs_gone={"b": {"a"}})
    shelf.fail["a"] = 1
    out = run(shelf, [])
    assert out.success, out.message
    assert [o for o, _ in shelf.relocations] == ["a", "d", "a", "T"] and not out.steps[0].ok
    assert out.replans[1].reason == "relocating a failed: no grasp found (STPIK) (relocating a to free the push of " \
        "b out of T's lanes)", out.replans[1].reason
    assert out.pushes[0].prep == ("d", "a") and shelf.pushes == [("b", "T", ("a", "d"))]


def test_pick_order_is_an_order_in_which_each_is_pickable():
    after = {"a": {"c"}, "c": set(), "d": {"x"}}  # object -> what must be gone before it
    assert pick_order(("a", "c"), lambda o, s: after[o] <= s) == ("c", "a")
    assert pick_order(("a", "c", "d"), lambda o, s: after[o] <= s) == ("c", "a")  # d never: not all


def test_max_pushes_bounds_the_pushes_and_the_end_says_why():
    """Pushes that open nothing: at most max_pushes are executed; the "no sequence" end names them and why no
    further one."""
    shelf = PushShelf(ineffective=True)
    out = run(shelf, [], max_pushes=2)
    assert not out.success and len(shelf.pushes) == 2 and len(out.pushes) == 2
    assert "no further push: max_pushes (2) spent" in out.message, out.message
    assert "pushes executed: pushed b out of T's lanes" in out.message
    assert out.message.startswith("no sequence remains: ")
    none = run(PushShelf(), [], max_pushes=0)
    assert not none.success and none.message.startswith("the target cannot be retrieved: ")
    assert "no push: pushes are off (max_pushes 0)" in none.message


def test_every_push_refused_is_said_in_the_end():
    shelf = PushShelf(refuse={"b", "T"})
    out = run(shelf, [])
    assert not out.success and not shelf.pushes
    assert "no push: every push refused: b out of T's lanes (no push: b is against" in out.message
    assert "T out of b's lanes (no push: T is against the back wall; with a, c, d, e gone: no push: T is against the " \
        "back wall)" in out.message


def test_an_open_loop_run_does_not_push():
    shelf = PushShelf()
    out = run(shelf, ["b", "T"], closed_loop=False)
    assert not out.success and not shelf.push_questions and not shelf.pushes
    assert not pushes_on({"closed_loop": False, "max_pushes": 2}.get)
    assert pushes_on({"closed_loop": True, "max_pushes": 2}.get)
    assert not pushes_on({"closed_loop": True, "max_pushes": 0}.get)
    none = ExactResult(None, None, 3, 1, "no sequence: blocking cycle")
    trained = SimpleNamespace(cancelled=False, found=False)
    assert training_outcome(trained, none, execute=True, push=False) == (
        False, "the target cannot be retrieved: no sequence: blocking cycle")
    assert training_outcome(trained, none, execute=True, push=True) is None  # the closed loop pushes


def test_a_failed_push_that_left_the_object_is_not_asked_again():
    shelf = PushShelf()
    shelf.do_push = lambda obj, clear_for, removed: (shelf.pushes.append((obj, clear_for)), (False, "no contact"))[1]
    out = run(shelf, [], max_pushes=3)
    assert not out.success and [p[:2] for p in shelf.pushes] == [("b", "T"), ("T", "b")]
    assert "b out of T's lanes (failed before)" in out.message and "T out of b's lanes (failed before)" in out.message
    assert out.pushes[0].line() == "push of b out of T's lanes failed: no contact; re-planned"


def test_a_missing_push_factor_is_said():
    shelf = PushShelf()

    def missing():
        raise ParameterError("action_cost.push is not a parameter of this task planner")
    pusher = Pusher(PushActions(shelf.push, shelf.do_push, missing, 2),
                    PushProof(lambda rp: [("b", "T")], lambda rp: (), lambda rp, banned, o, s: True))
    loop = ClosedLoopExecutor(SCENARIO, shelf.relocate, shelf.perceive,
                              lambda rp, banned: replan(rp, banned, GeometryCache(shelf)), pusher=pusher)
    out = loop.run([])
    assert not out.success and "no push: no push factor: action_cost.push is not a parameter" in out.message


# ---------------------------------------------------------------------------------- what would follow a push
class Lookahead(PushShelf):
    """PushShelf whose pushes of the objects in `slip` slide without leaving the lanes they were to clear (the
    executed push, and the motion planner's what-if scene: `what_if`, a copy of this shelf with the moved objects at
    their predicted end and, unless they slip, out of every lane)."""

    def __init__(self, slip=(), **kw):
        super().__init__(**kw)
        self.slip, self.what_ifs = set(slip), []

    def do_push(self, obj, clear_for, removed):
        self.pushes.append((obj, clear_for, tuple(removed)))
        o = self.scene[obj]
        self.put(obj, o.x, o.y + SLIDE, o.z, o.tilt)
        if obj not in self.slip:
            self.lanes[clear_for] = [b - {obj} for b in self.lanes.get(clear_for, [set()])]
        return True, "pushed"

    def what_if(self, moved):
        self.what_ifs.append(dict(moved))
        other = Lookahead(self.slip, lanes={k: [set(b) for b in v] for k, v in self.lanes.items()})
        other.scene = dict(self.scene)
        for obj, (x, y) in moved.items():
            o = self.scene[obj]
            other.put(obj, x, y, o.z, o.tilt)
            if obj not in self.slip:
                other.lanes = {k: [b - {obj} for b in v] for k, v in other.lanes.items()}
        return other


def looking(shelf, max_pushes=1):
    return execute(SCENARIO, [], scene_from_scenario(SCENARIO), shelf.relocate, shelf.perceive, CachedOracle(shelf),
                   closed_loop=True, cancelled=lambda: False,
                   pushes=PushActions(shelf.push, shelf.do_push, lambda: 2.0, max_pushes, shelf.what_if))


def test_a_push_is_chosen_by_what_would_follow_it():
    """b's push (cost 1.0) is the cheapest, but b would slip along T's lane: on the what-if scene (b at its
    predicted end) no pick sequence follows. T's push (2.0) out of b's lanes is followed by b, T. Before, the Pusher
    executed the cheapest feasible push (b's), which opened nothing, and with max_pushes 1 the goal ended; now it
    asks what would follow each push and executes T's: b, then T retrieved."""
    shelf = Lookahead(slip={"b"})
    out = looking(shelf)
    assert out.success, out.message
    assert shelf.pushes == [("T", "b", ())] and [o for o, _ in shelf.relocations] == ["b", "T"]
    assert shelf.what_ifs == [{"b": pytest.approx((0.55, 0.10))}, {"T": pytest.approx((0.77, 0.10))}]
    (p,) = out.pushes
    assert p.then == ("b", "T") and out.to_dict()["pushes"][0]["then"] == ["b", "T"]
    assert p.refused == ("b out of T's lanes (no pick sequence after it: T cannot be reached: no feasible relocation "
                         "sequence with the actions side_grasp, top_grasp over the 5 obstacles on the top shelf (0 "
                         "planner calls); blocking cycle: every lane of T needs an object that cannot leave first "
                         "(lane {b}: b needs T moved))",), p.refused


def test_the_push_whose_retrieval_costs_least_is_chosen_and_the_asking_stops_there():
    """Both pushes open a retrieval: b's (1.0, then T: 1.0 in all) is chosen; T's push (2.0) is never asked, since it
    alone costs more than b's whole retrieval. The choice carries the picks that would follow."""
    shelf = Lookahead()
    cache = GeometryCache(shelf)
    rp = remaining_problem(SCENARIO, shelf.perceive(), ())
    assert isinstance(replan(rp, (), cache), str)
    follow = []

    def after(rp, banned, pushed, end, prep):
        follow.append(pushed)
        from qtree_task_planner.executive.replan import after_push
        return after_push(rp, banned, pushed, end, prep, shelf.what_if)
    lines = []
    pusher = Pusher(PushActions(shelf.push, shelf.do_push, lambda: 2.0, 1, progress=lines.append),
                    PushProof(lambda rp: blocking_pairs(rp, cache), lambda rp: (), lambda *a: True, after))
    choice = pusher.choose(rp, WEIGHTS, {o: WEIGHTS[o] for o in rp.problem.obstacles}, rp.gone, frozenset())
    assert (choice.object_id, choice.then, choice.total) == ("b", ("T",), pytest.approx(1.0))
    assert follow == ["b"] and [q[:2] for q in shelf.push_questions] == [("b", "T")]
    assert lines == ["weighing push 1 of 2: b out of T's lanes (cost 1.00)"]  # the goal's feedback, per candidate


def test_a_push_followed_by_no_sequence_is_executed_only_while_a_further_push_is_left():
    """Every push slips (nothing follows any): with max_pushes 1 none is executed, and the end says why; with 2 the
    cheapest is executed as before (a second push may open what the first does not), its record listing the other
    candidate as refused, and no second one (after it, too, nothing would follow)."""
    one = Lookahead(slip={"b", "T"})
    out = looking(one, max_pushes=1)
    assert not out.success and not one.pushes
    assert "no push: every push refused: b out of T's lanes (no pick sequence after it: " in out.message, out.message
    two = Lookahead(slip={"b", "T"})
    out = looking(two, max_pushes=2)
    assert not out.success and [p[:2] for p in two.pushes] == [("b", "T")], two.pushes  # the last push must open
    (first,) = out.pushes
    assert first.then == () and len(first.refused) == 1  # T's, not its own
    assert first.refused[0].startswith("T out of b's lanes (no pick sequence after it: "), first.refused


def test_pushed_problem_takes_the_prep_away_and_moves_the_pushed_object():
    from qtree_task_planner.executive.replan import pushed_problem
    rp = remaining_problem(SCENARIO, PushShelf().perceive(), ())
    after = pushed_problem(rp, "b", (0.55, 0.2), ("a",))
    assert "a" not in after.problem.obstacles and "a" in after.gone and after.relocated == ("a",)
    assert len(after.free_slots) == len(rp.free_slots) - 1
    assert after.geometry()["b"][:2] == (0.55, 0.2) and after.moved["b"] == (0.55, 0.2)
    assert after.problem.costs == {o: c for o, c in rp.problem.costs.items() if o != "a"}


# ------------------------------------------------------------------------------------------------ ROS clients
def test_service_oracle_what_if_asks_on_the_moved_scene(monkeypatch):
    """ServiceOracle.what_if: every question it asks carries the moved objects (PlanFeasibility moved_ids,
    moved_to); the oracle it came from asks as before. ReplicaOracle.what_if: each replica's."""
    from qtree_relocation_msgs.srv import PlanFeasibility

    from qtree_task_planner.executive.replicas import ReplicaOracle
    from qtree_task_planner.ros_clients import ServiceOracle
    asked = []

    def call(self, req, what):
        asked.append(req)
        return PlanFeasibility.Response(ok=True, label=1, message="ok", action="side_grasp")
    monkeypatch.setattr(ServiceOracle, "_call", call)
    plain = ServiceOracle(SimpleNamespace(srv_name="/mp/plan_feasibility"), 5.0, 1.0)
    moved = plain.what_if({"b": (0.55, 0.2)})
    moved.feasibility("T", frozenset({"a"}))
    moved.push("a", "T", frozenset())
    moved.lane_blockers(frozenset())
    plain.feasibility("T", frozenset())
    assert [(list(r.moved_ids), [(p.x, p.y) for p in r.moved_to]) for r in asked] == \
        [(["b"], [(0.55, 0.2)])] * 3 + [([], [])]
    replicas = ReplicaOracle([plain, ServiceOracle(SimpleNamespace(srv_name="/replica_1/x"), 5.0, 1.0)])
    assert [r.moved for r in replicas.what_if({"b": (0.5, 0.1)}).replicas] == [{"b": (0.5, 0.1)}] * 2
    assert [r.moved for r in replicas.replicas] == [{}, {}]


def test_service_oracle_asks_a_push_and_refuses_an_answer_that_is_not_one(monkeypatch):
    from geometry_msgs.msg import Pose
    from qtree_relocation_msgs.srv import PlanFeasibility

    from qtree_task_planner.ros_clients import ServiceOracle
    asked = []

    def answer(action):
        def call(self, req, what):
            asked.append(req)
            pose = Pose()
            pose.position.x, pose.position.y = 0.61, 0.12
            return PlanFeasibility.Response(ok=True, label=1, message="ok", action=action, end_pose=pose)
        return call
    oracle = ServiceOracle(SimpleNamespace(srv_name="/mp/plan_feasibility"), 5.0, 1.0)
    monkeypatch.setattr(ServiceOracle, "_call", answer("push"))
    assert oracle.push("b", "T", frozenset({"a"})) == PushAnswer(True, "ok", (0.61, 0.12))
    assert (asked[0].object_id, asked[0].action, asked[0].clear_for, list(asked[0].removed_ids)) == \
        ("b", "push", "T", ["a"])
    monkeypatch.setattr(ServiceOracle, "_call", answer("side_grasp"))  # a motion planner that does not push
    got = oracle.push("b", "T", frozenset())
    assert not got.feasible and "answered a side_grasp, not a push" in got.message

    def refused(self, req, what):
        raise ValueError("motion planner refused the query for the push of 'b': unknown action")
    monkeypatch.setattr(ServiceOracle, "_call", refused)
    assert oracle.push("b", "T", frozenset()) == PushAnswer(
        False, "motion planner refused the query for the push of 'b': unknown action", None)


def test_the_relocator_sends_the_push_as_a_relocate_object_goal():
    from test_closed_loop_wiring import _Future

    from qtree_task_planner.ros_clients import Relocator
    goals = []

    class Planner:
        def wait_for_server(self, timeout_sec):
            return True

        def server_is_ready(self):
            return True

        def send_goal_async(self, goal, feedback_callback):
            goals.append(goal)
            result = _Future(SimpleNamespace(result=SimpleNamespace(success=True, message="pushed")))
            return _Future(SimpleNamespace(accepted=True, get_result_async=lambda: result))
    relocator = Relocator(Planner(), server_wait=1.0, limit=10.0, silence=5.0, ok=lambda: True)
    assert relocator.relocate("b", ["a"], cancelled=lambda: False, action="push", clear_for="T") == (True, "pushed")
    assert relocator.relocate("c", [], cancelled=lambda: False) == (True, "pushed")
    assert [(g.object_id, list(g.removed_ids), g.action, g.clear_for) for g in goals] == [
        ("b", ["a"], "push", "T"), ("c", [], "", "")]


def test_the_demo_report_lists_each_push_and_a_first_plan_without_sequence_executes_nothing_else():
    """report.json's `pushes` (the execution's) and the summary's lines; chosen_sequence of no sequence at all."""
    from qtree_task_planner.executive.retrieval import chosen_sequence
    from relocation_app import run_report
    out = run(PushShelf(), [])
    report = {"final_scene": {}, "learned_sequence": None, "disturbances": [], "replans": out.to_dict()["replans"],
              "pushes": out.to_dict()["pushes"], "respawns": [], "end": {"kind": "success", "exit_code": 0},
              "success": True, "message": out.message, "wall_time_s": 1.0, "out": "out"}
    lines = run_report.summary(report)
    assert "pushed b out of T's lanes (predicted end (0.550, 0.100)); re-planned" in lines
    assert "re-plan: pushed b out of T's lanes (predicted end (0.550, 0.100)) -> T (0.00)" in lines, lines
    assert out.message == "target T retrieved after 0 relocations, 1 push and 2 re-plans"
    assert chosen_sequence(None, None, None, None, execute_optimum=False, execute_learned=False) == ([], "")


def test_a_push_done_without_effect_is_not_asked_again():
    """The motion planner says "pushed" and the next scene shows b where it was: that push is not asked again (the
    loop went on to T's push instead of spending max_pushes on the same one)."""
    shelf = PushShelf(ineffective=True)
    shelf.do_push = lambda obj, clear_for, removed: (shelf.pushes.append((obj, clear_for)), (True, "pushed"))[1]
    out = run(shelf, [], max_pushes=3)
    assert not out.success and shelf.pushes == [("b", "T"), ("T", "b")], shelf.pushes


def test_a_push_stopped_without_the_motion_planner_ends_the_run():
    """As a relocation's: a push that stopped with no motion planner to recover with (its words, STOPPED) ends the
    run with that reason instead of re-planning over an arm in an unknown state."""
    shelf = PushShelf()
    shelf.do_push = lambda obj, clear_for, removed: (False, "the motion planner went away (relocate action server "
                                                            "gone)")
    out = run(shelf, [])
    assert not out.success and out.message == "pushing 'b' failed: the motion planner went away (relocate action " \
        "server gone)", out.message
