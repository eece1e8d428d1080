"""Pushes out of a blocking cycle, ROS-free: what the closed loop does when the A* proves that no pick sequence
frees the target (docs/closed_loop.md, "Pushes").

The proof's blocking cycle ("X needs T moved": every lane of X needs T gone and the other way round,
exact.blocking_needs) is what a non-prehensile push can open: X slid out of T's grasp lanes, or T out of X's. For
each pair the motion planner is asked for a push of X clearing T's lanes, then of T clearing X's; all the
candidates are asked cheapest first, a push of an object costing its weight times the push factor (the paper's cost
of an action, Eq. 8, with the factor of the action kind; config/task_planner.yaml). The first feasible push is
executed (RelocateObject, action "push"); the closed loop then waits for the next scene and re-plans from what the
world shows (the pushed object where it really ended), as after a relocation. At most `max_pushes` pushes are
executed per goal; a push that left the object where it was (failed, or done without effect) is not asked again.

Nothing here talks to ROS: the node supplies `ask` (ros_clients.ServiceOracle.push: PlanFeasibility, action
"push") and `execute` (ros_clients.Relocator.push: RelocateObject, action "push").
"""
from __future__ import annotations

from dataclasses import dataclass
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
    """One push executed: the object, the one whose lanes it clears, its cost (weight x push factor), the predicted
    end, the motion planner's outcome, where the next scene showed the object (None: not seen on the top shelf),
    and the candidates refused before it (one line each)."""

    object_id: str
    clear_for: str
    cost: float
    end: tuple[float, float]
    ok: bool
    message: str
    seen: tuple[float, float] | None
    refused: tuple[str, ...]

    def what(self) -> str:
        """'pushed X out of T's lanes (predicted end (x, y))', or 'push of X out of T's lanes failed: why'."""
        if not self.ok:
            return f"push of {self.object_id} out of {self.clear_for}'s lanes failed: {self.message}"
        return f"pushed {self.object_id} out of {self.clear_for}'s lanes (predicted end ({self.end[0]:.3f}, " \
               f"{self.end[1]:.3f}))"

    def line(self) -> str:
        """One line for the log and the report: `what`, then '; re-planned'."""
        return f"{self.what()}; re-planned"

    def to_dict(self) -> dict[str, Any]:
        """An entry of the result's (and report.json's) `pushes`."""
        return {"object": self.object_id, "clear_for": self.clear_for, "cost": self.cost,
                "predicted_end": list(self.end), "ok": self.ok, "message": self.message,
                "seen_end": list(self.seen) if self.seen is not None else None, "refused": list(self.refused),
                "line": self.line()}


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
    action costs (read when a push is first weighed), max_pushes (pushes executed per goal at most)."""

    ask: Callable[[str, str, frozenset[str]], PushAnswer]
    execute: Callable[[str, str, list[str]], tuple[bool, str]]
    factor: Callable[[], float]
    max_pushes: int

    def __post_init__(self) -> None:
        if isinstance(self.max_pushes, bool) or not isinstance(self.max_pushes, int) or self.max_pushes < 0:
            raise ValueError(f"max_pushes must be an integer >= 0, got {self.max_pushes!r}")


class Pusher:
    """Pushes for the closed loop (module doc) through `actions`; needs(rp) -> the proof's pairs "X needs T moved"
    of a remaining problem with no sequence (replan.blocking_pairs)."""

    def __init__(self, actions: PushActions, needs: Callable[[Any], Sequence[tuple[str, str]]]) -> None:
        self.ask, self.execute, self.factor = actions.ask, actions.execute, actions.factor
        self.max_pushes, self.needs = actions.max_pushes, needs
        self.executed = 0
        self._failed: set[tuple[str, str]] = set()  # executed, the object left where it was

    def push(self, rp: Any, weights: Mapping[str, float], removed: frozenset[str]) -> PushRecord | str:
        """Ask the candidates of the remaining problem `rp` (its pairs from `needs`; `weights`: each object's
        weight) cheapest first with `removed` gone, and execute the first feasible one: its record (`seen` is the
        caller's, from the scene after it), or why no push was executed (one line)."""
        if self.executed >= self.max_pushes:
            return f"max_pushes ({self.max_pushes}) spent" if self.max_pushes else "pushes are off (max_pushes 0)"
        pairs = self.needs(rp)
        if not pairs:
            return "the proof names no pair \"X needs T moved\" that a push could open"
        try:
            factor = self.factor()
        except ValueError as e:  # relocation_common.config.ParameterError
            return f"no push factor: {e}"
        refused = []
        for cost, pushed, clear_for in candidates(pairs, weights, factor):
            if (pushed, clear_for) in self._failed:
                refused.append(f"{pushed} out of {clear_for}'s lanes (failed before)")
                continue
            answer = self.ask(pushed, clear_for, removed)
            if not (answer.feasible and answer.end is not None):
                refused.append(f"{pushed} out of {clear_for}'s lanes ({answer.message or 'unfeasible'})")
                continue
            self.executed += 1
            ok, message = self.execute(pushed, clear_for, sorted(removed))
            return PushRecord(pushed, clear_for, cost, answer.end, ok, message, None, tuple(refused))
        return "every push refused: " + "; ".join(refused)

    def failed(self, pushed: str, clear_for: str) -> None:
        """A push executed without effect (the object where it was, failed or not): not asked again in this goal."""
        self._failed.add((pushed, clear_for))
