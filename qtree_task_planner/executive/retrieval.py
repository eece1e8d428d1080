"""The task planner's job, ROS-free: the exact optimum, then Q-Tree training (Sect. 4.2), then the relocations.

The exact optimum comes from the blocker A* (astar.py: the planner's lane blockers bound the search, the optimum
still proven, Eq. 8) in a handful of planner calls; exact.py's uniform-cost search stays the tested reference.

The node supplies the oracle (its feasibility service behind a CachedOracle), how to get through planner outages
(`until_planner`, qtree_task_planner.executive.outage), where to keep checkpoints, per-episode feedback and how to
relocate
one object; everything else (order, what is kept when the planner goes away, when execution stops) is here.
"""
from __future__ import annotations

import dataclasses
from typing import Callable, Iterable, Sequence

from qtree_task_planner.executive.closed_loop import (
    ClosedLoopExecutor,
    ExecutionResult,
    GiveUp,
    Option,
    ReplanAnswer,
    ReplanRecord,
    Step,
)
from qtree_task_planner.executive.outage import Cancelled, PlannerGone, PlannerUnavailable, UntilPlanner
from qtree_task_planner.executive.push import PushActions, PushAnswer, Pusher, PushProof, PushRecord
from qtree_task_planner.executive.replan import (
    GeometryCache,
    after_push,
    blocking_pairs,
    free_first,
    pickable,
    relearn,
    replan,
)
from qtree_task_planner.executive.resume import WithGone
from qtree_task_planner.executive.world import (
    RemainingProblem,
    Scene,
    Tolerances,
    check_capacity,
    free_slots,
    remaining_problem,
)
from qtree_task_planner.learning.checkpoint import Checkpoint
from qtree_task_planner.learning.params import TrainingParams
from qtree_task_planner.learning.training import EpisodeStats, TrainingResult, train
from qtree_task_planner.oracles import CachedOracle, no_grasp
from qtree_task_planner.problem import ActionCosts, RelocationProblem
from qtree_task_planner.search import astar
from qtree_task_planner.search.exact import ExactResult
from relocation_common.feasibility import LaneOracle
from relocation_common.scenario import Scenario, ScenarioError
from relocation_common.scene_check import foreign_ids

STAMP_PLAUSIBLE = 86400.0  # s: a scene stamp further from the node's clock is on another clock


def check_scene(topic: str, max_age: float, received_s: float | None, stamp_age_s: float | None,
                n_objects: int) -> str | None:
    """ScenarioError for a scene a goal must not train on: none received, stale (received longer than max_age
    ago, or stamped longer ago than that: an old scene handed over by transient-local durability from a
    perception that stopped; max_age 0: no check), or empty. received_s: seconds since it arrived (None: never);
    stamp_age_s: the node's clock minus the header stamp (None: unstamped). Returns a warning when the stamp is
    on another clock (simulated vs wall time: only the receive time counts then)."""
    if received_s is None:
        raise ScenarioError(f"no scene received on {topic}: is perception (or the driver) up?")
    stale = f"the scene on {topic} is stale: %s > scene_max_age {max_age:g} s; is perception still running?"
    if max_age > 0 and received_s > max_age:
        raise ScenarioError(stale % f"received {received_s:.1f} s ago")
    warning = None
    if max_age > 0 and stamp_age_s is not None:
        if not -1.0 < stamp_age_s < STAMP_PLAUSIBLE:
            warning = (f"scene stamp {stamp_age_s:.0f} s away from this node's clock: is one of them on use_sim_time? "
                       "Checking the scene's age by receive time only")
        elif stamp_age_s > max_age:
            raise ScenarioError(stale % f"stamped {stamp_age_s:.1f} s ago")
    if not n_objects:
        raise ScenarioError(f"the scene on {topic} is empty: perception sees no objects (camera, marker, lighting?)")
    return warning


def solve_then_train(problem: RelocationProblem, oracle: CachedOracle, params: TrainingParams, *,
                     resume: Checkpoint | None, until_planner: UntilPlanner,
                     keep: Callable[[Checkpoint], None], on_episode: Callable[[EpisodeStats], bool | None],
                     checkpoint_every: int, on_solved: Callable[[astar.AStarResult], None] = lambda optimum: None,
                     episode_every: int = 1) -> tuple[astar.AStarResult, TrainingResult]:
    """(exact optimum, training result). The answers the exact solve gathered before an outage are kept in a
    checkpoint (`keep`), so nothing asked is asked again; training checkpoints every `checkpoint_every` episodes,
    calls `on_episode(stats)` every `episode_every` episodes (training.train's callback) and stops when it
    returns False (cancel, shutdown). No training when the exact solve proved that no sequence exists (`proven_none`:
    every episode would ask in vain, up to E_max; a blocking cycle through an object the hand cannot grasp ran 30
    minutes of episodes before)."""
    state: dict[str, Checkpoint | None] = {"ck": resume}

    def solve() -> astar.AStarResult:
        try:
            return astar.solve(problem, oracle)
        except PlannerUnavailable as e:
            ck = dataclasses.replace(state["ck"] or Checkpoint.initial(problem, params),
                                     feasibility=Checkpoint.table_of(oracle), reason=f"interrupted: {e}")
            state["ck"] = ck
            keep(ck)
            raise

    optimum = until_planner(solve)
    on_solved(optimum)
    if not optimum.found:
        return optimum, proven_none(params, oracle.calls)

    def on_checkpoint(ck: Checkpoint) -> None:
        state["ck"] = ck
        keep(ck)

    def run() -> TrainingResult:
        return train(problem, oracle, params, optimal_weight=optimum.total_weight, optimal_cost=optimum.total_cost,
                     callback=on_episode,
                     callback_every=episode_every, resume=state["ck"], checkpoint_every=checkpoint_every,
                     on_checkpoint=on_checkpoint)

    return optimum, until_planner(run)


def proven_none(params: TrainingParams, planner_calls: int) -> TrainingResult:
    """The training result of a problem the exact solve proved has no sequence (its A* explored every set the
    planner's answers and certain lane claims leave open: no episode can find one): no episode run."""
    return TrainingResult(None, None, 0, False, 0, 0, planner_calls, None, None, False, 0, 0, [], params)


def training_outcome(trained: TrainingResult, optimum: ExactResult, *, execute: bool, push: bool = False
                     ) -> tuple[bool, str] | None:
    """(success, message) when the goal ends after training, None when it goes on to execute. Cancelled; no
    sequence at all (the exact solver's one-line reason, exact.why_none; `push`: the closed loop pushes, so an
    execution goes on with no sequence: its first re-plan proves the same and pushes); not executed (trained; or
    training found none within E_max while the proven optimum exists: said, with the optimum). Training without a
    sequence but with an optimum goes on: the optimum is executed (chosen_sequence says so)."""
    if trained.cancelled:
        return False, "cancelled"
    if not (trained.found or optimum.found) and not (push and execute):
        return False, f"the target cannot be retrieved: {optimum.reason or 'no sequence'}"
    if execute:
        return None
    if trained.found:
        return True, "trained (not executed)"
    return False, (f"training did not find a sequence to the target in {trained.episodes} episodes (the exact "
                   f"optimum {' '.join(optimum.sequence or ())}, weight {optimum.total_weight:.2f}, exists: "
                   "execute_optimum)")


def scene_notes(problem: RelocationProblem, oracle: CachedOracle) -> str:
    """One line for the log and the TrainPlanner result (after the exact solve): the scene's objects the scenario does
    not list with their estimated weights (problem.unlisted_line), the obstacles whose cost differs from their
    weight (problem.costs_line), and the obstacles the hand cannot grasp with the
    motion planner's reason (oracles.no_grasp over the answers at the start and the objects without a lane: such an
    answer costs no planning); "" when there are neither. A planner gone meanwhile leaves its part out (a note)."""
    parts = [problem.unlisted_line(), problem.costs_line()]
    try:
        why = no_grasp(problem.obstacles, oracle.lane_blockers(frozenset()),
                       [(o, a) for (o, r), a in oracle.table.items() if not r],
                       lambda o: oracle.feasibility(o, frozenset()))
    except (PlannerUnavailable, Cancelled, ValueError):
        why = {}
    if why:
        parts.append("never relocated, the hand cannot grasp them: " + "; ".join(f"{o} ({m})" for o, m in why.items()))
    return "; ".join(p for p in parts if p)


def planner_foreign_ids(oracle: LaneOracle, ids: Iterable[str]) -> str:
    """scene_check.foreign_ids: the motion planner's bottles (its lanes, all_lanes) the scene `ids` does not have;
    "" when the planner is gone or refuses the question (a diagnosis only, it says nothing then)."""
    try:
        return foreign_ids(oracle.lane_blockers(frozenset()) or {}, ids)
    except Exception:
        return ""


def execute_sequence(sequence: Sequence[str], relocate_one: Callable[[str, list[str]], tuple[bool, str]],
                     cancelled: Callable[[], bool], before_each: Callable[[], None] = lambda: None,
                     before: Sequence[str] = ()) -> tuple[bool, str, list[str]]:
    """Relocate the learned sequence in order (the target last): (success, message, relocated ids, after `before`:
    those relocated before, sent as removed). Stops at the first failure or on cancel, saying which object and
    why."""
    removed: list[str] = list(before)
    for object_id in sequence:
        before_each()
        if cancelled():
            return False, f"cancelled after relocating {removed}", removed
        ok, message = relocate_one(object_id, list(removed))
        if not ok:
            return False, f"relocating {object_id!r} failed: {message}", removed
        removed.append(object_id)
    return True, f"target {sequence[-1]!r} retrieved after {len(removed) - 1} relocations", removed


def chosen_sequence(learned: Sequence[str] | None, learned_weight: float | None, optimum: Sequence[str] | None,
                    optimal_weight: float | None, *, execute_optimum: bool, execute_learned: bool,
                    learned_cost: float | None = None, optimal_cost: float | None = None) -> tuple[list[str], str]:
    """(the sequence to execute, a note for the user): the learned one only when its cost (learned_cost and
    optimal_cost; Eq. 8's weight when they are not given: every action factor 1) equals the proven optimum's, or when
    asked for (execute_learned); else the optimum, saying so with both weights (and costs, when given)."""
    learned_seq, optimum_seq = list(learned or ()), list(optimum or ())
    if not (learned_seq or optimum_seq):  # none at all: the closed loop starts with a re-plan (and pushes)
        return [], ""
    if execute_optimum or not learned_seq:
        return optimum_seq, "" if execute_optimum else "executed the exact optimum (training found no sequence)"
    mine = learned_cost if learned_cost is not None else learned_weight
    best = optimal_cost if optimal_cost is not None else optimal_weight
    if execute_learned or not optimum_seq or best is None or mine is None or mine <= best + 1e-9:
        return learned_seq, ""
    assert optimal_weight is not None and learned_weight is not None

    def amount(weight: float, cost: float | None) -> str:
        return f"weight {weight:.2f}" + (f", cost {cost:.2f}" if cost is not None else "")

    return optimum_seq, (f"executed the exact optimum {' '.join(optimum_seq)} ({amount(optimal_weight, optimal_cost)})"
                         f" instead of the learned {' '.join(learned_seq)} ({amount(learned_weight, learned_cost)}); "
                         "execute_learned forces the learned")


def execute(scenario: Scenario, sequence: Sequence[str], scene: Scene,
            relocate_one: Callable[[str, list[str]], tuple[bool, str]], perceive: Callable[[], Scene],
            oracle: CachedOracle, *, closed_loop: bool, cancelled: Callable[[], bool],
            before_each: Callable[[], None] = lambda: None, on_step: Callable[[Step], None] = lambda s: None,
            on_replan: Callable[[ReplanRecord], None] = lambda r: None, bottom_seen: bool = True,
            retrain: TrainingParams | None = None, until_planner: UntilPlanner | None = None,
            on_progress: Callable[[ExecutionResult], None] = lambda out: None,
            action_cost: ActionCosts | None = None, pushes: PushActions | None = None,
            on_push: Callable[[PushRecord], None] = lambda p: None, before: Sequence[str] = (),
            tolerances: Tolerances | None = None) -> ExecutionResult:
    """Execute `sequence` from `scene` (the scene it was planned on), after the relocations `before` (done before
    this goal: executive.resume; sent as removed). closed_loop: closed_loop.ClosedLoopExecutor,
    checking the world after every relocation and re-planning over the exact blocker A* (replan.replan, Eq. 8)
    with the answers `oracle` gathered kept for unchanged geometry (docs/closed_loop.md). Else the paper's
    open-loop execution (execute_sequence) after the same capacity check: a sequence needing more slots than
    are free is never started. retrain: each re-plan also trains the Q-Tree on the remaining problem with these
    params (replan.relearn; the user's `replan_q_tree`), else the A* alone. until_planner: each re-plan goes
    through feasibility outages as training does (outage.until_available: a motion planner that died is waited for,
    planner_wait), else a question without an answer is asked again REPLAN_TRIES times. on_progress: the execution
    so far, after each relocation and re-plan (closed loop). action_cost: the re-plans' costs (the factor of the pick
    each object's pose takes: world.remaining_problem), else their weights. pushes: when a re-plan proves no
    sequence, a push out of its blocking cycle (executive.push; closed loop only: an open-loop run never pushes); an
    empty `sequence` (the first plan found none) then starts with that re-plan; on_push(record) after each push.
    tolerances: the closed loop's "as planned" (world.Tolerances; None: config/task_planner.yaml's)."""
    if closed_loop:
        asked = oracle.oracle  # the re-plans ask with their own gone set (RemainingOracle), not a start point's
        cache = GeometryCache(asked.oracle if isinstance(asked, WithGone) else asked, tolerances)
        cache.adopt(oracle.table, remaining_problem(scenario, scene, (), tolerances).geometry(), oracle.certified)

        def relocate(object_id: str, removed: list[str]) -> tuple[bool, str]:
            before_each()
            ok, message = relocate_one(object_id, removed)
            if not ok and any(w in message for w in STOPPED):  # no motion planner to recover with, or a stop
                raise GiveUp(f"relocating {object_id!r} failed: {message}")
            return ok, message

        def replan_through(rp: RemainingProblem, banned: frozenset[Option]) -> ReplanAnswer | str:
            """replan; a feasibility question with no answer (the planner's safety net under load, PlannerUnavailable)
            is asked again, up to REPLAN_TRIES re-plans (the answers already given are kept), then the run ends
            with the reason (before, it escaped the executor: the goal ended with no execution record)."""
            def once() -> ReplanAnswer | str:
                answer = replan(rp, banned, cache)
                if retrain is None or isinstance(answer, str):
                    return answer
                return relearn(rp, banned, cache, retrain, answer, keep_going=lambda: not cancelled())

            for attempt in range(1, REPLAN_TRIES + 1):
                try:
                    return once() if until_planner is None else until_planner(once)
                except PlannerGone as e:
                    raise GiveUp(f"re-plan stopped: {e}") from None
                except PlannerUnavailable as e:
                    if attempt == REPLAN_TRIES:
                        raise GiveUp(f"re-plan failed {REPLAN_TRIES} times without a feasibility answer: {e}") from None
            raise AssertionError("unreachable")

        def push(object_id: str, clear_for: str, removed: list[str]) -> tuple[bool, str]:
            assert pushes is not None
            before_each()
            ok, message = pushes.execute(object_id, clear_for, removed)
            if not ok and any(w in message for w in STOPPED):  # as a relocation's
                raise GiveUp(f"pushing {object_id!r} failed: {message}")
            return ok, message

        def can_pick(rp: RemainingProblem, banned: frozenset[Option], object_id: str, removed: frozenset[str]) -> bool:
            def once() -> bool:
                return pickable(rp, cache, banned, object_id, removed)
            try:
                return once() if until_planner is None else until_planner(once)
            except (PlannerGone, PlannerUnavailable) as e:
                raise GiveUp(f"feasibility question about {object_id!r} for a push stopped: {e}") from None

        def follow(rp: RemainingProblem, banned: frozenset[Option], pushed: str, end: tuple[float, float],
                   prep: tuple[str, ...]) -> tuple[tuple[str, ...], float] | str:
            def once() -> tuple[tuple[str, ...], float] | str:
                assert pushes is not None and pushes.what_if is not None
                return after_push(rp, banned, pushed, end, prep, pushes.what_if, tolerances)
            try:
                return once() if until_planner is None else until_planner(once)
            except (PlannerGone, PlannerUnavailable) as e:
                raise GiveUp(f"feasibility question after a push of {pushed!r} stopped: {e}") from None

        pusher = None if pushes is None else Pusher(
            dataclasses.replace(pushes, ask=through(pushes.ask, until_planner), execute=push),
            PushProof(lambda rp: blocking_pairs(rp, cache), lambda rp: free_first(rp, cache), can_pick,
                      follow if pushes.what_if is not None else None))
        return ClosedLoopExecutor(scenario, relocate, perceive, replan_through,
                                  cancelled=cancelled, on_step=on_step, on_replan=on_replan,
                                  bottom_seen=bottom_seen, on_progress=on_progress,
                                  action_cost=action_cost, pusher=pusher, on_push=on_push,
                                  tolerances=tolerances).run(sequence, scene, before)
    why = check_capacity(sequence, len(free_slots(scenario, scene, tolerances)))
    if why:
        return ExecutionResult(False, f"not executed: {why}")
    unverified: list[str] = []  # the motion planner's success without an outcome check (goal_check.outcome)

    def relocate_noted(object_id: str, removed: list[str]) -> tuple[bool, str]:
        ok, message = relocate_one(object_id, removed)
        if ok and "unverified" in message:
            unverified.append(object_id)
        return ok, message

    ok, message, relocated = execute_sequence(sequence, relocate_noted, cancelled, before_each, before)
    return ExecutionResult(ok, message + (f" (unverified: {', '.join(unverified)})" if ok and unverified else ""),
                           relocated, unverified=unverified)


def through(ask: Callable[[str, str, frozenset[str]], PushAnswer], until_planner: UntilPlanner | None
            ) -> Callable[[str, str, frozenset[str]], PushAnswer]:
    """The push question through feasibility outages as a re-plan's (`until_planner`); a planner gone, or no
    answer, ends the run with the reason (GiveUp)."""
    def asked(object_id: str, clear_for: str, removed: frozenset[str]) -> PushAnswer:
        def once() -> PushAnswer:
            return ask(object_id, clear_for, removed)
        try:
            return once() if until_planner is None else until_planner(once)
        except (PlannerGone, PlannerUnavailable) as e:
            raise GiveUp(f"push question about {object_id!r} stopped: {e}") from None
    return asked


REPLAN_TRIES = 3  # re-plans cut short by a missing feasibility answer before the closed loop gives up
STOPPED = ("shutting down", "went away", "cancelled", "relocate_timeout", "not available")  # relocation_stop's words
# (and the Relocator's): the relocation stopped without the motion planner's recovery; the closed loop ends there


def relocation_stop(*, shutting_down: bool, server_up: Callable[[], bool], silent_s: float, silence: float,
                    cancelled: bool, elapsed_s: float, limit: float) -> str | None:
    """Why a running relocation must stop now, or None (checked in this order): the task planner shutting down,
    the relocate action server gone (`server_up()`, asked only while the node runs: it needs a valid context), no
    feedback for more than `silence` s (relocate_silence), the goal cancelled, no result within `limit` s
    (relocate_timeout)."""
    if shutting_down:
        return "the task planner is shutting down"
    if not server_up():
        return "the motion planner went away (relocate action server gone)"
    if silent_s > silence:
        return f"the motion planner went away (no feedback for {silent_s:.0f} s > relocate_silence)"
    if cancelled:
        return "cancelled"
    if elapsed_s > limit:
        return f"no result within {limit:g} s (relocate_timeout)"
    return None
