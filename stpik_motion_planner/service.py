"""What the motion_planner node serves, without ROS (the node only translates messages to and from these calls).

One `MotionPlanner` (not thread-safe: a lock) on the scenario as last perceived: feasibility questions (Eq. 11)
with every lane's blockers when asked, scene updates from perception (`scene_update.merge_perceived`: the bottle
being carried and the bottles relocated by this node are not taken from perception until seen back on the top
shelf), and one relocation at a time (`relocation.relocate` on a `streaming.StreamedArm`, then `relocation.recover`
after a failure or a cancel). Logging goes to `log(level, text)` (the node's logger).
"""
from __future__ import annotations

import math
import threading
from dataclasses import dataclass
from typing import Callable, Iterable

from relocation_common.feasibility import BlockerSet, FeasibilityAnswer
from relocation_common.scenario import Bottle, Scenario, UnknownObjectError

from .blockers import lane_blockers
from .feasibility import MotionPlanner, PlannerParams, PlanningError
from .relocation import Progress, recover, relocate
from .scene_update import merge_perceived
from .streaming import Aborted, Cancelled, StreamedArm

STATE_WAIT = 5.0  # s a relocation waits for the first joint state (discovery of the driver right after start-up)


@dataclass(frozen=True)
class Outcome:
    """How a relocation goal ended: status 'succeeded', 'canceled' or 'aborted', and the result's message."""

    status: str
    message: str


class MotionPlannerService:
    """The node's behaviour (the module docstring). `home_tol`: relocation.relocate's (rad)."""

    def __init__(self, scenario: Scenario, params: PlannerParams, home_tol: float = 0.05,
                 log: Callable[[str, str], None] = lambda *_: None) -> None:
        self.base, self.log, self.home_tol = scenario, log, home_tol
        self.planner = MotionPlanner(scenario, params)
        self.plan_lock = threading.Lock()  # MotionPlanner is not thread-safe
        self.bottles = {b.id: b for b in scenario.objects}
        self.relocated: dict[str, int] = {}  # object -> slot, relocated by this node (until seen on the top shelf)
        self._held: str | None = None  # the object of the running relocation: its perceived pose is ignored
        self._relocating = threading.Lock()

    # -- the scene ------------------------------------------------------------------------------------------
    def update_scene(self, perceived: Iterable[tuple[Bottle, float]]) -> list[str]:
        """Bottles standing on the top shelf, as (bottle, base height) pairs, replace the planner's; the rest of the
        scene stays. The ids that changed; ScenarioError for a scene that cannot be (nothing changes then)."""
        merged, changed, seen = merge_perceived(self.base.shelf, self.bottles, list(perceived), self._held)
        for i in seen:  # seen back on the top shelf (a reset scene): it can be relocated again
            self.relocated.pop(i, None)
        if changed:
            scenario = self.base.with_objects(merged.values())
            with self.plan_lock:
                self.planner.set_scenario(scenario)
                self.bottles = merged
        return changed

    # -- feasibility (Eq. 11) -------------------------------------------------------------------------------
    def feasibility(self, object_id: str, removed: Iterable[str], timeout: float = 0.0,
                    all_lanes: bool = False) -> tuple[dict[str, tuple[BlockerSet, ...]], FeasibilityAnswer | None]:
        """(every lane's blockers with `removed` gone if `all_lanes`, else {}; the answer for `object_id`, None when
        all_lanes and no object is asked). `timeout` <= 0: the planner's. UnknownObjectError, ScenarioError,
        ValueError, TypeError for a bad question; SafetyNetTimeout when the wall-clock safety net ran out."""
        if not math.isfinite(timeout):
            raise ValueError(f"timeout must be a finite number of seconds (<= 0: the default), got {timeout}")
        removed = list(removed)
        with self.plan_lock:
            lanes = lane_blockers(self.planner, removed) if all_lanes else {}
            answer = None if all_lanes and not object_id else self.planner.feasibility(
                object_id, removed, float(timeout) if timeout > 0 else None)
        return lanes, answer

    # -- relocation -----------------------------------------------------------------------------------------
    def check_goal(self, object_id: str, removed_ids: Iterable[str]) -> None:
        """Why a RelocateObject goal cannot be accepted (UnknownObjectError, ScenarioError, ValueError), or None."""
        removed_ids = list(removed_ids)
        self.planner.scenario.object(object_id)
        removed = self.planner.scenario.check_ids(removed_ids)
        if object_id in removed:
            raise ValueError(f"{object_id!r} is in its own removed set")
        if object_id in self.relocated:  # it stands on the bottom shelf now: nothing to pick up there
            raise ValueError(f"{object_id!r} was already relocated (to slot {self.relocated[object_id]})")
        if len(removed_ids) >= len(self.base.slots):
            raise ValueError(f"no free slot: {len(removed_ids)} objects already relocated")
        if self._relocating.locked():
            raise ValueError("a relocation is already running")

    def relocate(self, arm: StreamedArm, object_id: str, removed_ids: Iterable[str]) -> Outcome:
        """Relocate `object_id` to slot len(removed_ids) with `arm`; after a failure or a cancel, recover (the
        result message says what was done). Never raises: a bug ends the goal with its reason, not the node."""
        removed_ids = list(removed_ids)
        progress = Progress()
        with self._relocating:
            self._held = object_id
            try:
                arm.wait_for_state(STATE_WAIT)
                relocate(self.planner, arm, object_id, removed_ids, home_tol=self.home_tol, lock=self.plan_lock,
                         progress=progress)
                self.relocated[object_id] = len(removed_ids)
                return Outcome("succeeded", f"relocated {object_id}")
            except Cancelled:
                arm.stop()
                return Outcome("canceled", "cancelled: arm stopped" + self._recover(arm, progress))
            except Exception as e:  # planning, the arm, bad input; a bug ends the goal with its reason, not the node
                arm.stop()
                known = isinstance(e, (Aborted, PlanningError, UnknownObjectError, ValueError))
                message = str(e) if known else f"internal error: {type(e).__name__}: {e}"
                self.log("error", f"relocation of {object_id} aborted: {message}")
                return Outcome("aborted", message + self._recover(arm, progress))
            finally:
                self._held = None

    def _recover(self, arm: StreamedArm, progress: Progress) -> str:
        """After a failed or cancelled goal: relocation.recover (the bottle set down where it was picked, the arm
        home), not cancellable itself; unless the node is shutting down. The text added to the result message."""
        if not arm.link.ok() or not progress.moves:
            return ""
        arm = arm.uncancellable()
        try:
            arm.measured()  # a driver that is gone: fail now, not after the gripper's timeout
            what = recover(self.planner, arm, progress, self.plan_lock)
        except Exception as e:
            self.log("error", f"recovery after the failed relocation failed: {e}")
            return f"; recovery failed: {e}"
        self.log("info", f"recovered: {what}")
        if progress.released:
            self.relocated[progress.object_id] = len(progress.removed)
        return f"; recovered: {what}"
