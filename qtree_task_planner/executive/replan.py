"""Re-planning the remaining retrieval over the exact blocker A* (astar.py, Eq. 8), keeping what is still true.

A feasibility answer (relocate o with a set removed, from home) depends on the geometry of the objects still on
the top shelf: o and every object not removed. `GeometryCache` keys each answer by those objects and the
*version* of each one's pose; a version changes only when the object is perceived to have moved (more than
`tol` m, by default the tolerance within which world.verify_relocation says a bottle stayed) or tipped (a
tipped bottle's answers are asked again: the motion planner's grasp from above, or its reason why not).
So after a disturbance only the answers in which a moved object was still present are asked again; those
where it was already removed, and everything about undisturbed parts of the shelf, stay.
Relocating an object does not change anyone's answers: a question after it is the old question with one more
object removed.

`RemainingOracle` poses the RemainingProblem's questions (object, S) to the planner as (object, gone | S) and
answers g_U, without asking, for a failed option (closed_loop.Option) and for a relocation that would need more
slots than are free: the A* then returns the least-weight sequence that fits the bottom shelf, still proven
optimal under that constraint, or none.

`relearn` trains the Q-Tree again on a remaining problem (Eq. 7), over the same oracle, when the user asks for it
(the task planner's `replan_q_tree`); otherwise a re-plan is the A* alone.
"""
from __future__ import annotations

import dataclasses
import math
from typing import Callable, Iterable, Mapping, Sequence

from qtree_task_planner.executive.closed_loop import Option, ReplanAnswer
from qtree_task_planner.executive.world import RemainingProblem, Tolerances, configured
from qtree_task_planner.learning.params import TrainingParams
from qtree_task_planner.learning.training import train
from qtree_task_planner.oracles import Lanes, no_grasp
from qtree_task_planner.search import astar
from qtree_task_planner.search.exact import (
    Claim,
    blocking_needs,
    can_leave,
    laneless_blockers,
    laneless_in_lanes,
    no_sequence,
)
from relocation_common.feasibility import (
    FeasibilityAnswer,
    FeasibilityOracle,
    Label,
    Query,
    action_set,
    ask_many,
    certifies,
    certify_many,
    claims,
    in_flight,
    is_pick,
)

Pose = tuple[float, float, float]  # x, y, tilt
Key = tuple[str, frozenset[tuple[str, int]]]  # GeometryCache.key: (object, {(present object, pose version)})


class GeometryCache:
    """Feasibility answers kept while the geometry they were computed on is unchanged (module doc). `calls`: real
    planner calls; `hits`: questions answered from the cache."""

    def __init__(self, oracle: FeasibilityOracle, tolerances: Tolerances | None = None) -> None:
        tol = tolerances or configured()  # a pose moved by more than `still`, or tipped past `tilt`: a new version
        self.oracle, self.tol, self.tilt_tol = oracle, tol.still, tol.tilt
        self._ref: dict[str, Pose] = {}
        self._version: dict[str, int] = {}
        self.table: dict[Key, FeasibilityAnswer] = {}
        self.certified: dict[Key, FeasibilityAnswer] = {}
        self._lanes: dict[Key, Lanes | None] = {}
        self.calls = self.hits = 0

    def observe(self, geometry: Mapping[str, Pose]) -> list[str]:
        """Take a perceived geometry (id -> (x, y, tilt) of the objects on the top shelf); returns the ids whose
        version changed (new ones, or moved by more than tol, or tipped by more than tilt_tol)."""
        changed = []
        for oid, pose in sorted(geometry.items()):
            ref = self._ref.get(oid)
            if ref is None or math.hypot(pose[0] - ref[0], pose[1] - ref[1]) > self.tol or \
                    abs(pose[2] - ref[2]) > self.tilt_tol:
                self._ref[oid] = pose
                self._version[oid] = self._version.get(oid, -1) + 1
                changed.append(oid)
        return changed

    def adopt(self, table: Mapping[tuple[str, frozenset[str]], FeasibilityAnswer],
              geometry: Mapping[str, Pose],
              certified: Mapping[tuple[str, frozenset[str]], FeasibilityAnswer] | None = None) -> int:
        """Take the answers of a set-keyed table (oracles.CachedOracle.table: (object, removed) -> answer) gathered
        on `geometry` (id -> (x, y, tilt) of the objects on the top shelf when they were asked: the first scene),
        before anything moved (ValueError once an object's version changed). The optimum's and training's answers
        then serve re-plans on that geometry; a later `observe` of a bottle elsewhere makes them about the old
        pose (without the geometry, the first re-plan's scene became version 0, disturbed or not). Returns how
        many."""
        if any(v > 0 for v in self._version.values()):
            raise ValueError("adopt answers before any object moved: they were computed on the first geometry")
        self.observe(geometry)
        if any(v > 0 for v in self._version.values()):
            raise ValueError("adopt answers on the geometry they were computed on: this cache saw another one")
        ids = frozenset(geometry)
        n = 0
        for (obj, removed), answer in table.items():
            k = self.key(obj, ids - removed)
            if k not in self.table:
                self.table[k], n = answer, n + 1
        for (obj, removed), answer in (certified or {}).items():  # the certifications too (CachedOracle.certified)
            self.certified.setdefault(self.key(obj, ids - removed), answer)
        return n

    def key(self, object_id: str, present: Iterable[str]) -> Key:
        """The cache key of a question about object_id with `present` (the objects not removed) on the shelf."""
        return object_id, frozenset((p, self._version.get(p, 0)) for p in set(present) | {object_id})

    def feasibility(self, object_id: str, removed: frozenset[str], present: Iterable[str]) -> FeasibilityAnswer:
        """The planner's answer for (object_id, removed), from the cache when `present`'s geometry is unchanged."""
        k = self.key(object_id, present)
        answer = self.table.get(k)
        if answer is None:
            answer = self.table[k] = self.oracle.feasibility(object_id, frozenset(removed))
            self.calls += 1
        else:
            self.hits += 1
        return answer

    def certify(self, object_id: str, removed: frozenset[str], present: Iterable[str]) -> FeasibilityAnswer:
        """The certification of (object_id, removed) (relocation_common.feasibility, "Certification"), cached like
        the answers; a failed one turns the cached answer unfeasible. A final answer (no pick alone:
        feasibility.is_pick), or any of a planner that does not certify, is its own certification."""
        k = self.key(object_id, present)
        got = self.certified.get(k)
        if got is None:
            answer = self.feasibility(object_id, removed, present)
            if not (certifies(self.oracle) and is_pick(answer)):  # final (feasibility.is_pick)
                got = answer
            else:
                got = certify_many(self.oracle, [(object_id, frozenset(removed))])[0]
                self.calls += 1
                if Label(got.label) == Label.UNFEASIBLE:
                    self.table[k] = dataclasses.replace(got, message=f"certification: {got.message}", blockers=())
            self.certified[k] = got
        return got

    def lane_blockers(self, removed: frozenset[str], present: Iterable[str]) -> Lanes | None:
        """The planner's lane blockers with `removed` gone (None if it has none), cached like the answers."""
        ask = getattr(self.oracle, "lane_blockers", None)
        if ask is None:
            return None
        k = self.key("", present)
        if k not in self._lanes:
            self._lanes[k] = ask(frozenset(removed))
        return self._lanes[k]


class RemainingOracle:
    """The feasibility oracle of a RemainingProblem (module doc): questions over its obstacles, asked of the
    GeometryCache with the objects already gone removed; banned options and relocations beyond the free slots
    answer g_U without asking."""

    def __init__(self, rp: RemainingProblem, cache: GeometryCache, banned: Iterable[Option] = (),
                 capacity: bool = True) -> None:
        if rp.problem is None:
            raise ValueError(f"no problem to solve: {rp.reason}")
        self.rp, self.cache, self.banned = rp, cache, tuple(banned)
        self.slots = len(rp.free_slots) if capacity else None
        self.target = rp.problem.target
        self.on_shelf = frozenset(rp.problem.ids)

    def feasibility(self, object_id: str, removed: frozenset[str]) -> FeasibilityAnswer:
        """g_U for a banned option or a slot too many; else the (cached) planner answer."""
        full = self.rp.gone | removed
        if any(b.bans(object_id, full) for b in self.banned):
            return FeasibilityAnswer(Label.UNFEASIBLE, message=f"{object_id} failed with these objects removed")
        if self.slots is not None and not fits(object_id, removed, self.slots, self.target):
            return no_slot(object_id, self.slots)
        return self.cache.feasibility(object_id, full, self.on_shelf - removed)

    def certify(self, object_id: str, removed: frozenset[str]) -> FeasibilityAnswer:
        """The certification of a question (GeometryCache.certify); g_U as `feasibility` for a banned option or a
        slot too many."""
        answer = self.feasibility(object_id, removed)
        if Label(answer.label) == Label.UNFEASIBLE:
            return answer
        return self.cache.certify(object_id, self.rp.gone | removed, self.on_shelf - removed)

    def lane_blockers(self, removed: frozenset[str]) -> Lanes | None:
        """The planner's lane blockers for the objects of the problem (others are not ours to relocate)."""
        lanes = self.cache.lane_blockers(self.rp.gone | removed, self.on_shelf - removed)
        return None if lanes is None else {o: sets for o, sets in lanes.items() if o in self.on_shelf}


def fits(object_id: str, removed: frozenset[str], slots: int, target: str) -> bool:
    """Relocating object_id after `removed` with `slots` free slots at the start: it takes slot |removed| and an
    obstacle must leave one for the target."""
    return len(removed) + (1 if object_id == target else 2) <= slots


def no_slot(object_id: str, slots: int) -> FeasibilityAnswer:
    """The g_U of a relocation beyond the free slots (no blockers: a capacity limit, not geometry)."""
    return FeasibilityAnswer(Label.UNFEASIBLE, message=f"no free slot left for {object_id} and the target "
                             f"({slots} slots)")


class SlotLimit:
    """Any feasibility oracle with the bottom shelf's capacity as a constraint: with `slots` free slots, relocating
    an obstacle after `removed` needs |removed| + 2 <= slots (its slot and one left for the target), the target
    |removed| + 1 <= slots; beyond that the answer is g_U without asking. In front of the oracle of the exact
    solvers and of the Q-Tree's episodes (oracles.CachedOracle(SlotLimit(service, n, target))), no sequence
    needing more slots than exist is ever found. Lane blockers and batches pass through."""

    def __init__(self, oracle: FeasibilityOracle, slots: int, target: str) -> None:
        if slots < 1:
            raise ValueError(f"slots must be >= 1 (the target needs one), got {slots}")
        self.oracle, self.slots, self.target = oracle, slots, target

    def fits(self, object_id: str, removed: frozenset[str]) -> bool:
        """True when relocating object_id after `removed` leaves a slot for everything still to come."""
        return fits(object_id, removed, self.slots, self.target)

    def feasibility(self, object_id: str, removed: frozenset[str]) -> FeasibilityAnswer:
        """g_U beyond the slots, else the oracle's answer."""
        if self.fits(object_id, removed):
            return self.oracle.feasibility(object_id, removed)
        return no_slot(object_id, self.slots)

    @property
    def in_flight(self) -> int:
        """As the wrapped oracle (relocation_common.feasibility.BatchOracle)."""
        return in_flight(self.oracle)

    def feasibility_many(self, queries: Sequence[Query],
                         on_answer: Callable[[Query, FeasibilityAnswer], None] | None = None
                         ) -> list[FeasibilityAnswer]:
        """The queries that fit go to the wrapped oracle together; the others are g_U."""
        ask = [q for q in queries if self.fits(*q)]
        got = dict(zip(ask, ask_many(self.oracle, ask)))
        out = [got[q] if q in got else no_slot(q[0], self.slots) for q in queries]
        if on_answer is not None:
            for q, a in zip(queries, out):
                on_answer(q, a)
        return out

    def certify(self, object_id: str, removed: frozenset[str]) -> FeasibilityAnswer:
        """g_U beyond the slots, else the oracle's certification (its answer when it does not certify)."""
        if not self.fits(object_id, removed):
            return no_slot(object_id, self.slots)
        return certify_many(self.oracle, [(object_id, removed)])[0]

    def certify_many(self, queries: Sequence[Query],
                     on_answer: Callable[[Query, FeasibilityAnswer], None] | None = None
                     ) -> list[FeasibilityAnswer]:
        """The certifications of the queries that fit, together (feasibility.certify_many); the others g_U."""
        ask = [q for q in queries if self.fits(*q)]
        got = dict(zip(ask, certify_many(self.oracle, ask)))
        out = [got[q] if q in got else no_slot(q[0], self.slots) for q in queries]
        if on_answer is not None:
            for q, a in zip(queries, out):
                on_answer(q, a)
        return out

    def lane_blockers(self, removed: frozenset[str]) -> Lanes | None:
        """The wrapped oracle's lane blockers (geometry: capacity does not change them), None if it has none."""
        lanes = getattr(self.oracle, "lane_blockers", None)
        return None if lanes is None else lanes(removed)


def replan(rp: RemainingProblem, banned: Iterable[Option], cache: GeometryCache) -> ReplanAnswer | str:
    """The least-cost sequence (Eq. 8 with the problem's costs: the weight at factor 1) for the remaining problem that
    avoids failed options and fits the free slots: (sequence, Eq. 8's weight, planner calls it cost), or the reason
    there is none in one line, naming the actions it is a proof for (the problem's action_set; what the objects the
    hand cannot grasp have to do with it, `held_reason`, else the A*'s own, exact.why_none: the target without a
    lane, a blocking cycle; then the motion planner's reasons for those objects, `grasp_reason`). A bottle tipped
    over is asked about like any other: the motion planner's answer decides (its grasp from above where the
    headroom allows; "no grasp: " and the headroom it needs where not). The cache first takes the perceived
    geometry, so answers about moved objects are asked again and the others reused."""
    if rp.problem is None:
        return rp.reason
    banned = tuple(banned)
    cache.observe(rp.geometry())
    calls0 = cache.calls
    r = astar.solve(rp.problem, RemainingOracle(rp, cache, banned))
    if r.found:
        assert r.sequence is not None and r.total_weight is not None
        return r.sequence, r.total_weight, cache.calls - calls0
    t, n = rp.problem.target, len(rp.problem.obstacles)
    if banned or len(rp.free_slots) < n + 1:  # would it be reachable without the failed options and the slot limit?
        free = astar.solve(rp.problem, RemainingOracle(rp, cache, (), capacity=False))
        if free.found:
            assert free.sequence is not None
            why = []
            if len(free.sequence) > len(rp.free_slots):
                why.append(f"needs {len(free.sequence)} slots, {len(rp.free_slots)} free")
            if banned:
                why.append(f"failed options: {', '.join(sorted(b.object_id for b in banned))}")
            return (f"{t} cannot be reached with {action_set(rp.problem.action_set)}: every sequence left needs a "
                    f"failed option or more slots than are free (the best without those limits, "
                    f"{' '.join(free.sequence)}, {'; '.join(why)})")
    lanes = RemainingOracle(rp, cache, (), capacity=False).lane_blockers(frozenset())
    cannot = not_graspable(rp, cache, lanes)
    because = held_reason(t, lanes or {}, frozenset(cannot) - {t}) or \
        (f"; {r.reason.removeprefix(no_sequence(rp.problem.action_set))}" if r.reason else "")
    return (f"{t} cannot be reached: no feasible relocation sequence with {action_set(rp.problem.action_set)} over the "
            f"{n} obstacle{'s' * (n != 1)} on the top shelf ({cache.calls - calls0} planner calls){because}"
            f"{grasp_reason({o: m for o, m in cannot.items() if o != t})}")


def blocking_pairs(rp: RemainingProblem, cache: GeometryCache) -> tuple[tuple[str, str], ...]:
    """The pairs (X, Y) "X needs Y moved" of the blocking cycle a failed re-plan's proof names (exact.blocking_needs
    over the same certain claims at the problem's start: `start_claims`), then (X, T) for each object X in a lane of
    the target T that has no lane of its own (exact.laneless_blockers: "X has no lane", a bottle lying where no grasp
    reaches it; the push of X out of T's lanes is asked first), then (X, T) for each such X in a lane of T when the
    proof is no cycle (exact.laneless_in_lanes: T unfeasible from every set reached, its other lanes failed in the
    motion planner); () when there is none. What a push can open (qtree_task_planner.executive.push)."""
    if rp.problem is None:
        return ()
    t, claims = rp.problem.target, start_claims(rp, cache)
    pairs = tuple((x, y) for x, stuck in blocking_needs(t, claims) for y in stuck) + tuple(
        (x, t) for x in laneless_blockers(t, claims))
    return pairs + tuple((x, t) for x in laneless_in_lanes(t, claims) if (x, t) not in pairs)


def free_first(rp: RemainingProblem, cache: GeometryCache) -> tuple[str, ...]:
    """The objects of a failed re-plan's proof that the picks alone can take away first (exact.can_leave over
    `start_claims`): what a push may need gone (qtree_task_planner.executive.push)."""
    if rp.problem is None:
        return ()
    return can_leave(rp.problem.target, start_claims(rp, cache))


def start_claims(rp: RemainingProblem, cache: GeometryCache) -> dict[str, list[Claim]]:
    """The certain claims at the remaining problem's start: the planner's lane blockers and the answers about each
    object with nothing more removed, from the cache (no planner call beyond the lane screen)."""
    assert rp.problem is not None
    on_shelf = frozenset(rp.problem.ids)
    claimed: dict[str, list[Claim]] = {}
    for o, sets in (RemainingOracle(rp, cache, (), capacity=False).lane_blockers(frozenset()) or {}).items():
        if sets == () or claims(sets):  # as astar.Knowledge.lanes_known: () = no lane at all
            claimed.setdefault(o, []).append((frozenset(), tuple(b.objects for b in sets)))
    for o in rp.problem.ids:
        a = cache.table.get(cache.key(o, on_shelf))
        if a is not None and Label(a.label) == Label.UNFEASIBLE and claims(a.blockers):
            claimed.setdefault(o, []).append((frozenset(), tuple(b.objects for b in a.blockers)))
    return claimed


def not_graspable(rp: RemainingProblem, cache: GeometryCache, lanes: Lanes | None) -> dict[str, str]:
    """object -> the motion planner's "no grasp: " reason, for the objects on the top shelf (the target too) the
    hand cannot grasp as they are now (oracles.no_grasp over the answers about each object at its present pose and
    the objects without a lane): a standing one too wide, a box, a bottle lying under a board too low for the grasp
    from above, one leaning."""
    if rp.problem is None:
        return {}
    on_shelf = frozenset(rp.problem.ids)
    known = [(k[0], a) for k, a in cache.table.items() if cache.key(k[0], ())[1] <= k[1]]  # its pose as now
    return no_grasp(rp.problem.ids, lanes, known, lambda o: cache.feasibility(o, rp.gone, on_shelf))


def grasp_reason(cannot: Mapping[str, str]) -> str:
    """What a failed re-plan's line adds about the obstacles the hand cannot grasp (`not_graspable`; the target's
    reason is the A*'s), or ""."""
    return f"; never relocated, the hand cannot grasp {'it' if len(cannot) == 1 else 'them'}: " + "; ".join(
        f"{o} ({m})" for o, m in cannot.items()) if cannot else ""


def held_reason(t: str, lanes: Lanes, cannot: frozenset[str]) -> str:
    """What the obstacles the hand cannot grasp (`cannot`) have to do with a failed re-plan, from the planner's lane
    screen (no planner call; "" when nothing): every lane of the target `t` holding one; every lane of it holding
    one or an object that can never be moved because of them (`never_free`)."""
    if not cannot:
        return ""
    t_lanes = lanes.get(t)
    if t_lanes and all(b.certain and b.objects & cannot for b in t_lanes):
        inside = sorted(frozenset().union(*(b.objects for b in t_lanes)) & cannot)
        return f"; every lane of {t} holds an object the hand cannot grasp ({', '.join(inside)})"
    stuck = never_free(lanes, cannot)
    if t in stuck:
        held = ", ".join(sorted(stuck - cannot - {t}))
        return (f"; every lane of {t} holds an object the hand cannot grasp ({', '.join(sorted(cannot))}) or one "
                f"that can never be moved because each of its lanes holds such an object ({held})")
    return ""


def never_free(lanes: Lanes, cannot: frozenset[str]) -> frozenset[str]:
    """The objects that can never be relocated because of those the hand cannot grasp (`cannot`): those, and (to a
    fixpoint) every object each of whose lanes holds one of them (lanes: LaneOracle.lane_blockers; only certain
    blocker sets count: such a lane is clear exactly when all its blockers are gone, and an object no grasp takes
    never goes)."""
    stuck = set(cannot)
    grew = True
    while grew:
        grew = False
        for obj, sets in lanes.items():
            if obj not in stuck and sets and all(b.certain and b.objects & stuck for b in sets):
                stuck.add(obj)
                grew = True
    return frozenset(stuck)


def relearn(rp: RemainingProblem, banned: Iterable[Option], cache: GeometryCache, params: TrainingParams,
            exact: ReplanAnswer, keep_going: Callable[[], bool] = lambda: True) -> ReplanAnswer:
    """The Q-Tree trained again on the remaining problem (Eq. 7, `params`: policy, search, E_max, Eq. 16), asking
    the re-plan's own oracle (failed options and slots beyond the free ones g_U, answers of unchanged geometry
    reused), after the A* found `exact` (its optimum: the E_1st reference). The learned sequence is kept when it
    costs no more than the A*'s (the problem's costs: the weight at factor 1; as retrieval.chosen_sequence), else
    the A*'s, and the note says which, with both weights (and costs, in a costed problem), the episodes and whether
    Eq. 16 was met. keep_going() False stops training (a cancelled goal).
    The calls are the A*'s and training's together."""
    if rp.problem is None:
        raise ValueError(f"no problem to train on: {rp.reason}")
    seq, weight, calls = exact[:3]
    cost = rp.problem.cost(seq)
    calls0 = cache.calls
    r = train(rp.problem, RemainingOracle(rp, cache, tuple(banned)), params, optimal_weight=weight, optimal_cost=cost,
              callback=lambda stats: keep_going(), callback_every=50)
    calls += cache.calls - calls0
    steady = f"{r.e_ss} episodes" + ("" if r.converged else " (E_max or stopped, Eq. 16 not met)")
    if not r.found or r.total_weight is None:
        return seq, weight, calls, f"Q-Tree retrained: no sequence in {steady}; executing the A*'s optimum"
    mine = rp.problem.cost(r.sequence or ())
    costed = rp.problem.costed
    learned = f"learned {' '.join(r.sequence or ())} ({_amount(r.total_weight, mine, costed)}) in {steady}"
    if mine <= cost + 1e-9:
        return tuple(r.sequence or ()), r.total_weight, calls, f"Q-Tree retrained: {learned}, executed"
    return seq, weight, calls, f"Q-Tree retrained: {learned}; executing the A*'s optimum " \
        f"({_amount(weight, cost, costed).removeprefix('weight ')}) instead"


def _amount(weight: float, cost: float, costed: bool) -> str:
    """'weight 0.50', or in a costed problem (an action factor other than 1) 'weight 0.50, cost 0.75'."""
    return f"weight {weight:.2f}" + (f", cost {cost:.2f}" if costed else "")


def pickable(rp: RemainingProblem, cache: GeometryCache, banned: Iterable[Option], object_id: str,
             removed: frozenset[str]) -> bool:
    """Whether the re-plan's oracle (`RemainingOracle`: failed options `banned` and the free slots counted, answers
    of unchanged geometry reused) answers relocating `object_id` with `removed` gone (beyond rp.gone) feasible: an
    order in which a push's prep relocations can go (qtree_task_planner.executive.push.pick_order)."""
    return Label(RemainingOracle(rp, cache, banned).feasibility(object_id, removed).label) != Label.UNFEASIBLE


def after_push(rp: RemainingProblem, banned: Iterable[Option], pushed: str, end: tuple[float, float],
               prep: Sequence[str], what_if: Callable[[Mapping[str, tuple[float, float]]], FeasibilityOracle],
               tolerances: Tolerances | None = None) -> tuple[tuple[str, ...], float] | str:
    """What would follow a push (docs/closed_loop.md, "Pushes"): the least-cost pick sequence of the remaining
    problem once its prep relocations `prep` are done and `pushed` is at its predicted `end` (x, y), the A* over the
    picks (`replan`) asking `what_if({pushed: end})` (the motion planner on that scene: PlanFeasibility's moved_ids,
    moved_to) through a cache of its own; (the sequence, its cost) or the reason there is none, in one line."""
    after = pushed_problem(rp, pushed, end, prep)
    got = replan(after, banned, GeometryCache(what_if({pushed: end}), tolerances))
    if isinstance(got, str):
        return got
    assert after.problem is not None
    return tuple(got[0]), after.problem.cost(got[0])


def pushed_problem(rp: RemainingProblem, pushed: str, end: tuple[float, float], prep: Sequence[str]
                   ) -> RemainingProblem:
    """The remaining problem `rp` once the objects of `prep` are relocated (gone, each in a free slot) and `pushed`
    is at `end` on the top shelf (as it was turned and resting)."""
    if rp.problem is None:
        raise ValueError(f"no problem to push in: {rp.reason}")
    p, gone = rp.problem, frozenset(prep)
    keep = tuple(o for o in p.obstacles if o not in gone)
    problem = dataclasses.replace(p, obstacles=keep, weights={o: p.weights[o] for o in keep},
                                  estimated={o: w for o, w in p.estimated.items() if o in keep},
                                  costs={o: p.costs[o] for o in keep})
    bottles = tuple(dataclasses.replace(b, x=end[0], y=end[1]) if b.id == pushed else b
                    for b in rp.bottles if b.id not in gone)
    return dataclasses.replace(rp, problem=problem, bottles=bottles, relocated=rp.relocated + tuple(prep),
                               gone=rp.gone | gone, moved={**rp.moved, pushed: end},
                               free_slots=rp.free_slots[len(gone):])
