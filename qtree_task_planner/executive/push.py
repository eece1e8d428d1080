"""Pushes out of a blocking cycle, ROS-free: what the closed loop does when the A* proves that no pick sequence
frees the target (docs/closed_loop.md, "Pushes").

The proof's blocking cycle ("X needs T moved": every lane of X needs T gone and the other way round,
exact.blocking_needs) is what a non-prehensile push can open: X slid out of T's grasp lanes, or T out of X's. For
each pair the motion planner is asked for a push of X clearing T's lanes, then of T clearing X's, with the objects
already gone removed; a push refused so is asked again with the objects the picks alone can take away first gone
too (the proof's own fixpoint, exact.can_leave, in an order in which each is pickable: `pick_order`), and when
feasible, again without each of those, heaviest first, keeping only the ones the push needs gone (its `prep`). A
push of an object costs its weight times the push factor (the paper's cost of an action, Eq. 8, with the factor of
the action kind; config/task_planner.yaml), a candidate its prep relocations' pick costs plus its push's; the
cheapest feasible one is executed: the closed loop relocates its prep objects (verified as every relocation, the
rest re-planned when one fails or the world differs), then pushes (RelocateObject, action "push"); it then waits for
the next scene and re-plans from what the world shows (the pushed object where it really ended), as after a
relocation. At most `max_pushes` pushes are executed per goal; a push that left the object where it was (failed, or
done without effect) is not asked again.

Nothing here talks to ROS: the node supplies `ask` (ros_clients.ServiceOracle.push: PlanFeasibility, action
"push") and `execute` (ros_clients.Relocator.push: RelocateObject, action "push").
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any, Callable, Mapping, Protocol, Sequence

PUSH = "push"  # the action's name in PlanFeasibility and RelocateObject


@dataclass(frozen=True)
class PushAnswer:
    """The motion planner's answer to "push object_id out of clear_for's grasp lanes": feasible, its message, and
    the pushed object's predicted end (x, y) on the top shelf (None when unfeasible)."""

    feasible: bool
    message: str
    end: tuple[float, float] | None


class PushOracle(Protocol):
    """Anything that answers the push question (ros_clients.ServiceOracle)."""

    def push(self, object_id: str, clear_for: str, removed: frozenset[str]) -> PushAnswer:
        """Can `object_id` be pushed out of the grasp lanes of `clear_for`, with `removed` gone?"""
        ...


@dataclass(frozen=True)
class PushRecord:
    """One push executed: the object, the one whose lanes it clears, its cost (weight x push factor, plus its prep
    relocations' costs), the predicted end, the motion planner's outcome, where the next scene showed the object
    (None: not seen on the top shelf), the candidates refused before it (one line each), the objects relocated
    first to free it (`prep`) and the pick sequence expected after it (`then`, PushChoice.then: () when not looked
    at or none; the closed loop re-plans from what it sees)."""

    object_id: str
    clear_for: str
    cost: float
    end: tuple[float, float]
    ok: bool
    message: str
    seen: tuple[float, float] | None
    refused: tuple[str, ...]
    prep: tuple[str, ...]
    then: tuple[str, ...] = ()

    def what(self) -> str:
        """'pushed X out of T's lanes (predicted end (x, y))', or 'push of X out of T's lanes failed: why'; after
        'relocated a, b to free the push; ' when it had prep relocations."""
        first = f"relocated {', '.join(self.prep)} to free the push; " if self.prep else ""
        if not self.ok:
            return f"{first}push of {self.object_id} out of {self.clear_for}'s lanes failed: {self.message}"
        return f"{first}pushed {self.object_id} out of {self.clear_for}'s lanes (predicted end ({self.end[0]:.3f}, " \
               f"{self.end[1]:.3f}))"

    def line(self) -> str:
        """One line for the log and the report: `what`, then '; re-planned'."""
        return f"{self.what()}; re-planned"

    def to_dict(self) -> dict[str, Any]:
        """An entry of the result's (and report.json's) `pushes`."""
        return {"object": self.object_id, "clear_for": self.clear_for, "cost": self.cost,
                "predicted_end": list(self.end), "ok": self.ok, "message": self.message,
                "seen_end": list(self.seen) if self.seen is not None else None, "refused": list(self.refused),
                "prep": list(self.prep), "then": list(self.then), "line": self.line()}


def candidates(needs: Sequence[tuple[str, str]], weights: Mapping[str, float], factor: float
               ) -> list[tuple[float, str, str]]:
    """(cost, object pushed, object whose lanes it clears) for every pair "X needs T moved" of `needs`: X clearing
    T's lanes, then T clearing X's; each once, cheapest first (weight x factor; ties keep that order)."""
    out: dict[tuple[str, str], float] = {}
    for x, t in needs:
        for pushed, clear_for in ((x, t), (t, x)):
            out.setdefault((pushed, clear_for), weights[pushed] * factor)
    return sorted(((c, p, f) for (p, f), c in out.items()), key=lambda e: e[0])


@dataclass(frozen=True)
class PushActions:
    """What the node gives for pushes: ask(object, clear_for, removed) -> PushAnswer (the push question),
    execute(object, clear_for, removed) -> (ok, message) (the push executed), factor() -> the push factor of the
    action costs (read when a push is first weighed), max_pushes (pushes executed per goal at most), what_if(moved)
    -> the feasibility oracle asking on the scene with `moved`'s objects at those (x, y) (what would follow a push:
    replan.after_push), progress(line) -> told each candidate as it is weighed ("weighing push 2 of 6: ...")."""

    ask: Callable[[str, str, frozenset[str]], PushAnswer]
    execute: Callable[[str, str, list[str]], tuple[bool, str]]
    factor: Callable[[], float]
    max_pushes: int
    what_if: Callable[[Mapping[str, tuple[float, float]]], Any] | None = None  # the feasibility oracle on the scene
    # with these objects elsewhere (ros_clients.ServiceOracle.what_if): what would follow a push; None: not looked at
    progress: Callable[[str], None] = lambda line: None  # each candidate weighed, one line (the goal's feedback)

    def __post_init__(self) -> None:
        if isinstance(self.max_pushes, bool) or not isinstance(self.max_pushes, int) or self.max_pushes < 0:
            raise ValueError(f"max_pushes must be an integer >= 0, got {self.max_pushes!r}")



After = tuple[tuple[str, ...], float] | str  # what would follow a push: (the pick sequence, its cost) or why none


@dataclass(frozen=True)
class PushProof:
    """What the re-plan gives the pushes: needs(rp) -> the proof's pairs "X needs T moved" of a remaining problem
    with no sequence (replan.blocking_pairs); free(rp) -> the objects the picks alone can take away first, from the
    same proof (replan.free_first); pickable(rp, banned, object, removed) -> whether relocating `object` with
    `removed` gone (beyond rp.gone) is feasible, as the re-plan's oracle answers it (failed options `banned` and the
    free slots counted); follow(rp, banned, pushed, end, prep) -> what would follow the push of `pushed` to its
    predicted `end` after the relocations `prep` (replan.after_push: the A* over the picks on that scene); None:
    not looked at (a push is then chosen by its own cost)."""

    needs: Callable[[Any], Sequence[tuple[str, str]]]
    free: Callable[[Any], Sequence[str]]
    pickable: Callable[[Any, frozenset[Any], str, frozenset[str]], bool]
    follow: Callable[[Any, frozenset[Any], str, tuple[float, float], tuple[str, ...]], After] | None = None


@dataclass(frozen=True)
class PushChoice:
    """The push chosen (`Pusher.choose`): the object, the one whose lanes it clears, its cost (the prep relocations'
    costs + the push's), the predicted end, the objects to relocate first in that order (`prep`, each pickable
    after those before it), and the candidates refused before it (one line each)."""

    object_id: str
    clear_for: str
    cost: float
    end: tuple[float, float]
    prep: tuple[str, ...]
    refused: tuple[str, ...]
    then: tuple[str, ...] = ()  # the pick sequence that would follow it (PushProof.follow), () when not known
    then_cost: float = 0.0  # its cost

    @property
    def total(self) -> float:
        """What the retrieval would cost through this push: its prep relocations, the push, the picks after it."""
        return self.cost + self.then_cost


def pick_order(objects: Sequence[str], pickable: Callable[[str, frozenset[str]], bool]) -> tuple[str, ...]:
    """The objects of `objects` the picks alone take away, one after another, in an order in which each is pickable
    (pickable(o, those before it)): grown to a fixpoint, the first pickable one in the given order next. All of
    them when every one can go."""
    done: list[str] = []
    while len(done) < len(objects):
        nxt = next((o for o in objects if o not in done and pickable(o, frozenset(done))), None)
        if nxt is None:
            break
        done.append(nxt)
    return tuple(done)


class Pusher:
    """Pushes for the closed loop (module doc) through `actions`, from the re-plan's proof (`proof`)."""

    def __init__(self, actions: PushActions, proof: PushProof) -> None:
        self.ask, self.execute, self.factor, self.progress = actions.ask, actions.execute, actions.factor, \
            actions.progress
        self.max_pushes, self.proof = actions.max_pushes, proof
        self.executed = 0
        self._failed: set[tuple[str, str]] = set()  # executed, the object left where it was

    def choose(self, rp: Any, weights: Mapping[str, float], costs: Mapping[str, float], removed: frozenset[str],
               banned: frozenset[Any]) -> PushChoice | str:
        """The push through which the retrieval costs least (`weights`: each object's weight, the push's cost is
        its weight x the push factor; `costs`: each object's pick cost; `removed`: the objects gone), or why there
        is none (one line). Candidates in the order of their push's cost; each asked with `removed` gone, and when
        refused, with the objects the picks alone can take away first gone too (`prep`); then, a feasible one, again
        without each of those, heaviest first, keeping only those the push needs gone. A candidate costs its prep
        relocations' costs + its push's + the pick sequence that would follow it (`PushProof.follow`); one after
        which no pick sequence exists is refused, and chosen (the cheapest such) only when a further push is left
        (`max_pushes`): a second push may open what the first does not. The asking stops when no later candidate
        can cost less than the best found."""
        if self.executed >= self.max_pushes:
            return f"max_pushes ({self.max_pushes}) spent" if self.max_pushes else "pushes are off (max_pushes 0)"
        pairs = self.proof.needs(rp)
        if not pairs:
            return "the proof names no pair \"X needs T moved\" that a push could open"
        try:
            factor = self.factor()
        except ValueError as e:  # relocation_common.config.ParameterError
            return f"no push factor: {e}"
        def pickable(o: str, s: frozenset[str]) -> bool:
            return self.proof.pickable(rp, banned, o, s)
        free: list[tuple[str, ...]] = []  # the objects the picks alone take away first, asked when a push needs it

        def free_first() -> tuple[str, ...]:
            if not free:
                free.append(pick_order(tuple(self.proof.free(rp)), pickable))
            return free[0]
        refused: list[str] = []
        best: PushChoice | None = None  # followed by a pick sequence (or not looked at)
        blind: tuple[PushChoice, str] | None = None  # feasible, followed by none (a further push may open it), why
        weighed = candidates(pairs, weights, factor)
        for i, (cost, pushed, clear_for) in enumerate(weighed, 1):
            if best is not None and cost >= best.total:
                break
            self.progress(f"weighing push {i} of {len(weighed)}: {pushed} out of {clear_for}'s lanes (cost {cost:.2f})")
            got = self._candidate(pushed, clear_for, cost, removed, costs, pickable, free_first)
            if isinstance(got, str):
                refused.append(f"{pushed} out of {clear_for}'s lanes ({got})")
                continue
            choice = replace(got, refused=tuple(refused))
            after = None if self.proof.follow is None else self.proof.follow(rp, banned, pushed, got.end, got.prep)
            if isinstance(after, str):
                refused.append(f"{pushed} out of {clear_for}'s lanes (no pick sequence after it: {after})")
                if blind is None or choice.cost < blind[0].cost:
                    blind = (choice, refused[-1])
                continue
            if after is not None:
                choice = replace(choice, then=after[0], then_cost=after[1])
            if best is None or choice.total < best.total:
                best = choice
        if best is not None:
            return best
        if blind is not None and self.executed + 1 < self.max_pushes:
            return replace(blind[0], refused=tuple(r for r in refused if r != blind[1]))
        return "every push refused: " + "; ".join(refused)

    def _candidate(self, pushed: str, clear_for: str, cost: float, removed: frozenset[str],
                   costs: Mapping[str, float], pickable: Callable[[str, frozenset[str]], bool],
                   free_first: Callable[[], tuple[str, ...]]) -> PushChoice | str:
        """The push of `pushed` out of `clear_for`'s lanes with `removed` gone, else with the prep relocations it
        needs of `free_first()` (`_prepared`), its cost the push's `cost` + theirs; or why not ('failed before', the
        planner's)."""
        if (pushed, clear_for) in self._failed:
            return "failed before"
        answer = self.ask(pushed, clear_for, removed)
        if answer.feasible and answer.end is not None:
            return PushChoice(pushed, clear_for, cost, answer.end, (), ())
        free = tuple(o for o in free_first() if o not in (pushed, clear_for))
        got = self._prepared(pushed, clear_for, removed, free, costs, pickable)
        if isinstance(got, str):
            return f"{answer.message or 'unfeasible'}{got}"
        prep, end = got
        return PushChoice(pushed, clear_for, cost + sum(costs[o] for o in prep), end, prep, ())

    def _prepared(self, pushed: str, clear_for: str, removed: frozenset[str], free: tuple[str, ...],
                  costs: Mapping[str, float], pickable: Callable[[str, frozenset[str]], bool]
                  ) -> tuple[tuple[str, ...], tuple[float, float]] | str:
        """(the objects of `free` the push needs gone, in an order in which each is pickable; its predicted end), or
        what the push said with all of `free` gone ('; with a, b gone: why'; '' when there is none to remove)."""
        if not free:
            return ""
        answer = self.ask(pushed, clear_for, removed | frozenset(free))
        if not (answer.feasible and answer.end is not None):
            return f"; with {', '.join(free)} gone: {answer.message or 'unfeasible'}"
        prep, end = free, answer.end
        for o in sorted(free, key=lambda o: (-costs[o], o)):  # heaviest first: the costliest relocation spared first
            fewer = tuple(p for p in prep if p != o)
            if len(pick_order(fewer, pickable)) < len(fewer):
                continue
            again = self.ask(pushed, clear_for, removed | frozenset(fewer))
            if again.feasible and again.end is not None:
                prep, end = fewer, again.end
        return pick_order(prep, pickable), end

    def run(self, choice: PushChoice, removed: frozenset[str]) -> PushRecord:
        """Execute the push `choice` with `removed` gone (its prep relocations done): its record (`seen` is the
        caller's, from the scene after it)."""
        self.executed += 1
        ok, message = self.execute(choice.object_id, choice.clear_for, sorted(removed))
        return PushRecord(choice.object_id, choice.clear_for, choice.cost, choice.end, ok, message, None,
                          choice.refused, choice.prep, choice.then)

    def failed(self, pushed: str, clear_for: str) -> None:
        """A push executed without effect (the object where it was, failed or not): not asked again in this goal."""
        self._failed.add((pushed, clear_for))
