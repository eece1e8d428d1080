"""The motion planner (paper Sect. 4.1): the feasibility oracle of the Q-Tree (Eq. 11) and the motions of a
relocation, behind one class. `MotionPlanner` is the planning context (context.py: the scene, the robot's models,
the question's random generator) with the phases as its methods:

- `feasibility` / `certify` / `plan_pick` (pick.py): home -> pre-grasp -> grasp, the answer g_U / g_O / g_T;
  certified (`certify`, the executed pick, every answer with certify_relocation) a pick counts only if the rest of
  its relocation plans (certify.py);
- `plan_carry` (carry.py): lift, out of the shelf, in to the slot, release, retreat;
- `push_feasibility` (push.py): a push of a standing or lying cylinder, or a box, out of another object's grasp lanes;
- `plan_home` (home.py): back to the home configuration;
- the scene: `set_scenario`, `update_object` (bottles as perceived), `slot_problems`, `lane_blockers`; `what_if`, a
  planner on this scene with some objects elsewhere (what would follow a push).
"""
from __future__ import annotations

import dataclasses
import math
from typing import Iterable, Mapping

import numpy as np

from relocation_common import robot_description as rd
from relocation_common.feasibility import BlockerSet, FeasibilityAnswer
from relocation_common.scenario import Scenario
from stpik_motion_planner.model.blockers import lane_blockers
from stpik_motion_planner.model.collision import Lying, ObstacleSet
from stpik_motion_planner.model.grasp import WorkspaceError, check_pose, place_poses
from stpik_motion_planner.model.push import moved as moved_to
from stpik_motion_planner.planning import carry, home, pick, push
from stpik_motion_planner.planning.context import Placed, PlanningContext
from stpik_motion_planner.planning.params import PlannerParams
from stpik_motion_planner.planning.results import Segment
from stpik_motion_planner.planning.trajectory import Trajectory


class MotionPlanner(PlanningContext):
    """Answers the feasibility oracle of qtree_task_planner (Eq. 11) and plans the relocation motions; `params`
    default: config/motion_planner.yaml."""

    def __init__(self, scenario: Scenario, params: PlannerParams | None = None) -> None:
        super().__init__(scenario, params)
        self._what_if: tuple[tuple[tuple[str, float, float], ...], MotionPlanner] | None = None  # `what_if`'s last
        if scenario.auto_slots:  # `slots: auto` must give slots the arm reaches (explicit ones: per relocation)
            bad = self.slot_problems()
            if bad:
                raise WorkspaceError(f"{scenario.source}: slots 'auto' gives {len(bad)} slot(s) out of the arm's "
                                     f"reach; list reachable slots in the scenario. First: {bad[0]}")

    # ---------------------------------------------------------------- the phases
    def feasibility(self, object_id: str, removed: Iterable[str] = frozenset(),
                    timeout: float | None = None) -> FeasibilityAnswer:
        """Eq. 11's answer with the home -> grasp trajectory (pick.feasibility); SafetyNetTimeout when the wall-clock
        `timeout` (default params.timeout) ran out before the work budget (no answer)."""
        return pick.feasibility(self, object_id, removed, timeout)

    def certify(self, object_id: str, removed: Iterable[str] = frozenset(),
                timeout: float | None = None) -> FeasibilityAnswer:
        """The certify question (relocation_common.feasibility.CertifyingOracle): Eq. 11's answer whose pick counts
        only if the carry to slot len(removed), the retreat and the way home plan from its grasp (certify.py); the
        lane an execution's plan_pick takes. Errors as `feasibility`."""
        return pick.feasibility(self, object_id, removed, timeout, certify=True)

    def push_feasibility(self, object_id: str, clear_for: str, removed: Iterable[str] = frozenset(),
                         timeout: float | None = None) -> tuple[FeasibilityAnswer, push.PushPlan | None]:
        """A push of `object_id` out of the grasp lanes of `clear_for` (push.py): g_O with the whole motion (home to
        home) and its plan (the predicted end pose), or g_U with the reason and None. Errors as `feasibility`."""
        return push.push_feasibility(self, object_id, clear_for, removed, timeout)

    def plan_pick(self, object_id: str, removed: Iterable[str] = frozenset()) -> list[Segment]:
        """Home -> pre-grasp -> grasp, then close the gripper (pick.plan_pick). PlanningError if unfeasible."""
        return pick.plan_pick(self, object_id, removed)

    def plan_carry(self, object_id: str, removed: Iterable[str], slot_index: int, q_start: object = None,
                   placed: Placed | None = None) -> list[Segment]:
        """From the grasp (q_start, default: the end of the last plan_pick/feasibility of this object and set,
        planned if there is none): lift, out of the shelf, down to the slot on the bottom shelf
        (`scenario.slot(slot_index)`), release ('open'), and retreat to the front of the bottom shelf (carry.py).
        Raises PlanningError naming the stage that failed (a slot or a pose out of reach included, before any
        planning)."""
        removed = self.check_question(object_id, removed)
        carry.carry_goal(self, object_id, slot_index, 0.0)  # the slot and its poses checked before any planning
        if q_start is None:
            q_start = self.pick_end.get((object_id, removed))
            if q_start is None:
                q_start = self.plan_pick(object_id, removed) and self.pick_end[(object_id, removed)]
        goal = carry.carry_goal(self, object_id, slot_index, self.grasp_yaw(q_start))  # the face held
        return carry.plan_carry(self, object_id, removed, goal, q_start, placed)

    def plan_home(self, q_from: object, removed: Iterable[str] = frozenset(),
                  placed: Placed | None = None) -> Trajectory:
        """From q_from back to Q_HOME (home.plan_home)."""
        return home.plan_home(self, q_from, removed, placed)

    def plan_joint(self, q_from: object, q_to: object, obs: ObstacleSet, max_checks: int, deadline: float,
                   margin: float = 0.005, rng: np.random.Generator | None = None) -> Trajectory | None:
        """RRT-Connect in joint space with the planner's collision checker (home.plan_joint)."""
        return home.plan_joint(self, q_from, q_to, obs, max_checks, deadline, margin, rng)

    # ---------------------------------------------------------------- the scene
    def lane_blockers(self, removed: Iterable[str] = frozenset()) -> dict[str, tuple[BlockerSet, ...]]:
        """Every object's grasp-lane blockers at once (blockers.lane_blockers: the screen only, no planning)."""
        return lane_blockers(self, removed)

    def slot_problems(self) -> list[str]:
        """Why some of the scenario's slots cannot take a bottle (empty if all can): not on the bottom shelf with room
        for the open hand beside it, or the place or staging pose of a graspable bottle of any size in the scene out
        of the arm's reach (grasp.check_pose)."""
        sc, p = self.scenario, self.params
        s = sc.shelf
        hand = max(abs(c.p1[0]) + c.radius for c in rd.CAPSULES if c.name.startswith("finger"))
        sizes: dict[tuple[float, float], str] = {}
        for b in sc.objects:
            if not self.not_graspable(b.id):  # never carried (a lying bottle, a wide box...): never placed
                sizes.setdefault((b.upright_radius, b.height), b.id)
        out = []
        for k, (x, y) in enumerate(sc.slots):
            where = f"slot {k} {(round(x, 3), round(y, 3))}"
            r = max((rad for rad, _ in sizes), default=0.0)
            if not (s.x_front + r <= x <= s.x_back - r):
                out.append(f"{where} is not on the bottom shelf (x {s.x_front:.2f}-{s.x_back:.2f})")
                continue
            if not (s.y_min + hand + p.stpik.clearance <= y <= s.y_max - hand - p.stpik.clearance):
                out.append(f"{where}: no room for the open hand ({hand:.3f} m beside the axis) before a side panel")
                continue
            for oid in sizes.values():
                try:
                    _, release = self.carry_heights(oid)
                except WorkspaceError:
                    continue  # a bottle that cannot be carried at all is answered UNFEASIBLE, not placed
                try:
                    box = sc.object(oid).shape == "box"
                    for yaw in self.all_yaws(oid) if box else [0.0]:  # a box: each face it may be held by
                        stage, _ = place_poses(sc, oid, (x, y), release, p.stage_distance, yaw,
                                               self.grasp_pitch(oid))
                        check_pose(stage, f"staging pose of {oid} for {where}")
                except WorkspaceError as e:
                    out.append(str(e))
                    break
        return out

    def set_scenario(self, scenario: Scenario, lying: Mapping[str, Lying] | None = None,
                     gone: Iterable[str] = ()) -> None:
        """Replace the scene (same shelf; e.g. bottles as perceived): `lying`, the bottles of the top shelf that lean,
        neither standing nor lying flat (scene_update.lying_pose: obstacles as the cylinders they are, never
        graspable); `gone`, those that left the shelf (no
        obstacle, never graspable). Cached grasp ends and STPIK checks are dropped."""
        self.scenario = scenario
        self.lying, self.gone = dict(lying or {}), frozenset(gone)
        self.scene = self.collision_scene()
        self.pick_end.clear()
        self.pick_near.clear()
        self.stage_refs.clear()
        self.certified.clear()
        self.near_cache.clear()
        self._what_if = None
        if self.stpik.memo is not None:
            self.stpik.memo.clear()

    def what_if(self, moved: Mapping[str, tuple[float, float]], removed: Iterable[str] = ()) -> "MotionPlanner":
        """A planner on this scene with each object of `moved` at the given (x, y) on the top shelf, turned and
        standing or lying as it is (a push slides it: its predicted end, docs/motion_planner.md "What would follow a
        push"); this one for an empty `moved`. This planner and its caches are unchanged; the last what-if planner
        is kept (its own caches) until this scene or `moved` changes. UnknownObjectError for an id the scene does
        not have; WorkspaceError for a position not finite, an object gone, or an outline off the top shelf or
        overlapping that of an object not in `removed` (the question's removed set)."""
        key = tuple(sorted((str(i), float(x), float(y)) for i, (x, y) in moved.items()))
        if not key:
            return self
        if self._what_if is None or self._what_if[0] != key:
            sc, s = self.scenario, self.scenario.shelf
            for oid, x, y in key:
                o = sc.object(oid)
                if not (math.isfinite(x) and math.isfinite(y)):
                    raise WorkspaceError(f"moved position of {oid!r} must be finite, got {(x, y)}")
                if oid in self.gone or not dataclasses.replace(o, x=x, y=y).footprint().inside(
                        s.x_front, s.x_back, s.y_min, s.y_max):
                    raise WorkspaceError(f"{oid!r} moved to ({x:.3f}, {y:.3f}) is not on the top shelf")
                sc = moved_to(sc, oid, x, y)
            planner = MotionPlanner(sc, self.params)
            planner.set_scenario(sc, self.lying, self.gone)
            self._what_if = (key, planner)
        planner = self._what_if[1]
        absent = self.gone | set(removed)
        present = [o for o in planner.scenario.objects if o.id not in absent]
        for oid, x, y in key:
            outline = planner.scenario.object(oid).footprint()
            hit = [o.id for o in present if o.id != oid and outline.overlaps(o.footprint())]
            if hit:
                raise WorkspaceError(f"{oid!r} moved to ({x:.3f}, {y:.3f}) overlaps {', '.join(hit)}")
        return planner

    def update_object(self, object_id: str, x: float, y: float) -> None:
        """Move a bottle (e.g. from perception); NaN, off-shelf or unknown ids raise."""
        b = self.scenario.object(object_id)
        if not (math.isfinite(x) and math.isfinite(y)):
            raise WorkspaceError(f"position of {object_id!r} must be finite, got {(x, y)}")
        s = self.scenario.shelf
        if not (s.x_front + b.radius <= x <= s.x_back - b.radius and s.y_min + b.radius <= y <= s.y_max - b.radius):
            raise WorkspaceError(f"{object_id!r} at {(x, y)} is not on the top shelf")
        objs = tuple(dataclasses.replace(o, x=x, y=y) if o.id == object_id else o for o in self.scenario.objects)
        self.set_scenario(dataclasses.replace(self.scenario, objects=objs, _by_id={}), self.lying, self.gone)
