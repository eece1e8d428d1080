"""What the blocker A* (astar.py) has learnt, and the two bounds it draws from it: the heuristic and the objects
worth removing (docs/qtree.md, "Exact minimum-weight sequence from blockers").

Knowledge. A certain blocker claim (relocation_common.feasibility: an unfeasible answer whose BlockerSets are all
certain, or the oracle's `lane_blockers`) of object o made at set S says: from S or any superset, relocating o needs
one of its lanes cleared (all of that lane's objects removed). Uncertain sets claim nothing and are not kept. A claim
another one already implies (made at a subset, every old lane holding a new one once S is removed) is not kept.

The optimistic graph G (astar.py) has the edge "relocate o after R" unless o was answered g_U at exactly R, or a
claim of o made at some S <= R has no lane inside R. A path of G from R relocates o_1 .. o_k, then the target T; its
weight (Eq. 8) is phi(o_1) + .. + phi(o_k) in any order. A claim made at S <= R is *open* at R when none of its lanes
is inside R; a claim with a lane inside R holds at every superset of R, so it never blocks again.

1. Forced objects, F_R(o) (`frame`): objects not in R that every path of G from R removes before relocating o.
   The least fixpoint, grown from F = {} for every object, of
       lane(o, b) = (b - R) | union of F(y) over y in b - R, no way if it holds o or an impossible y;
       F(o)      = union over the claims of o open at R of (the intersection of lane(o, b) over its lanes b
                   that are a way); impossible when a claim has no lane that is a way.
   Proof, by induction over the iterations: a path of G from R that relocates o at R' >= R meets every claim of o
   open at R (it is made at S <= R <= R'), so one of its lanes b is inside R'; each y in b - R left the path before o,
   at a set not holding o, so (induction) F(y) was removed before y and o is not in it, and b is a way; hence
   lane(o, b) <= R' - R, so is the intersection, so is the union over the claims. An impossible y has no path at
   all. Objects without any claim (no lane information) get F = {}: nothing is known, so nothing is forced.
   Claims not yet made, or made at sets that are not subsets of R, are left out, which only weakens F (sound).
2. Heuristic h(R) (`h`): the largest of w(F_R(T)); `need(T)`: over the open claims of T the lightest of its
   lanes' weights w(lane(T, b)), plus, for the objects y of that lane, the most any one needs beyond it for one of
   its own lanes (recursively, `depth` levels; a lane of y needing an object that leaves after y is no way); and
   the chain bound d(T) (`chain`): d(o) = over the open claims of o the least over their lanes of the larger of
   w(lane(o, b)) and the most w(y) + d(y) of an object y of b, an object without open claims 0.
   Admissible on G: any path relocating T clears one lane b of every open claim of T, so removes lane(T, b) (1.),
   and each y in b cleared one of its own lanes before it left; the y's may share what they need, hence the max,
   not the sum. For d, by induction over the order in which `chain` settles objects: everything removed before y
   is removed before o too, and y itself, so a path relocating o removes at least w(y) + d(y) before it, and all
   of lane(o, b); an object whose every way needs an unsettled one (a cycle, an impossible object) is never
   settled, and a target never settled has no path (infinity). An impossible target gives h = infinity (the set
   is pruned). Memoised by set across the searches; a new (not implied) claim made at S clears the memo of the
   supersets of S, an answer alone does not change h. The sums lose ROUNDING so float rounding never lifts them
   over w(F_R(T)) (f is then one exact sum, and the sets of one closure tie exactly).
3. Objects worth removing, D(R) (`relevant`): T, and, grown to a fixpoint, the objects not in R of every lane of
   every claim (made at any set) of an object in D(R) that is not held at R (no lane inside R). The search removes
   only objects of D(R) after R, unless an *unexplained* g_U answer (o, S) (o answered unfeasible at S though every
   claim of o made at a subset of S holds at S: uncertain blockers, none, or a failure no lane explains) has o in
   D(R) and R <= S <= R | D(R): then every object may be removed after R.
   Proof (no optimal path of G is lost). Take a path P of G from R: R = R_0 < R_1 < .. < R_k, then T from R_k, and
   keep only its objects of D(R): the sets R'_i = R | (R_i & D(R)). Each kept edge "o after R'_i" (o in D(R), T
   included) is in G: a claim of o made at S <= R'_i is made at S <= R_i, so P cleared one of its lanes b <= R_i;
   if the claim holds at R, a lane of it is inside R <= R'_i; if not, every object of each of its lanes is in R or,
   by the closure, in D(R), so b <= R | (R_i & D(R)) = R'_i. An answer g_U at exactly (o, R'_i) is then unexplained
   (its own claim, made at R'_i, holds there), with o in D(R) and R <= R'_i <= R | D(R): excluded by the rule. So
   the kept path is in G and weighs less when an object was dropped (every phi > 0): every optimal path of G from
   R removes only objects of D(R) (or the rule allows all). Several lanes (alternatives) are all followed; an
   object with no lane information adds nothing to D(R) but is in it when a lane names it; a target without any
   claim has D(R) = {T}, and only an unexplained answer (the target's own uncertain g_U, say) opens the others.
"""
from __future__ import annotations

import heapq
import math
from dataclasses import dataclass
from typing import Mapping, Sequence

from qtree_task_planner.search.exact import Claim
from relocation_common.feasibility import BlockerSet, FeasibilityAnswer, Label, Query, claims

DEPTH = 2  # levels of the blockers' own lanes in `need`
Forced = dict[str, "frozenset[str] | None"]  # object -> F_R(object), None: impossible from R
Lanes = tuple[frozenset[str], ...]
ROUNDING = 1e-9  # taken off the summed bounds: their float rounding must not break the exact ties of w(F_R(T))


@dataclass
class Frame:
    """One removed set R seen from the target: the claims open at R of the objects reached through their lanes,
    F_R of each (1.; None: impossible) and each open lane's value lane(o, b) (None: no way), claim by claim."""

    removed: frozenset[str]
    opened: dict[str, list[Lanes]]
    forced: Forced
    values: dict[str, list[list[frozenset[str] | None]]]


def _implies(old: Claim, new: Claim) -> bool:
    """Whether claim `old` implies claim `new`: made at a subset, and every old lane, once new's set is removed,
    holds a lane of new (every superset of new's set clearing an old lane clears a new one)."""
    (s0, lanes0), (s, lanes) = old, new
    return s0 <= s and all(any(b <= b0 | s for b in lanes) for b0 in lanes0)


class Knowledge:
    """What the answers said: feasibility of asked edges and certain blocker claims (object -> [(S, lanes)]), and
    the bounds of the module doc: `h` (2.) and `relevant` (3.)."""

    def __init__(self, weights: Mapping[str, float], target: str, depth: int = DEPTH) -> None:
        self.weights, self.target, self.depth = weights, target, depth
        self.answers: dict[Query, bool] = {}
        self.claims: dict[str, list[Claim]] = {}
        self._h: dict[frozenset[str], tuple[float, int, float]] = {}  # set -> bound(set)
        self._relevant: dict[frozenset[str], frozenset[str] | None] = {}
        self._unexplained: list[Query] | None = None

    def claim(self, obj: str, removed: frozenset[str], blockers: Sequence[BlockerSet]) -> None:
        """Record a certain claim (ignored unless every set is certain)."""
        if claims(blockers):
            self._add(obj, (frozenset(removed), tuple(b.objects for b in blockers)))

    def lanes_known(self, obj: str, removed: frozenset[str], lanes: tuple[BlockerSet, ...]) -> None:
        """From lane_blockers: object -> its lanes (an empty tuple: never relocatable; certain sets only)."""
        if lanes == ():
            self._add(obj, (frozenset(removed), ()))
        else:
            self.claim(obj, removed, lanes)

    def _add(self, obj: str, entry: Claim) -> None:
        """Keep a claim unless one already kept implies it; the memos that depend on claims are cleared."""
        if any(_implies(old, entry) for old in self.claims.get(obj, ())):
            return
        self.claims.setdefault(obj, []).append(entry)
        made = entry[0]  # h(R) reads only the claims made at subsets of R
        self._h = {r: v for r, v in self._h.items() if not made <= r} if made else {}
        self._relevant.clear()
        self._unexplained = None

    def record(self, obj: str, removed: frozenset[str], answer: FeasibilityAnswer) -> bool:
        """Remember an answer (and its lane blockers); whether the object was feasible."""
        ok = Label(answer.label) != Label.UNFEASIBLE
        self.answers[(obj, removed)] = ok
        if not ok:
            self._relevant.clear()
            self._unexplained = None
            self.claim(obj, removed, answer.blockers)
        return ok

    def held(self, obj: str, removed: frozenset[str]) -> bool:
        """Every claim of `obj` made at a subset of `removed` has a lane inside it."""
        return all(any(b <= removed for b in lanes) for s, lanes in self.claims.get(obj, ()) if s <= removed)

    def possible(self, obj: str, removed: frozenset[str]) -> bool:
        """The edge is in the optimistic graph: not answered g_U, and every applicable claim held."""
        return self.answers.get((obj, removed)) is not False and self.held(obj, removed)

    def verified(self, obj: str, removed: frozenset[str]) -> bool:
        """Whether the planner answered feasible for `obj` after `removed`."""
        return self.answers.get((obj, removed)) is True

    def unexplained(self) -> list[Query]:
        """The g_U answers no kept claim explains (module doc, 3.)."""
        if self._unexplained is None:
            self._unexplained = [(o, s) for (o, s), ok in self.answers.items() if not ok and self.held(o, s)]
        return self._unexplained

    def h(self, removed: frozenset[str]) -> float:
        """Admissible lower bound on the weight still to remove before the target can be relocated (2.)."""
        return self.bound(removed)[0]

    def bound(self, removed: frozenset[str]) -> tuple[float, int, float]:
        """(h(removed), how many objects are forced before the target (F_R(T)'s size), f = g + h), memoised. f is
        summed in one exact sum when w(F_R(T)) is the bound, so sets of one closure tie exactly."""
        got = self._h.get(removed)
        if got is None:
            frame = self.frame(removed)
            mine = frame.forced[self.target]
            if mine is None:
                got = (math.inf, 0, math.inf)
            else:
                need = max(self.need(frame, self.target, frozenset(), frozenset(), self.depth),
                           self.chain(frame)) - ROUNDING  # a lower bound may only go down
                h = self._w(mine)
                f = self._w(removed | mine) if h >= need else self._w(removed) + need
                got = (max(h, need), len(mine), f)
            self._h[removed] = got
        return got

    def _w(self, objects: frozenset[str]) -> float:
        """Weight of a set (Eq. 8); the target (or an unknown id) weighs infinity: nothing leaves after it."""
        return math.fsum(self.weights.get(y, math.inf) for y in objects)  # fsum: exact in any set order

    def frame(self, removed: frozenset[str]) -> Frame:
        """The claims open at `removed` (made at a subset, no lane inside) of every object reached from the target
        through their lanes (the objects not in `removed`), with F_R (1.) and the lanes' values."""
        opened: dict[str, list[Lanes]] = {}
        todo = [self.target]
        while todo:
            o = todo.pop()
            mine = opened[o] = [ls for s, ls in self.claims.get(o, ()) if s <= removed
                                and not any(b <= removed for b in ls)]
            todo.extend(y for ls in mine for b in ls for y in b - removed if y not in opened and y not in todo)
        frame = Frame(removed, opened, {o: frozenset() for o in opened}, {})
        while self._grow(frame):
            pass
        return frame

    def _grow(self, frame: Frame) -> bool:
        """One round of the fixpoint of 1. over every object of the frame (the ones found last first: fewer rounds on
        chains), keeping each lane's value; whether a forced set grew."""
        changed = False
        forced = frame.forced
        for o in reversed(list(frame.opened)):
            if forced[o] is None:
                continue
            got: set[str] | None = set()
            values = frame.values[o] = []
            for lanes in frame.opened[o]:
                values.append([self.lane(o, b, frame.removed, forced) for b in lanes])
                ways = [v for v in values[-1] if v is not None]
                if not ways:
                    got = None
                    break
                assert got is not None
                got |= frozenset.intersection(*ways)
            new = None if got is None else frozenset(got)
            if new != forced[o]:
                forced[o], changed = new, True
        return changed

    @staticmethod
    def lane(obj: str, lane: frozenset[str], removed: frozenset[str], forced: Forced) -> frozenset[str] | None:
        """lane(o, b) of 1.: the lane's objects not removed and what each is forced to need; None if that holds
        `obj` itself or an impossible object."""
        members = lane - removed
        out = set(members)
        for y in members:
            f = forced.get(y, frozenset())
            if f is None:
                return None
            out |= f
        return None if obj in out else frozenset(out)

    def need(self, frame: Frame, obj: str, free: frozenset[str], chain: frozenset[str], depth: int) -> float:
        """Weight outside `free` that must be removed before `obj` (2.; objects of `chain` leave after it)."""
        best = 0.0
        for lanes, values in zip(frame.opened.get(obj, ()), frame.values.get(obj, ())):
            low = math.inf
            for b, v in zip(lanes, values):
                if v is None or v & chain:
                    continue
                cost = self._w(v - free)
                if depth and cost < low:
                    sub, up = free | v, chain | {obj}
                    cost += max((self.need(frame, y, sub, up, depth - 1) for y in b - frame.removed), default=0.0)
                low = min(low, cost)
            best = max(best, low)
        return best

    def chain(self, frame: Frame) -> float:
        """d(T) of 2.: d(o) = over the claims of o open at R, the least over its lanes b of the larger of
        w(lane(o, b)) and the most w(y) + d(y) of an object y of b; solved as Knuth's generalisation of Dijkstra
        (every lane's value is at least each of its objects' d), so an object is settled only through lanes of
        settled objects: cycles never settle, the target then unreachable (infinity)."""
        waiting: dict[str, list[tuple[str, int, int]]] = {}  # object -> the lanes (owner, claim, lane) it is in
        left: dict[tuple[str, int, int], int] = {}  # lane -> objects of it not settled yet
        top: dict[tuple[str, int, int], float] = {}  # lane -> its value so far
        best: dict[str, list[float]] = {o: [math.inf] * len(cl) for o, cl in frame.opened.items()}
        heap: list[tuple[float, str]] = []
        for o, cl in frame.opened.items():
            if frame.forced[o] is None:
                continue
            for c, (lanes, values) in enumerate(zip(cl, frame.values[o])):
                for k, (b, v) in enumerate(zip(lanes, values)):
                    if v is None:
                        continue
                    key, members = (o, c, k), b - frame.removed
                    left[key], top[key] = len(members), self._w(v)
                    for y in members:
                        waiting.setdefault(y, []).append(key)
                    if not members:
                        best[o][c] = min(best[o][c], top[key])
            heapq.heappush(heap, (max(best[o], default=0.0), o))
        settled: set[str] = set()
        while heap:
            value, o = heapq.heappop(heap)
            if o in settled or math.isinf(value):
                continue
            if o == self.target:
                return value
            settled.add(o)
            for key in waiting.get(o, ()):
                top[key] = max(top[key], self.weights.get(o, math.inf) + value)
                left[key] -= 1
                owner, c, _ = key
                if left[key] == 0 and owner not in settled and top[key] < best[owner][c]:
                    best[owner][c] = top[key]
                    heapq.heappush(heap, (max(best[owner]), owner))
        return math.inf

    def relevant(self, removed: frozenset[str]) -> frozenset[str] | None:
        """D(R) of 3. without the target: the objects worth removing after `removed`; None: every object (an
        unexplained answer in reach), memoised until the next claim or g_U answer."""
        if removed in self._relevant:
            return self._relevant[removed]
        worth = {self.target}
        todo = [self.target]
        while todo:
            o = todo.pop()
            for _, lanes in self.claims.get(o, ()):
                if not any(b <= removed for b in lanes):
                    new = {y for b in lanes for y in b - removed} - worth
                    worth |= new
                    todo.extend(new)
        out: frozenset[str] | None = frozenset(worth - {self.target})
        if any(o in worth and removed <= s and s - removed <= worth for o, s in self.unexplained()):
            out = None
        self._relevant[removed] = out
        return out
