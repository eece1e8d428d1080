"""A goal that starts where an earlier one stopped, ROS-free (docs/reliability.md, "A node that dies").

A task planner respawned during an execution gets its goal again while the world is no longer the scenario's: the
bottles relocated before its death stand on the bottom shelf (the motion planner placed them: its ~/relocated says
which, in slot order), the relocation that was in flight ended as the motion planner left it. `start_point` says what
the new goal starts from: the retrieval problem of the top shelf as it is now (`world.remaining_problem`, the
closed loop's own rule: a bottle counts as relocated only when the scene does not show it on the top shelf), the
relocations done before it (the executor sends them as removed, so the motion planner's slot numbering goes on), or
that the target was already retrieved (seen on the bottom shelf; or, with a camera that does not see it, placed
there by the motion planner and gone from the top shelf: the closed loop's rule after a relocation). Nothing
placed by the motion planner (or every bottle it placed back on the top shelf) is a fresh start (None): the goal
trains on the scene as always.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping, Sequence

from qtree_task_planner.executive.world import Scene, Tolerances, board_of, configured, remaining_problem
from qtree_task_planner.oracles import Lanes
from qtree_task_planner.problem import ActionCosts, RelocationProblem
from relocation_common.feasibility import (
    FeasibilityAnswer,
    OnAnswer,
    Query,
    ask_many,
    certify_many,
    in_flight,
)
from relocation_common.scenario import Scenario


@dataclass(frozen=True)
class StartPoint:
    """Where a goal starts when the world changed before it: the problem left on the top shelf (None: `retrieved`,
    or no problem, `line` says why), the relocations done before it (slot order), one line for the log."""

    problem: RelocationProblem | None
    before: tuple[str, ...]
    retrieved: bool
    line: str


def relocated_before(scenario: Scenario, scene: Scene, placed: Mapping[str, int],
                     tol: Tolerances | None = None) -> tuple[str, ...]:
    """The bottles the motion planner placed on the bottom shelf (`placed`: id -> slot, its ~/relocated) that the
    scene does not show on the top shelf, in slot order (a placed bottle seen back on the top shelf is not
    relocated: the closed loop's rule)."""
    tol = tol or configured()
    return tuple(o for o, _ in sorted(placed.items(), key=lambda kv: (kv[1], kv[0]))
                 if o not in scene or board_of(scene[o], scenario, tol) != "top")


def start_point(scenario: Scenario, scene: Scene, placed: Mapping[str, int], action_cost: ActionCosts | None,
                tol: Tolerances | None = None) -> StartPoint | None:
    """What a goal starts from (module doc); None when the motion planner placed no bottle that the scene does not
    show on the top shelf (a fresh start)."""
    tol = tol or configured()
    before = relocated_before(scenario, scene, placed, tol)
    if not before:  # the scene as given (a bottle off the top shelf that nobody placed: the first plan's business)
        return None
    off = sorted(o for o, seen in scene.items() if board_of(seen, scenario, tol) != "top")
    rp = remaining_problem(scenario, scene, before, tol, action_cost)
    done = f"relocated before this goal: {', '.join(before)} (the motion planner placed them; not on the top shelf)"
    elsewhere = f"; off the top shelf: {', '.join(off)}" if off else ""
    if rp.problem is None:
        return StartPoint(None, before, rp.target_retrieved, f"the world changed before this goal: {done}{elsewhere}; "
                          f"{rp.reason}")
    return StartPoint(rp.problem, before, False, f"the world changed before this goal: {done}{elsewhere}; the "
                      f"retrieval re-planned from the scene as it is now: {len(rp.problem.obstacles)} obstacle(s) on "
                      f"the top shelf ({', '.join(rp.problem.obstacles) or 'none'}), target {rp.problem.target}")


class WithGone:
    """The feasibility oracle of a goal that starts after relocations (`gone`: StartPoint.before): every question
    to the wrapped oracle (the planners) is asked with those bottles removed too, as the closed loop's re-plans ask
    with RemainingProblem.gone (the motion planner keeps a bottle it placed as an obstacle of a question that does
    not name it: the resumed goal's first plan took o1 and o5 for T, whose lane o4 had left). The questions and
    answers the cache above it keeps are the problem's own (without `gone`)."""

    def __init__(self, oracle: Any, gone: frozenset[str]) -> None:
        self.oracle, self.gone = oracle, gone

    @property
    def in_flight(self) -> int:
        """The wrapped oracle's (feasibility.in_flight)."""
        return in_flight(self.oracle)

    def feasibility(self, object_id: str, removed: frozenset[str]) -> FeasibilityAnswer:
        """Eq. 11 for (object_id, removed | gone)."""
        return self.oracle.feasibility(object_id, frozenset(removed) | self.gone)

    def certify(self, object_id: str, removed: frozenset[str]) -> FeasibilityAnswer:
        """The certification of (object_id, removed | gone) (a final answer from an oracle that does not certify)."""
        return certify_many(self.oracle, [(object_id, frozenset(removed) | self.gone)])[0]

    def lane_blockers(self, removed: frozenset[str]) -> Lanes | None:
        """The lane blockers with removed | gone gone (None from an oracle without them)."""
        ask = getattr(self.oracle, "lane_blockers", None)
        return None if ask is None else ask(frozenset(removed) | self.gone)

    def feasibility_many(self, queries: Sequence[Query], on_answer: OnAnswer | None = None) -> list[FeasibilityAnswer]:
        """Every answer (feasibility.ask_many), asked with `gone` removed too."""
        return ask_many(self.oracle, *self._mapped(queries, on_answer))

    def certify_many(self, queries: Sequence[Query], on_answer: OnAnswer | None = None) -> list[FeasibilityAnswer]:
        """Every certification (feasibility.certify_many), asked with `gone` removed too."""
        return certify_many(self.oracle, *self._mapped(queries, on_answer))

    def _mapped(self, queries: Sequence[Query], on_answer: OnAnswer | None) -> tuple[list[Query], OnAnswer | None]:
        """The queries with `gone` removed too, and on_answer called with the query as it was asked of us."""
        full = [(o, frozenset(r) | self.gone) for o, r in queries]
        back = dict(zip(full, queries))
        return full, None if on_answer is None else (lambda q, a: on_answer(back[q], a))
