"""Closed-loop retrieval, ROS-free: check the world after every relocation, re-plan when it differs, recover.

The paper executes the learned sequence open-loop (Sect. 5). Here, after each relocation a scene perceived after
it ended is checked against the plan (`verify_relocation`: the moved bottle on the bottom shelf at its slot, every
other bottle where it was, the target present). When the world differs, when a new object is seen (one present now
and absent before: a hidden object revealed behind the relocated one, or an object the scenario does not list seen
for the first time; `new_objects`), or a relocation failed (the motion planner's recovery has brought the arm home
and the bottle back), the remaining retrieval problem is built from
the perceived scene (`remaining_problem`: relocated bottles out, moved ones at their new poses, newly seen ones in)
and solved again (an injected re-planner: `qtree_task_planner.executive.replan` over the exact blocker A*, Eq. 8),
with the
failed option marked so that it is not proposed again. The executor gives up only when no sequence remains, with
the reason in one line. The free slots of the bottom shelf bound every sequence (`check_capacity`): a sequence
relocating more objects than there are free slots is never executed.

The scene, its tolerances, the check and the remaining problem are `executive.world`'s.

A relocation whose outcome the motion planner could not see (no scene after its motion: its message ends with
"outcome unknown", relocation_common.feasibility.OUTCOME_UNKNOWN; perception restarting, say) is neither a success
nor a failure of the option: the scene perceived after it is checked as after any relocation, and the check
decides. A relocation the motion planner's restart interrupted is a failure of time (TRANSIENT): re-planned, and
its option tried again.

Nothing here talks to ROS: the node supplies `relocate(object_id, removed) -> (ok, message)` (the RelocateObject
action), `perceive() -> scene` (a scene perceived after the call) and `replan(problem, banned)`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any, Callable, Iterable, Iterator, Sequence

from qtree_task_planner.executive.push import Pusher, PushRecord
from qtree_task_planner.executive.world import (
    Difference,
    RemainingProblem,
    Scene,
    SeenObject,
    Tolerances,
    Verification,
    board_of,
    check_capacity,
    configured,
    new_objects,
    remaining_problem,
    support_of,
    verify_relocation,
)
from qtree_task_planner.problem import ActionCosts, RelocationProblem
from relocation_common.feasibility import OUTCOME_UNKNOWN, destination_slot
from relocation_common.scenario import Scenario


# ------------------------------------------------------------------------------------------------ the executor
@dataclass(frozen=True)
class Option:
    """A failed option, not to be proposed again: relocating `object_id` with exactly `removed` gone (None: with
    any set, after the object failed `max_attempts` times)."""

    object_id: str
    removed: frozenset[str] | None = None

    def bans(self, object_id: str, removed: frozenset[str]) -> bool:
        """True when this option forbids relocating object_id with `removed` gone."""
        return object_id == self.object_id and (self.removed is None or self.removed == frozenset(removed))


ReplanAnswer = tuple[tuple[str, ...], float, int] | tuple[tuple[str, ...], float, int, str]  # (sequence, weight
# (Eq. 8), planner calls it cost[, a note: how the Q-Tree retrained on the remaining problem did, replan.relearn])
Replanner = Callable[[RemainingProblem, frozenset[Option]], "ReplanAnswer | str"]


@dataclass(frozen=True)
class ReplanRecord:
    """One re-plan: why, and what came of it (the sequence and its weight, the planner calls it cost, or why none)."""

    reason: str
    sequence: tuple[str, ...] | None
    weight: float | None
    calls: int
    failure: str = ""
    note: str = ""  # the retrained Q-Tree's outcome (replan.relearn), when asked for

    def to_dict(self) -> dict[str, Any]:
        """An entry of the result's (and report.json's) `replans`."""
        d: dict[str, Any] = {"reason": self.reason, "sequence": list(self.sequence) if self.sequence else None,
                             "weight": self.weight, "calls": self.calls}
        return {**d, **{k: v for k, v in (("failure", self.failure), ("note", self.note)) if v}}

    def line(self) -> str:
        """One line for the feedback: why, and the new sequence with its weight (or why there is none)."""
        got = f"{' '.join(self.sequence)} (weight {self.weight:.2f})" if self.sequence and self.weight is not None \
            else self.failure
        return f"re-plan: {self.reason} -> {got}" + (f" ({self.note})" if self.note else "")


@dataclass(frozen=True)
class Step:
    """One relocation and its check: the object, the removed list it was sent with, the slot planned, the motion
    planner's outcome and the verification (None when the relocation failed)."""

    index: int
    object_id: str
    removed: tuple[str, ...]
    slot: int
    ok: bool
    message: str
    verification: Verification | None

    def to_dict(self) -> dict[str, Any]:
        """For the feedback and the result."""
        return {"index": self.index, "object": self.object_id, "removed": list(self.removed), "slot": self.slot,
                "ok": self.ok, "message": self.message,
                "verification": self.verification.to_dict() if self.verification else None}

    def line(self) -> str:
        """One line for the feedback: the check after this relocation, or why it failed."""
        what = self.verification.summary() if self.verification else f"relocating {self.object_id} failed: " \
            f"{self.message}"
        return f"check {self.index + 1}: {what}"


@dataclass
class ExecutionResult:
    """The outcome: success only when the target was seen on the bottom shelf (or, with a camera that does not see
    it, relocated and gone from the top shelf); one-line message; the steps
    (relocations tried), the re-plans, the objects relocated (verified, in order) and the new objects seen on the
    way, one line each ('new object u3 (box, 0.31 kg est.) at (0.84, 0.12) after relocating o2: re-planned')."""

    success: bool = False
    message: str = ""
    relocated: list[str] = field(default_factory=list)
    steps: list[Step] = field(default_factory=list)
    replans: list[ReplanRecord] = field(default_factory=list)
    unverified: list[str] = field(default_factory=list)  # relocated, but no scene showed where they stand
    new_objects: list[str] = field(default_factory=list)
    pushes: list[PushRecord] = field(default_factory=list)  # executed (executive.push)

    def to_dict(self) -> dict[str, Any]:
        """For the result and report.json (`replans`, `unverified`, `new_objects`, `pushes`)."""
        return {"success": self.success, "message": self.message, "relocated": list(self.relocated),
                "steps": [s.to_dict() for s in self.steps], "replans": [r.to_dict() for r in self.replans],
                "unverified": list(self.unverified), "new_objects": list(self.new_objects),
                "pushes": [p.to_dict() for p in self.pushes]}


class GiveUp(Exception):
    """The executor stops: no sequence remains (or cancelled, or the re-plan budget is spent); the one-line reason."""


class ClosedLoopExecutor:
    """Executes a relocation sequence, checking the world after each relocation and re-planning (module doc).

    relocate(object_id, removed) -> (ok, message): one relocation (removed: the verified relocations, in order;
    the motion planner's recovery brings the arm home and the bottle back on a failure). perceive() -> scene: a
    scene perceived after the call. replan(problem, banned) -> (sequence, weight, calls) or the reason there is
    none: a sequence for the RemainingProblem that uses no banned Option and at most len(problem.free_slots)
    slots. slot_of(problem) -> the slot index the next relocation goes to (default: the motion planner's rule,
    relocation_common.feasibility.destination_slot: slot len(removed), the one its certified answer planned the
    carry to, when it is free, else the first free one). on_step(step) after each relocation and
    on_replan(record) after each re-plan (feedback). action_cost: the remaining problems' obstacles costed by the
    pick their poses take (remaining_problem), else their weights.
    bottom_seen False: perception does not see the bottom shelf (verify_relocation); a relocated bottle that is
    not seen counts as relocated. perceive() raising ValueError, TimeoutError or RuntimeError (no scene) ends the
    run with its message. pusher (executive.push.Pusher; None: no pushes): when a re-plan proves that no sequence
    remains, the cheapest feasible push out of the proof's blocking cycle is executed (after the relocations of the
    objects it needs gone first, each verified), then the next scene is perceived and the rest re-planned from it
    (on_push(record) after each); an empty `sequence` to `run` (the first
    plan found none) starts with that re-plan.
    """

    def __init__(self, scenario: Scenario, relocate: Callable[[str, list[str]], tuple[bool, str]],
                 perceive: Callable[[], Scene], replan: Replanner, *, tolerances: Tolerances | None = None,
                 max_replans: int = 20, max_attempts: int = 2, cancelled: Callable[[], bool] = lambda: False,
                 on_step: Callable[[Step], None] = lambda step: None,
                 on_replan: Callable[[ReplanRecord], None] = lambda record: None,
                 slot_of: Callable[[RemainingProblem], int] | None = None, bottom_seen: bool = True,
                 on_progress: Callable[[ExecutionResult], None] = lambda result: None,
                 action_cost: ActionCosts | None = None, pusher: Pusher | None = None,
                 on_push: Callable[[PushRecord], None] = lambda record: None) -> None:
        if max_replans < 0 or max_attempts < 1:
            raise ValueError(f"need max_replans >= 0 and max_attempts >= 1, got {max_replans}, {max_attempts}")
        self.scenario, self.relocate, self.perceive, self.replan = scenario, relocate, perceive, replan
        self.tol, self.max_replans, self.max_attempts = tolerances or configured(), max_replans, max_attempts
        self.cancelled, self.on_step, self.on_replan = cancelled, on_step, on_replan
        self.slot_of = slot_of
        self.bottom_seen = bottom_seen
        self.on_progress = on_progress
        self.action_cost = action_cost
        self.pusher, self.on_push = pusher, on_push

    def run(self, sequence: Iterable[str], scene: Scene | None = None, relocated: Iterable[str] = ()
            ) -> ExecutionResult:
        """Relocate `sequence` (obstacles, then the target) starting from `scene` (default: perceive()); the
        result says whether the target reached the bottom shelf and, if not, why in one line. `relocated`: the
        relocations done before this run (a goal sent again to a respawned task planner: executive.resume), kept
        as relocated while the scene does not show them on the top shelf, and sent as removed."""
        out = ExecutionResult(relocated=list(relocated))
        self._banned: set[Option] = set()
        self._failures: dict[str, int] = {}
        self._retried: dict[tuple[str, frozenset[str]], int] = {}  # failures of time per option
        self._top: set[str] = set()  # every object seen resting on the top shelf during the run
        try:
            self._run(list(sequence), dict(scene if scene is not None else self._perceive("at the start")), out)
        except _Done:
            pass
        except GiveUp as e:
            out.success, out.message = False, str(e)
        return out

    def _run(self, seq: list[str], scene: dict[str, SeenObject], out: ExecutionResult) -> None:
        rp = self._problem(scene, out)
        problem = rp.problem
        assert problem is not None
        why = check_capacity(seq, len(rp.free_slots))
        if not seq:
            seq, scene, rp = self._replan(NONE_AT_START, scene, rp, out)
        elif why:
            seq, scene, rp = self._replan(f"capacity: {why}", scene, rp, out)
        elif _invalid(seq, problem):
            seq, scene, rp = self._replan(f"the sequence does not fit the scene: {_invalid(seq, problem)}", scene, rp,
                                          out)
        while True:
            scene, rp, why = self._relocate(seq[0], scene, rp, out)
            if why is None:
                seq = seq[1:]
                continue
            seq, scene, rp = self._replan(why, scene, rp, out)

    def _relocate(self, obj: str, scene: dict[str, SeenObject], rp: RemainingProblem, out: ExecutionResult
                  ) -> tuple[dict[str, SeenObject], RemainingProblem, str | None]:
        """Relocate `obj`, perceive and check the scene after it: (that scene, its remaining problem, None when the
        world is as planned, else the reason to re-plan, one line). A failed option is marked (`_fail`)."""
        if self.cancelled():
            raise GiveUp(f"cancelled after relocating {out.relocated}")
        if not rp.free_slots:
            raise GiveUp(f"no free slot on the bottom shelf for {obj}")
        # the relocated bottles, then those seen off the top shelf otherwise (dropped to the floor): the motion
        # planner keeps an unseen bottle at its last pose, and the re-plan's answers had them gone (rp.gone)
        removed, gone = tuple(out.relocated) + tuple(sorted(o for o in rp.gone if o in scene and o in self._top
                                                            and o not in out.relocated)), rp.gone
        slot = self.slot_of(rp) if self.slot_of else destination_slot(len(removed), rp.free_slots)
        ok, message = self.relocate(obj, list(removed))
        after = self._perceive(f"after relocating {obj}")
        check = None
        if ok or message.endswith(OUTCOME_UNKNOWN):  # unknown: the motion planner saw no scene, we look
            x, y = self.scenario.slots[slot]
            check = verify_relocation(obj, (x, y, self.scenario.shelf.bottom_z), scene, after, self.tol,
                                      self.bottom_seen)
            check = replace(check, new=self._on_top(check.new, after))
            if not ok and check.ok:
                ok, message = True, f"{message}; the scene after it shows it done"
        stayed, new = _stayed(obj, scene, after, self.tol), self._on_top(new_objects(scene, after, obj), after)
        if ok and check is not None and check.unseen_place:
            out.unverified.append(obj)
        step = Step(len(out.steps), obj, removed, slot, ok, message, check)
        out.steps.append(step)
        self.on_step(step)
        landed = after.get(obj)
        if (board_of(landed, self.scenario, self.tol) == "bottom" if landed is not None else
                ok and not self.bottom_seen):
            out.relocated.append(obj)
        self.on_progress(out)
        rp = self._problem(after, out)
        if check is not None and check.ok and not new:
            return after, rp, None
        out.new_objects += [f"{d.line} after relocating {obj}: re-planned" for d in new]
        if not ok:
            if stayed:  # the option failed; else the bottle was dropped or knocked: the re-plan asks about its
                self._fail(obj, gone, message)  # new pose (a bottle on the bottom shelf is relocated, above)
            return after, rp, f"relocating {obj} failed: {message}"
        assert check is not None  # a new object is no fault of the relocation: the rest is re-planned
        return after, rp, (f"the world differs after relocating {obj}: {check.summary()}" if not check.ok
                           else "; ".join(d.line for d in new))

    def _on_top(self, new: tuple[Difference, ...], scene: Scene) -> tuple[Difference, ...]:
        """The new objects that rest on the top shelf: an object first seen elsewhere (a relocated bottle the
        camera glimpses on the bottom shelf, as perception names it anew) is no obstacle and no re-plan."""
        return tuple(d for d in new if board_of(scene[d.object_id], self.scenario, self.tol) == "top")

    def _perceive(self, when: str) -> dict[str, SeenObject]:
        try:
            return dict(self.perceive())
        except (ValueError, TimeoutError, RuntimeError) as e:
            raise GiveUp(f"no scene {when}: {e}") from None

    def _problem(self, scene: Scene, out: ExecutionResult) -> RemainingProblem:
        """The remaining problem; stops the run when the target is on the bottom shelf (success) or out of reach.
        A relocated bottle seen back on the top shelf is no longer relocated (the motion planner must see it)."""
        out.relocated[:] = [o for o in out.relocated
                            if o not in scene or board_of(scene[o], self.scenario, self.tol) != "top"]
        rp = remaining_problem(self.scenario, scene, out.relocated, self.tol, self.action_cost)
        self._top |= {b.id for b in rp.bottles}  # an object off the top shelf is sent as removed only if it was on it
        # ... in the feasibility questions too: an unlisted object never seen on the top shelf (perception's glimpse
        # of the carried bottle or the hand, named anew) is one the motion planner never had, and it refuses the
        # question ("unknown object id 'u2'"), which ended the run; and an unlisted object no longer in the scene
        # (perception named it anew: the motion planner dropped it, scene_update's "superseded") is not gone either:
        # the planner has dropped it or keeps it at its last pose, an obstacle (sent removed, it asked "unknown
        # object id 'u1'" on world/crowd_20)
        rp = replace(rp, gone=frozenset(o for o in rp.gone if self._sent_as_gone(o, scene, out)))
        if rp.target_retrieved:
            out.success = True
            k, n = len(out.pushes), len(out.replans)
            out.message = (f"target {self.scenario.target_id} retrieved after {len(out.relocated) - 1} relocations"
                           + (f", {k} push{'es' * (k != 1)}" if k else "")
                           + (f" and {n} re-plan{'s' * (n != 1)}" if n else "")
                           + (" (it left the top shelf; its place on the bottom shelf was not seen: unverified)"
                              if self.scenario.target_id in out.unverified else ""))
            raise _Done
        if rp.problem is None:
            raise GiveUp(rp.reason)
        return rp

    def _sent_as_gone(self, oid: str, scene: Scene, out: ExecutionResult) -> bool:
        """Whether an object off the top shelf goes to the motion planner as removed: a listed one always; an
        unlisted one once seen on the top shelf and now relocated or seen elsewhere (not one perception renamed)."""
        listed = oid in self.scenario.ids and self.scenario.world_object(oid).listed
        return listed or oid in self._top and (oid in scene or oid in out.relocated)

    def _fail(self, obj: str, removed: frozenset[str], message: str = "") -> None:
        """Mark the failed option; an object failing max_attempts times is banned with any set. A failure of time
        (TRANSIENT: the planner's safety net, the follower under load) says nothing about the option: it is tried
        again, up to TRANSIENT_TRIES times in all, before it is marked."""
        if any(w in message for w in TRANSIENT):
            self._retried[(obj, removed)] = tries = self._retried.get((obj, removed), 0) + 1
            if tries < TRANSIENT_TRIES:
                return
        self._failures[obj] = self._failures.get(obj, 0) + 1
        self._banned.add(Option(obj, None if self._failures[obj] >= self.max_attempts else removed))

    def _replan(self, reason: str, scene: dict[str, SeenObject], rp: RemainingProblem, out: ExecutionResult
                ) -> tuple[list[str], dict[str, SeenObject], RemainingProblem]:
        """(a new sequence for `rp`, the scene and the remaining problem it is for), or GiveUp with the reason in
        one line. When no sequence remains, a push out of the proof's blocking cycle (`pusher`), then the scene
        after it re-planned, as often as pushes are executed."""
        while True:
            answer = self._solve(reason, rp, out)
            if not isinstance(answer, str):
                return answer, scene, rp
            pushed = self._push(scene, rp, out) if self.pusher is not None else None
            if pushed is None or isinstance(pushed, str):
                tried = self._tried(out, pushed)
                if not out.steps and not out.pushes and reason == NONE_AT_START:
                    raise GiveUp(f"the target cannot be retrieved: {answer}{tried}")
                raise GiveUp(f"no sequence remains: {answer} (re-planned because {reason}){tried}")
            scene, rp, reason = pushed

    def _push(self, scene: dict[str, SeenObject], rp: RemainingProblem, out: ExecutionResult
              ) -> tuple[dict[str, SeenObject], RemainingProblem, str] | str:
        """The cheapest feasible push (executive.push.Pusher), its prep relocations done (each verified; when one
        fails or the world differs, (the scene after it, its problem, why) to re-plan from), then the push executed,
        and (the scene after it, its remaining problem, the push's line as the next re-plan's reason); or why no push
        was executed."""
        assert self.pusher is not None and rp.problem is not None
        if self.cancelled():
            raise GiveUp(f"cancelled after relocating {out.relocated}")
        choice = self.pusher.choose(rp, {b.id: b.weight for b in rp.bottles}, rp.problem.costs, rp.gone,
                                    frozenset(self._banned))
        if isinstance(choice, str):
            return choice
        for i, obj in enumerate(choice.prep):
            scene, rp, why = self._relocate(obj, scene, rp, out)
            if why is not None:
                return scene, rp, f"{why} (relocating {', '.join(choice.prep[:i + 1])} to free the push of " \
                    f"{choice.object_id} out of {choice.clear_for}'s lanes)"
        if self.cancelled():
            raise GiveUp(f"cancelled after relocating {out.relocated}")
        got = self.pusher.run(choice, rp.gone)
        after = self._perceive(f"after pushing {got.object_id}")
        now = after.get(got.object_id)
        seen = (now.x, now.y) if now is not None and board_of(now, self.scenario, self.tol) == "top" else None
        got = replace(got, seen=seen)
        if _stayed(got.object_id, scene, after, self.tol):  # failed, or "done" and nothing moved: not asked again
            self.pusher.failed(got.object_id, got.clear_for)
        out.pushes.append(got)
        self.on_push(got)
        self.on_progress(out)
        return after, self._problem(after, out), got.what()

    @staticmethod
    def _tried(out: ExecutionResult, why: str | None) -> str:
        """What the "no sequence" end adds about pushes: those executed, and why no further one ("" without a
        pusher)."""
        if why is None:
            return ""
        done = f"; pushes executed: {'; '.join(p.line() for p in out.pushes)}" if out.pushes else ""
        return f"{done}; no {'further ' * bool(out.pushes)}push: {why}"

    def _solve(self, reason: str, rp: RemainingProblem, out: ExecutionResult) -> list[str] | str:
        """A new sequence for `rp` (recorded in out.replans), the proof's one-line reason there is none, or GiveUp
        (the re-plan budget, a sequence that cannot be executed)."""
        if len(out.replans) >= self.max_replans:
            raise GiveUp(f"gave up after {len(out.replans)} re-plans (max_replans); last: {reason}")
        # a bottle tipped over is asked about like any other (no ban of its own): the motion planner answers its
        # grasp from above where the headroom allows, else "no grasp: " with the headroom it needs
        answer = self.replan(rp, frozenset(self._banned))
        again = {b for b in self._banned if self._failures.get(b.object_id, 0) < self.max_attempts}
        if isinstance(answer, str) and again:  # no sequence avoids them: give up only when none remains at all
            retry = self.replan(rp, frozenset(self._banned - again))
            if not isinstance(retry, str):
                self._banned -= again
                answer, reason = retry, f"{reason}; no sequence avoids the failed option" + \
                    f"{'s' * (len(again) != 1)} of {', '.join(sorted({b.object_id for b in again}))}: tried again"
        if isinstance(answer, str):
            out.replans.append(ReplanRecord(reason, None, None, 0, answer))
            self.on_replan(out.replans[-1])
            self.on_progress(out)
            return answer
        seq, weight, calls, *note = answer
        problem = rp.problem
        assert problem is not None
        bad = (check_capacity(seq, len(rp.free_slots)) or _invalid(seq, problem)
               or next((f"it relocates {o} again, a failed option" for o, s in _options(seq, rp.gone)
                        if any(b.bans(o, s) for b in self._banned)), None))
        out.replans.append(ReplanRecord(reason, tuple(seq), weight, calls, f"refused: {bad}" if bad else "",
                                        note[0] if note else ""))
        self.on_replan(out.replans[-1])
        self.on_progress(out)
        if bad:
            raise GiveUp(f"the re-planner proposed a sequence that cannot be executed: {bad}")
        return list(seq)


NONE_AT_START = "the first plan found no sequence"  # the reason of the re-plan `run` starts with for an empty sequence
TRANSIENT = ("safety net", "did not settle", "tracking error", "stalled at", "no joint state from the driver",
             "restarted during this relocation")  # the motion planner's words for a relocation that ran out of time
# (budget.SafetyNetTimeout, execution.TrajectoryFollower, a driver starved under load) or that its restart
# interrupted (service.MotionPlannerService._resumed_outcome), not one that cannot be done
TRANSIENT_TRIES = 3  # relocations of one option that ran out of time before it is marked (a demo under load: twice)


class _Done(GiveUp):
    """The target is on the bottom shelf."""


def _stayed(obj: str, before: Scene, after: Scene, tol: Tolerances) -> bool:
    """True when `obj` rests where it rested before a failed relocation (within tol.still, standing or lying as it
    was): the failure is the option's (no grasp, no path) and the option is marked; a bottle moved or tipped by the
    attempt is not."""
    was, now = before.get(obj), after.get(obj)
    return was is not None and now is not None and (now.tilt > tol.tilt) == (was.tilt > tol.tilt) and \
        math.hypot(now.x - was.x, now.y - was.y) <= tol.still and abs(support_of(now) - support_of(was)) <= tol.board


def _options(seq: Iterable[str], gone: frozenset[str]) -> Iterator[tuple[str, frozenset[str]]]:
    """(object, removed set) of each relocation of `seq` after `gone`."""
    removed = set(gone)
    for o in seq:
        yield o, frozenset(removed)
        removed.add(o)


def _invalid(seq: Sequence[str], problem: RelocationProblem) -> str | None:
    """Why `seq` is not a retrieval sequence of `problem` (obstacles of it, once each, then its target), or None."""
    if not seq or seq[-1] != problem.target:
        return f"it does not end with the target {problem.target}"
    body = seq[:-1]
    unknown = [o for o in body if o not in problem.weights]
    if unknown or len(set(body)) != len(body):
        return f"it names {', '.join(unknown)} not on the top shelf" if unknown else "it relocates an object twice"
    return None
