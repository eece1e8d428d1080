"""What the motion_planner node serves, without ROS (the node only translates messages to and from these calls).

One `MotionPlanner` (not thread-safe: a lock) on the scenario as last perceived: feasibility questions (Eq. 11)
with every lane's blockers when asked, scene updates from perception (`scene_update.merge_perceived`: standing and
lying bottles of the top shelf, bottles gone from it; the bottle being carried and the bottles relocated by this
node are not taken from perception until seen back on the top shelf), and one relocation at a time
(`relocation.relocate` on a `streaming.StreamedArm`, then `relocation.recover` after a failure or a cancel). While
a relocation runs, its last feedback is sent again every `HEARTBEAT` s when nothing new was sent: a plan under
load can take the planner's whole wall-clock safety net (carry_timeout, 60 s) without a phase change, and the task
planner takes `relocate_silence` (10 s) without feedback for a planner that is gone. Logging goes to
`log(level, text)` (the node's logger).

A process that dies mid-relocation leaves the arm where it stopped, perhaps holding a bottle; one that dies
mid-push leaves it in the shelf with the fingers shut. The relocation's or the push's progress is kept in a journal
(`execution.journal`, the node's `journal_path`) before each motion and at the release (a push: its plan, before
the arm moves); a new process reads it and `recover_interrupted` brings the arm back as after a cancel (a push: home
from where the arm is, the gripper opened, the pushed object modelled at its predicted end once its retreat had
started). A goal sent again for that object (and action) then answers for the interrupted one: released (a push:
its retreat started) before the death, the outcome checked against the scene now; else aborted with what the
recovery did (the task planner re-plans as after any failed relocation). Goals wait (with feedback) until that
recovery has ended. `on_relocated(relocated)` is called when the bottles this node placed change (the node publishes
them: perception leaves a relocated target out of view instead of publishing no scene).
"""
from __future__ import annotations

import dataclasses
import math
import threading
import time
from dataclasses import dataclass
from typing import Callable, Iterable, Mapping

import numpy as np

from relocation_common import robot_description as rd
from relocation_common.feasibility import BlockerSet, FeasibilityAnswer
from relocation_common.scenario import Scenario, ShelfObject, UnknownObjectError
from relocation_common.scene_check import check_scene
from stpik_motion_planner.execution import goal_check
from stpik_motion_planner.execution import push as pushing
from stpik_motion_planner.execution.journal import Journal, JournalError, Running, near_recorded
from stpik_motion_planner.execution.relocation import Progress, recover, relocate
from stpik_motion_planner.execution.streaming import Aborted, Cancelled, StreamedArm
from stpik_motion_planner.model.blockers import lane_blockers
from stpik_motion_planner.model.scene_update import merge_perceived
from stpik_motion_planner.planning.params import PlannerParams, node_parameters
from stpik_motion_planner.planning.planner import MotionPlanner
from stpik_motion_planner.planning.push import PushPlan
from stpik_motion_planner.planning.results import PlanningError

STATE_WAIT = 5.0  # s a relocation waits for the first joint state (discovery of the driver right after start-up)
RESTART_STATE_WAIT = 30.0  # s the recovery of an interrupted relocation waits for the driver's joint states
HEARTBEAT = 2.0  # s without feedback after which a running relocation's last feedback is sent again
HOME_SETTLE = 0.01  # rad: a relocation or a recovery that ends farther than this from home is brought home
SETTLE_WAIT = 0.3  # s after the last motion before the arm's place is measured
RECOVERY_STATE_WAIT = 10.0  # s each recovery attempt waits for fresh joint states: a relocation aborted because the
# driver fell silent (starved under load) was recovered at once, on the same stale state, and failed twice within a
# millisecond; the arm stayed in the shelf holding the bottle and every later goal failed (the closed-loop grid at
# a load average of 25, scenario1_5 K=1 seed 1)
RECOVERY_TRIES = 2  # a recovery that failed (under load: the fingers' result late) is tried again from where the arm
# is: the recorded motions are followed back from the nearest sample (Trajectory.back_from); left in the shelf, the
# arm had no collision-free way home and every later goal failed (the benchmark, scenario1_5 K=3 seed 1)


@dataclass(frozen=True)
class Outcome:
    """How a relocation goal ended: status 'succeeded', 'canceled' or 'aborted', and the result's message."""

    status: str
    message: str


class MotionPlannerService:
    """The node's behaviour (the module docstring). `home_tol`: relocation.relocate's, `recover_near`:
    relocation.recover's `near` (rad; None: config/motion_planner.yaml's); `phantom_scenes`: scene_update's (None:
    config/motion_planner.yaml's)."""

    def __init__(self, scenario: Scenario, params: PlannerParams, home_tol: float | None = None,
                 log: Callable[[str, str], None] = lambda *_: None, journal: Journal | None = None,
                 recover_near: float | None = None, phantom_scenes: int | None = None) -> None:
        self.base, self.log, self.home_tol, self.recover_near = scenario, log, home_tol, recover_near
        n = node_parameters()["phantom_scenes"] if phantom_scenes is None else phantom_scenes
        if isinstance(n, bool) or not isinstance(n, int) or n < 1:
            raise ValueError(f"motion planner parameter phantom_scenes must be an integer >= 1, got {n!r}")
        self.phantom_scenes = n
        self._missing: dict[str, int] = {}  # unlisted id -> counted scenes in a row without it (scene_update)
        self._scene_stamp: object = None  # the stamp of the last scene (a scene received again counts once)
        self.planner = MotionPlanner(scenario, params)
        self.plan_lock = threading.Lock()  # MotionPlanner is not thread-safe
        self.bottles = {b.id: b for b in scenario.objects}
        self._held: str | None = None  # the object of the running relocation: its perceived pose is ignored
        self._relocating = threading.Lock()
        self._slot = 0  # the running relocation's slot
        self.scene = goal_check.SceneWatch()  # the last scene as received (goal checks, outcome checks)
        self.checks: dict[str, float] = goal_check.configured()  # the node sets the parameters'
        self.on_relocated: Callable[[dict[str, int]], None] = lambda relocated: None
        self.journal = journal or Journal(None)
        self.interrupted: Running | None = None  # a relocation a previous process did not finish
        self._running: Running | None = None  # the relocation being carried out or recovered (its journal entry)
        self._resumed: tuple[Running, str] | None = None  # it, recovered, with what the recovery did
        self._ready = threading.Event()  # set once no interrupted relocation is left to recover
        try:
            relocated, running = self.journal.load()
        except JournalError as e:
            self.log("warning", f"{e}; starting without it")
            relocated, running = {}, None
        self.relocated: dict[str, int] = relocated  # object -> slot, placed by this node (until seen on the top shelf)
        if running is not None and running.progress.moves:
            self.interrupted = running
        else:
            self._ready.set()

    # -- the scene ------------------------------------------------------------------------------------------
    def update_scene(self, perceived: Iterable[ShelfObject], source: str = "the scene",
                     stamp: object = None) -> list[str]:
        """Objects as perceived (ros_conversions.msg_to_objects) resting on the top shelf replace the planner's:
        standing, lying flat (tipped over: the grasp from above takes it where the headroom allows), or leaning (an
        obstacle as it leans, never graspable), listed in the scenario or not (`listed`
        false: an object the scenario does not name, an obstacle as its primitive, relocatable when the side grasp
        takes it); bottles seen off the shelf leave the planner's scene; the rest stays
        (scene_update.merge_perceived), but an unlisted object left out of `phantom_scenes` scenes in a row with its
        place in view is dropped (`stamp`: the message's; one received again counts once, None: every scene
        counts). The ids that changed; ScenarioError for a scene that cannot be
        (scene_check: a listed id the scenario does not have, an unlisted one it has, an id twice, poses far from
        the shelf): the whole message is dropped, nothing changes."""
        bottles = list(perceived)
        bases = [(b.id, float(c[0]), float(c[1]), float(c[2])) for b, c in ((b, b.base()) for b in bottles)]
        check_scene(self.base, bases, source, unlisted={b.id for b in bottles if not b.listed})
        self.scene.update(bottles)
        counted = stamp is None or stamp != self._scene_stamp
        self._scene_stamp = stamp
        m = merge_perceived(self.base.shelf, self.bottles, bottles, self.planner.params.flat_tilt, self._held,
                            self.planner.lying, self.planner.gone, self._missing,
                            self.phantom_scenes if counted else None, kept=set(self.relocated))
        self._missing = m.missing
        dropped = [i for i in m.changed if i not in m.bottles and i in self.bottles]
        if dropped:
            self.log("info", f"unlisted objects no longer in {source} dropped from the planner's scene: {dropped}")
        back = [i for i in m.seen if i in self.relocated]  # seen back on the top shelf: it can be relocated again
        for i in back:
            self.relocated.pop(i)
        if back:
            self.on_relocated(dict(self.relocated))
        if m.changed:
            scenario = self.base.with_objects(m.bottles.values())
            with self.plan_lock:
                self.planner.set_scenario(scenario, m.lying, m.gone)
                self.bottles = m.bottles
        return m.changed

    # -- feasibility (Eq. 11) -------------------------------------------------------------------------------
    def feasibility(self, object_id: str, removed: Iterable[str], timeout: float | None = None,
                    all_lanes: bool = False, certify: bool = False, moved: Mapping[str, tuple[float, float]] | None
                    = None) -> tuple[dict[str, tuple[BlockerSet, ...]], FeasibilityAnswer | None]:
        """(every lane's blockers with `removed` gone if `all_lanes`, else {}; the answer for `object_id`, None when
        all_lanes and no object is asked): the pick, or with `certify` the certification (MotionPlanner.certify);
        on the scene with the objects of `moved` at those (x, y) (MotionPlanner.what_if: what would follow a push).
        `timeout` None or <= 0: the planner's. UnknownObjectError, ScenarioError, ValueError, TypeError for a bad
        question; SafetyNetTimeout when the wall-clock safety net ran out."""
        if timeout is not None and not math.isfinite(timeout):
            raise ValueError(f"timeout must be a finite number of seconds (<= 0: the default), got {timeout}")
        removed = list(removed)
        with self.plan_lock:
            planner = self.planner.what_if(moved or {}, removed)
            lanes = lane_blockers(planner, removed) if all_lanes else {}
            ask = planner.certify if certify else planner.feasibility
            answer = None if all_lanes and not object_id else ask(
                object_id, removed, float(timeout) if timeout is not None and timeout > 0 else None)
        return lanes, answer

    def push_feasibility(self, object_id: str, removed: Iterable[str], clear_for: str, timeout: float | None = None,
                         moved: Mapping[str, tuple[float, float]] | None = None
                         ) -> tuple[FeasibilityAnswer, PushPlan | None]:
        """The answer for a push of `object_id` out of the grasp lanes of `clear_for` with `removed` gone
        (MotionPlanner.push_feasibility: g_O with the whole motion and the plan, whose `end` is the predicted pose;
        g_U with the reason and None), on the scene with the objects of `moved` elsewhere as `feasibility`. Errors
        as `feasibility`."""
        if timeout is not None and not math.isfinite(timeout):
            raise ValueError(f"timeout must be a finite number of seconds (<= 0: the default), got {timeout}")
        if not isinstance(clear_for, str) or not clear_for:
            raise ValueError("a push question names the object whose lanes it clears (clear_for)")
        with self.plan_lock:
            removed = list(removed)
            return self.planner.what_if(moved or {}, removed).push_feasibility(
                object_id, clear_for, removed, float(timeout) if timeout is not None and timeout > 0 else None)

    # -- relocation -----------------------------------------------------------------------------------------
    def busy(self) -> bool:
        """A relocation is running (a second goal is rejected: the one refusal without a result message)."""
        return self._relocating.locked()

    def check_goal(self, object_id: str, removed_ids: Iterable[str]) -> None:
        """ValueError with the reason a RelocateObject goal cannot be carried out (goal_check.goal_refusal: unknown
        ids (of the planner's scene: the scenario's and the unlisted objects seen), the object in its own removed
        set, no free slot, the goal contradicting the scene)."""
        # the planner's scene, not the file's: an unlisted object is relocated and removed like a listed one
        why = goal_check.goal_refusal(self.planner.scenario, object_id, list(removed_ids), self.scene.seen,
                                      self.relocated)
        if why is not None:
            raise ValueError(why)

    def relocate(self, arm: StreamedArm, object_id: str, removed_ids: Iterable[str], source: str = "the scene",
                 ok: Callable[[], bool] = lambda: True) -> Outcome:
        """Relocate `object_id` to a free slot of the scene (goal_check.destination: slot len(removed_ids), the one
        a certified answer planned, when it is free) with `arm`; after a failure or
        a cancel, recover (the result message says what was done). A goal that contradicts the scene (a removed
        bottle still on the top shelf, the object already relocated: goal_check.goal_refusal) is aborted with the
        reason; after the motion, success only if the scene from `source` shows the bottle at its slot and no
        other bottle moved (goal_check.outcome). The goal waits until a relocation a previous process left is
        recovered; a goal for that object answers for it (`_resumed_outcome`). Never raises: a bug ends the goal
        with its reason, not the node."""
        removed_ids = list(removed_ids)
        with self._relocating, _Heartbeat(arm):
            if not self._ready.is_set():
                arm.phase("recover")  # the heartbeat repeats it while the previous process's relocation is undone
                self._ready.wait()
            resumed = self._resumed_outcome(object_id, source, ok)
            if resumed is not None:
                return resumed
            try:
                self.check_goal(object_id, removed_ids)
            except ValueError as e:  # accepted, then aborted with the reason: the client learns why (as nav2 does)
                self.log("error", f"relocation goal refused: {e}")
                return Outcome("aborted", f"relocation goal refused: {e}")
            self._held = object_id
            try:
                return self._relocate(arm, object_id, removed_ids, source, ok)
            finally:
                self._held = None
                self._write_journal(None)

    def push(self, arm: StreamedArm, object_id: str, removed_ids: Iterable[str], clear_for: str,
             source: str = "the scene", ok: Callable[[], bool] = lambda: True) -> Outcome:
        """Push `object_id` out of the grasp lanes of `clear_for` with `arm` (execution.push: planned as the
        feasibility answer, then shut, approach, push, retreat, home, open), journalled as a relocation is (the
        module docstring); after a failure or a cancel, recover_push. Afterwards the planner models the object at
        the push's predicted end pose, until a scene says where it is (update_scene). Success only if the scene from
        `source` shows it within slot_tolerance of that pose on the top shelf and no other object moved more than
        outcome_tolerance. A goal for the push a previous process left answers for it (`_resumed_outcome`). Never
        raises."""
        removed = list(removed_ids)
        with self._relocating, _Heartbeat(arm):
            if not self._ready.is_set():
                arm.phase("recover")
                self._ready.wait()
            resumed = self._resumed_outcome(object_id, source, ok, push=True)
            if resumed is not None:
                return resumed
            progress = Progress()
            try:
                with self.plan_lock:
                    self.planner.check_question(object_id, removed)
                    self.planner.check_question(clear_for, removed)
                arm.wait_for_state(STATE_WAIT)
                before = {i: b.point for i, b in self.scene.seen.items()}
                self._running = running = Running(progress, -1, [(i, *p) for i, p in before.items()], None)

                def on_plan(made: PushPlan) -> None:  # planned, before the arm moves
                    running.push = made
                    self._write_journal(running)

                self._held = object_id
                made = pushing.push(self.planner, arm, object_id, clear_for, removed, home_tol=self.home_tol,
                                    lock=self.plan_lock, progress=progress,
                                    on_change=lambda: self._write_journal(running), on_plan=on_plan)
                self._pushed(made)
                self._held = None
                return self._push_outcome(before, made, source, ok)
            except Cancelled:
                arm.stop()
                return Outcome("canceled", "cancelled: arm stopped" + self._recover_push(arm, progress))
            except Exception as e:  # planning, the arm, bad input; a bug ends the goal with its reason, not the node
                arm.stop()
                known = isinstance(e, (Aborted, PlanningError, UnknownObjectError, ValueError, TypeError))
                message = str(e) if known else f"internal error: {type(e).__name__}: {e}"
                self.log("error", f"push of {object_id} aborted: {message}")
                return Outcome("aborted", message + self._recover_push(arm, progress))
            finally:
                self._held = None
                self._write_journal(None)

    def _pushed(self, made: PushPlan) -> None:
        """The pushed object stands at the push's predicted end pose in the planner's scene (until a scene)."""
        x, y = made.end[:2]
        with self.plan_lock:
            self.planner.update_object(made.object_id, x, y)
            b = self.bottles.get(made.object_id)
            if b is not None:
                self.bottles[made.object_id] = dataclasses.replace(b, x=x, y=y)

    def _push_outcome(self, before: dict[str, goal_check.Point], made: PushPlan, source: str,
                      ok: Callable[[], bool]) -> Outcome:
        """The push's outcome against the first scene after it (execution.push.push_problems)."""
        done = (f"pushed {made.object_id} {made.distance * 1000:.0f} mm (yaw {made.yaw:+.2f}): "
                f"{made.clear_for}'s lane {made.lane} open")
        after = self.scene.after(time.monotonic() + goal_check.OUTCOME_SETTLE, self.checks["outcome_timeout"], ok)
        if after is None:
            return Outcome("aborted", f"{done}, but no scene on {source} within outcome_timeout after the motion: "
                                      f"{goal_check.OUTCOME_UNKNOWN}")
        problems = pushing.push_problems(self.base.shelf, before, after, made, self.checks["outcome_tolerance"],
                                         self.checks["slot_tolerance"])
        if problems:
            return Outcome("aborted", f"{done}, but the scene shows: {'; '.join(problems)}")
        return Outcome("succeeded", done)

    def _recover_push(self, arm: StreamedArm, progress: Progress) -> str:
        """After a failed, cancelled or interrupted push (the running one, `_running`): execution.push.recover_push,
        not cancellable, its journal kept. The text added."""
        if not arm.link.ok() or not progress.moves:
            return ""
        made = self._running.push if self._running is not None else None
        try:
            arm = arm.uncancellable()
            arm.wait_for_state(RECOVERY_STATE_WAIT)
            what = pushing.recover_push(arm, progress, lambda: self._write_journal(self._running), made,
                                        self.recover_near)
        except Exception as e:
            self.log("error", f"recovery after the failed push failed: {e}")
            return f"; recovery failed: {e}"
        self.log("info", f"recovered: {what}")
        return f"; recovered: {what}"

    def _relocate(self, arm: StreamedArm, object_id: str, removed_ids: list[str], source: str,
                  ok: Callable[[], bool]) -> Outcome:
        """The relocation of a checked goal, its journal kept, then its outcome (relocate's docstring)."""
        progress = Progress()
        try:
            arm.wait_for_state(STATE_WAIT)
            before = {i: b.point for i, b in self.scene.seen.items()}
            self._slot, placed = goal_check.destination(self.base, self.scene.seen, self.relocated, len(removed_ids))
            self._running = running = Running(progress, self._slot, [(i, *p) for i, p in before.items()], None)

            def on_change() -> None:  # a motion about to start, or the release
                if progress.released:
                    self._placed(object_id, self._slot)
                self._write_journal(running)

            relocate(self.planner, arm, object_id, removed_ids, home_tol=self.home_tol, lock=self.plan_lock,
                     progress=progress, slot=self._slot, placed=placed, on_change=on_change)
            self._placed(object_id, self._slot)
            self._settle_home(arm, progress)
            success, message = goal_check.outcome(self.scene, before, self.base, object_id, self._slot,
                                                  self.checks, source, ok)
            return Outcome("succeeded" if success else "aborted", message)
        except Cancelled:
            arm.stop()
            return Outcome("canceled", "cancelled: arm stopped" + self._recover(arm, progress))
        except Exception as e:  # planning, the arm, bad input; a bug ends the goal with its reason, not the node
            arm.stop()
            known = isinstance(e, (Aborted, PlanningError, UnknownObjectError, ValueError))
            message = str(e) if known else f"internal error: {type(e).__name__}: {e}"
            self.log("error", f"relocation of {object_id} aborted: {message}")
            return Outcome("aborted", message + self._recover(arm, progress))

    def _placed(self, object_id: str, slot: int) -> None:
        """object_id is on the bottom shelf at `slot`, put there by this node (on_relocated once)."""
        if self.relocated.get(object_id) != slot:
            self.relocated[object_id] = slot
            self.on_relocated(dict(self.relocated))

    def _write_journal(self, running: Running | None) -> None:
        """The journal now (execution.journal); a failure to write is said, never raised (the arm goes on)."""
        try:
            self.journal.write(self.relocated, running)
        except OSError as e:
            self.log("error", f"journal {self.journal.path} not written: {e}")

    # -- a relocation a previous process left (the module docstring) ----------------------------------------
    def recover_interrupted(self, arm: StreamedArm) -> str:
        """Bring the arm back from the relocation or push the journal says a previous process did not finish (as
        after a cancel: the bottle set down where it was picked, or after the release, the arm home; a push: the arm
        home from where it is, the gripper opened, and once its retreat had started the pushed object modelled at
        its predicted end pose until a scene); goals wait for it. A journal whose motions the arm is nowhere near (a
        new world) is dropped. What was done, one line."""
        run = self.interrupted
        if run is None:
            self._ready.set()
            return "nothing to recover"
        kind = "relocation" if run.push is None else "push"
        try:
            arm.wait_for_state(RESTART_STATE_WAIT)
            q = arm.measured()
            if not near_recorded(run.progress, q):
                what = (f"the journal's {kind} of {run.progress.object_id} is not where the arm is (a new "
                        "world?): dropped")
            else:
                self._slot, self._running = run.slot, run
                if run.push is None:
                    what = self._recover(arm, run.progress).lstrip("; ")
                else:
                    done = pushing.pushed(run.progress)
                    what = self._recover_push(arm, run.progress).lstrip("; ")
                    if done:
                        self._pushed(run.push)
                self._resumed = (run, what)
        except Exception as e:  # the driver gone, the planner: said; the next goal starts from where the arm is
            what = f"recovery of the interrupted {kind} of {run.progress.object_id} failed: {e}"
        finally:
            self.interrupted = None
            self._running = None
            self._write_journal(None)
            self._ready.set()
        self.log("warning", f"restarted during the {kind} of {run.progress.object_id}: {what}")
        return what

    def _resumed_outcome(self, object_id: str, source: str, ok: Callable[[], bool], push: bool = False
                         ) -> Outcome | None:
        """The answer for the relocation (`push`: the push) a previous process left, to a goal of the same kind for
        the same object (None for any other goal, which forgets it): released (a push: its retreat started) before
        the death, the outcome against the scene now (success only if the world confirms it); else aborted, saying
        what the recovery did (the task planner re-plans)."""
        resumed, self._resumed = self._resumed, None
        if resumed is None or resumed[0].progress.object_id != object_id or (resumed[0].push is not None) != push:
            return None
        run, what = resumed
        before = {i: (x, y, z) for i, x, y, z in run.before}
        if run.push is not None:
            note = f"the motion planner restarted during this push ({what})"
            if not pushing.pushed(run.progress):
                return Outcome("aborted", f"interrupted: {note}")
            out = self._push_outcome(before, run.push, source, ok)
            return Outcome(out.status, f"{out.message} ({note})")
        note = f"the motion planner restarted during this relocation ({what})"
        if not run.progress.released:
            return Outcome("aborted", f"interrupted: {note}")
        success, message = goal_check.outcome(self.scene, before, self.base, object_id, run.slot, self.checks,
                                              source, ok)
        return Outcome("succeeded" if success else "aborted", f"{message} ({note})")

    def _recover(self, arm: StreamedArm, progress: Progress) -> str:
        """After a failed or cancelled goal: relocation.recover (the bottle set down where it was picked, the arm
        home), not cancellable itself; unless the node is shutting down. The text added to the result message."""
        if not arm.link.ok() or not progress.moves:
            return ""
        arm = arm.uncancellable()
        for attempt in range(RECOVERY_TRIES):
            try:
                arm.wait_for_state(RECOVERY_STATE_WAIT)
                arm.measured()  # a driver that is gone: fail now, not after the gripper's timeout
                what = recover(self.planner, arm, progress, self.plan_lock,
                               on_change=lambda: self._write_journal(self._running), near=self.recover_near)
                break
            except Exception as e:
                self.log("error", f"recovery after the failed relocation failed: {e}")
                if attempt + 1 == RECOVERY_TRIES or not arm.link.ok():
                    return f"; recovery failed: {e}"
        self.log("info", f"recovered: {what}")
        if progress.released:
            self._placed(progress.object_id, self._slot)
        self._settle_home(arm, progress)
        return f"; recovered: {what}"

    def _settle_home(self, arm: StreamedArm, progress: Progress) -> None:
        """The final settle: an arm that ended farther than HOME_SETTLE from home is brought home from where it is,
        so the next goal starts there (a motion settles within settle_tol of its last point, for the follower's
        settle_dwell: on joint states a tenth of a second old, a follower that stopped at the first state within
        settle_tol left a recovery 0.044 rad off home; this is the net for what is left). A failure is logged: the
        arm is near home, and the next goal plans its way home first when it is farther than home_tol."""
        try:
            time.sleep(SETTLE_WAIT)  # commands still on their way to the driver (under load) have played out
            q = arm.measured()
            off = float(np.max(np.abs(q - rd.Q_HOME)))
            if off <= HOME_SETTLE:
                self.log("info", f"the arm ended {off:.3f} rad from home")
                return
            self.log("warning", f"the arm ended {off:.3f} rad from home: bringing it home")
            removed = progress.removed + [progress.object_id] * progress.released
            with self.plan_lock:
                home = self.planner.plan_home(q, removed, progress.placed)
            arm.follow(home, "home")
        except Exception as e:  # the arm or the planner: said, not raised (the relocation's outcome stands)
            self.log("error", f"bringing the arm home after the relocation failed: {e}")


class _Heartbeat:
    """While a relocation runs: the arm's last feedback (phase, progress) sent again every HEARTBEAT s in which
    nothing new was sent (the module docstring). A context manager around the relocation and its recovery."""

    def __init__(self, arm: StreamedArm) -> None:
        self.arm, self.send = arm, arm.feedback
        self.last: tuple[str, float] | None = None
        self.sent = time.monotonic()
        self.lock = threading.Lock()
        self.done = threading.Event()
        self.thread = threading.Thread(target=self._beat, name="relocation heartbeat", daemon=True)

    def __call__(self, phase: str, progress: float) -> None:
        with self.lock:
            self.last, self.sent = (phase, progress), time.monotonic()
            self.send(phase, progress)

    def __enter__(self) -> _Heartbeat:
        self.arm.feedback = self
        self.thread.start()
        return self

    def __exit__(self, *_: object) -> None:
        self.done.set()
        self.thread.join()
        self.arm.feedback = self.send

    def _beat(self) -> None:
        while not self.done.wait(HEARTBEAT / 4):
            with self.lock:
                if self.last is not None and time.monotonic() - self.sent >= HEARTBEAT and self.arm.link.ok():
                    self.sent = time.monotonic()
                    self.send(*self.last)
