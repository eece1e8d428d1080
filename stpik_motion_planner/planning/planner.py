"""The feasibility question of the Q-Tree answered by the motion planner (paper Sect. 4.1 and Eq. 11).

feasibility(i, removed): 1) action to pose: side grasp and pre-grasp of object i for a few approach yaws;
2) RRT-Connect (OMPL) in Cartesian space for the tool from its home pose to the pre-grasp, keeping the hand clear
of the bottles still there; then the straight approach to the grasp; 3) STPIK check (Eq. 9-10) tracking that path;
a rejected path is re-sampled up to max_attempts times. 4) label g_U / g_O / g_T, planning time,
attempts and the joint trajectory (100 Hz, Q convention, within Table 7).
plan_pick / plan_carry / plan_home give the executor the whole relocation: grasp, lift, out of the shelf, down to
the slot on the bottom shelf, release, retreat, home.

Budgets are work, not time: validity checks per RRT-Connect attempt (rrt_max_checks), IK steps per STPIK check
(stpik.step_budget), attempts per query (max_attempts); so a question gets the same answer on an idle and on a
loaded machine. `timeout` / `carry_timeout` are wall-clock safety nets only: reached first, the query raises
SafetyNetTimeout (no answer; never g_U, so no cache keeps it).
"""
from __future__ import annotations

import dataclasses
import hashlib
import math
import time
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any, Iterable, Mapping, Sequence

import numpy as np

from relocation_common import robot_description as rd
from relocation_common.config import node_section
from relocation_common.feasibility import BlockerSet, FeasibilityAnswer, Label
from relocation_common.paths import config_file
from relocation_common.scenario import Scenario, UnknownObjectError
from relocation_common.shelf_object import objects_key
from stpik_motion_planner.model.blockers import answer_blockers, lane_blockers
from stpik_motion_planner.model.collision import (
    CARRIED,
    HAND_PARTS,
    PENETRATION,
    ArmGeometry,
    CollisionScene,
    HandProxy,
    Lying,
    ObstacleSet,
    carried_bottle,
)
from stpik_motion_planner.model.grasp import (
    Grasp,
    WorkspaceError,
    carry_heights,
    check_pose,
    exit_pose,
    grasp_standoff,
    home_pose,
    place_poses,
    side_grasp,
    yaw_tiers,
)
from stpik_motion_planner.model.kinematics import Kinematics
from stpik_motion_planner.planning.budget import SafetyNetTimeout  # noqa: F401 (for callers)
from stpik_motion_planner.planning.rrt import CartesianRRT, JointRRT, seed_ompl
from stpik_motion_planner.planning.stpik import Stpik, StpikParams, StpikResult
from stpik_motion_planner.planning.trajectory import Trajectory

START_RELIEF = 0.0005  # m: margin under a tight start's distance (_carried_models, _carried_hand)
WHOLE_NUMBERS = ("max_attempts", "n_yaws", "wide_yaws", "seed", "rrt_max_checks", "simplify_checks")
# left out of question_rng's seed: the safety nets (wall clock), and the second yaw tier's settings, so that the
# first tier's draws, and every answer it gives, are those of a planner without the second tier; the grasp's yaw
# tolerance (stpik.*), so that every path that converged without it is drawn and ends as before
UNSEEDED = ("timeout", "carry_timeout", "wide_yaws", "wide_max_yaw")
UNSEEDED_STPIK = ("grasp_yaw_tol",)


class PlanningError(RuntimeError):
    """A pick, carry or home motion that could not be planned (the message says which stage failed)."""


@dataclass
class PlannerParams:
    """The motion planner's settings (config/motion_planner.yaml, docs/motion_planner.md), validated once."""

    seed: int = 7
    timeout: float = 30.0  # s: wall-clock safety net per feasibility query (the service may pass its own)
    rrt_max_checks: int = 4000  # validity checks per RRT-Connect attempt (about 80 ms here, idle)
    max_attempts: int = 6  # sampled paths per query before answering g_U
    n_yaws: int = 3  # approach yaws tried: 0, +max_yaw, -max_yaw, ...
    max_yaw: float = 0.35  # rad
    wide_yaws: int = 0  # the second tier (grasp.yaw_tiers), tried when the first found nothing; 0: none
    wide_max_yaw: float = 0.8  # rad
    pre_grasp_distance: float = 0.11  # m back along the approach
    hand_margin: float = 0.012  # m: inflation of the hand proxy in the Cartesian planner
    resolution: float = 0.01  # m: motion checking resolution of the Cartesian planner
    joint_resolution: float = 0.01  # rad: of the joint-space planner
    simplify_checks: int = 250  # validity checks of OMPL path simplification (0: none)
    lift: float = 0.03  # m, after the grasp (at least carried_clearance + stpik.act: grasp.carry_heights)
    drop: float = 0.012  # m, bottle base above the bottom shelf at release (at most half the room: carry_heights)
    carried_clearance: float = 0.005  # m, the carried bottle (real size) to boards and bottles
    carry_ramp: float = 0.25  # s to full speed and to a stop at each waypoint of the carry and retreat (0: none)
    carry_accel: float = 3.0  # rad/s^2, joint accelerations while a bottle is held (0: no limit)
    stage_distance: float = 0.15  # m, staging pose in front of the slot (at most x_front - 0.07: grasp.place_poses)
    carry_timeout: float = 60.0  # s: wall-clock safety net of plan_pick / plan_carry / plan_home
    direct_first: bool = True  # try home -> front of shelf -> pre-grasp before sampling with RRT-Connect
    seed_per_query: bool = False  # every OMPL solve seeded from the question (question_rng), not process history
    screen_at_clearance: bool = False  # the grasp screen's hand proxy inflated by at least stpik.clearance
    certify_relocation: bool = False  # a feasible pick counts only if the carry, retreat and way home plan from it
    workspace_lo: tuple = (0.05, -0.55, -0.10, -0.9)  # (x, y, z, yaw) box of the Cartesian planner
    workspace_hi: tuple = (1.0, 0.55, 0.65, 0.9)
    stpik: StpikParams = field(default_factory=StpikParams)

    def __post_init__(self) -> None:
        """Every setting checked once, with its name in the error (ValueError)."""
        positive = ("timeout", "pre_grasp_distance", "resolution", "joint_resolution",
                    "stage_distance", "carry_timeout", "carried_clearance")
        non_negative = ("max_yaw", "wide_max_yaw", "hand_margin", "lift", "drop", "carry_ramp", "carry_accel")
        for k in positive + non_negative:
            v = getattr(self, k)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) \
                    or v < 0 or (v == 0 and k in positive):
                raise ValueError(f"motion planner parameter {k} must be a finite number "
                                 f"{'> 0' if k in positive else '>= 0'}, got {v!r}")
        for k in WHOLE_NUMBERS:
            v, least = getattr(self, k), {"seed": None, "simplify_checks": 0, "wide_yaws": 0}.get(k, 1)
            if isinstance(v, bool) or not isinstance(v, int) or (least is not None and v < least):
                raise ValueError(f"motion planner parameter {k} must be an integer"
                                 f"{'' if least is None else f' >= {least}'}, got {v!r}")
        lo, hi = (np.asarray(getattr(self, k), float) for k in ("workspace_lo", "workspace_hi"))
        if lo.shape != (4,) or hi.shape != (4,) or not np.all(np.isfinite(lo) & np.isfinite(hi) & (lo < hi)):
            raise ValueError(f"motion planner parameters workspace_lo < workspace_hi must be 4 finite numbers each "
                             f"(x, y, z, yaw), got {self.workspace_lo!r}, {self.workspace_hi!r}")

    @classmethod
    def keys(cls) -> tuple[str, ...]:
        """The flat parameter names (ROS parameters): the planner's own and stpik.* for StpikParams."""
        return tuple(f.name for f in fields(cls) if f.name != "stpik") + tuple(
            f"stpik.{f.name}" for f in fields(StpikParams))

    @classmethod
    def from_mapping(cls, data: Mapping[str, Any]) -> "PlannerParams":
        """From a flat mapping (ROS parameters); stpik.* keys go to StpikParams. Unknown keys are an error."""
        own = {f.name for f in fields(cls)} - {"stpik"}
        sp = {f.name for f in fields(StpikParams)}
        kw: dict[str, Any] = {}
        skw: dict[str, Any] = {}
        for k, v in data.items():
            if k.startswith("stpik.") and k[6:] in sp:
                skw[k[6:]] = v
            elif k in own:
                kw[k] = tuple(float(x) for x in v) if isinstance(v, (list, tuple)) else v
            else:
                raise ValueError(f"motion planner parameter {k!r} is unknown; known: {sorted(own)} and stpik.*")
        for k in WHOLE_NUMBERS:  # whole numbers only
            if isinstance(kw.get(k), float) and kw[k].is_integer():
                kw[k] = int(kw[k])
        for k in ("direct_first", "seed_per_query", "screen_at_clearance", "certify_relocation"):
            if k in kw and not isinstance(kw[k], bool):
                raise ValueError(f"motion planner parameter {k} must be true or false, got {kw[k]!r}")
        return cls(**kw, stpik=StpikParams(**skw))

    @classmethod
    def load(cls, path: str | Path | None = None) -> "PlannerParams":
        """The planner's keys of a ROS params file (default config/motion_planner.yaml). Keys the shipped file gives
        the motion_planner node for itself are skipped; any other unknown key is an error. ValueError naming the
        file on malformed YAML, a wrong layout or a bad value."""
        shipped = config_file("motion_planner.yaml")
        path = path if path is not None else shipped
        section = node_section(path, "motion_planner")
        node_keys = set(node_section(shipped, "motion_planner")) - set(cls.keys())
        try:
            return cls.from_mapping({k: v for k, v in section.items() if k not in node_keys})
        except (TypeError, ValueError) as e:
            raise ValueError(f"{path}: {e}") from None


@dataclass
class Segment:
    """One continuous motion of a relocation and the gripper action after it ('close', 'open' or None)."""

    name: str
    trajectory: Trajectory
    gripper_after: str | None = None


@dataclass
class QueryStats:
    """Where one query spent its work (RRT-Connect, STPIK) and STPIK's rejections."""

    rrt_time: float = 0.0
    stpik_time: float = 0.0
    rrt_calls: int = 0
    direct_paths: int = 0
    stpik_reject: list = field(default_factory=list)


class MotionPlanner:
    """Answers the feasibility oracle of qtree_task_planner (Eq. 11) and plans the relocation motions."""

    def __init__(self, scenario: Scenario, params: PlannerParams | None = None) -> None:
        self.scenario = scenario
        self.params = params or PlannerParams()
        seed_ompl(self.params.seed)
        self.kin = Kinematics()
        self.lying: dict[str, Lying] = {}  # bottles of the top shelf that do not stand (set_scenario)
        self.gone: frozenset[str] = frozenset()  # bottles that left the shelf
        self.scene = self._collision_scene()
        self.arm = ArmGeometry(self.kin)
        p = self.params
        self.stpik = Stpik(self.kin, self.arm, p.stpik)
        # the screen (and the Cartesian planner) keep STPIK's own bound when screen_at_clearance: a lane reported
        # clear is then clear for the fingers STPIK drives to the grasp (docs/motion_planner.md, "Blockers")
        self.hand_margin = max(p.hand_margin, p.stpik.clearance) if p.screen_at_clearance else p.hand_margin
        self.hand = HandProxy(self.hand_margin)
        self.rrt = CartesianRRT(p.workspace_lo, p.workspace_hi, p.resolution, p.simplify_checks)
        self.home = np.array(home_pose())
        self.last_stats = QueryStats()
        self._pick_end: dict[tuple[str, frozenset], np.ndarray] = {}
        self._stage_refs: dict[tuple, list[np.ndarray] | None] = {}
        if scenario.auto_slots:  # `slots: auto` must give slots the arm reaches (explicit ones: per relocation)
            bad = self.slot_problems()
            if bad:
                raise WorkspaceError(f"{scenario.source}: slots 'auto' gives {len(bad)} slot(s) out of the arm's "
                                     f"reach; list reachable slots in the scenario. First: {bad[0]}")

    # ---------------------------------------------------------------- input checks
    def _check(self, object_id: str, removed: Iterable[str]) -> frozenset[str]:
        if not isinstance(object_id, str):
            raise UnknownObjectError(f"object id must be a string, got {object_id!r}")
        self.scenario.object(object_id)
        if isinstance(removed, str):
            raise TypeError("removed must be a collection of ids, not a string")
        removed = self.scenario.check_ids(removed)
        if object_id in removed:
            raise ValueError(f"object {object_id!r} is in the removed set: it is no longer on the shelf")
        return removed

    def _carry_heights(self, object_id: str) -> tuple[float, float]:
        """(lift, release height) of the object carried at its real size (grasp.carry_heights); WorkspaceError if
        it is too tall for the compartments."""
        p = self.params
        return carry_heights(self.scenario, object_id, p.carried_clearance + p.stpik.act, p.lift, p.drop)

    def _carried_models(self, b, q_start, obs: ObstacleSet, support: dict):
        """(carried bottle, arm holding it out of the shelf, arm holding it in to the slot). The bottle is modelled
        on the hand where the tool stopped at the grasp (STPIK's final tolerance, up to 4 mm from the bottle's
        perceived place); where that model stands closer to a neighbour than `carried_clearance`, the lift and
        the way out keep that start distance less START_RELIEF (less half of it under 2 x START_RELIEF: the bound
        never allows contact) as the bound, whatever it is (a model in contact within the perception and STPIK
        tolerances included): lifted straight up and then drawn back, the bottle
        may never come closer to anything than it already stood, and STPIK checks that it does not. Otherwise the
        start would fail the bound at once and the pick would be refused for the model's offset. A model that
        penetrates a neighbour at the start (no distance to keep) keeps the full bound: refused."""
        p = self.params
        carried = carried_bottle(b.radius, b.height, grasp_standoff(b.radius), p.carried_clearance)
        arm_c = ArmGeometry(self.kin, [carried])
        self.kin.update(q_start, jacobians=False)
        arm_c.pose()
        near = [d for i, _, d, _, _ in arm_c.obstacle_distances(obs, p.carried_clearance, support)
                if arm_c.specs[i].name == CARRIED]
        gap = min(near, default=math.inf)
        if gap >= p.carried_clearance or gap == PENETRATION:
            return carried, arm_c, arm_c
        start = carried_bottle(b.radius, b.height, grasp_standoff(b.radius), gap - min(START_RELIEF, gap / 2))
        return carried, ArmGeometry(self.kin, [start]), arm_c

    def _carried_hand(self, carried, lifted, obs: ObstacleSet, floor: float) -> HandProxy:
        """The Cartesian planner's hand proxy holding the bottle, inflated by its clearance bound plus STPIK's
        activation band, or less where the lifted start is closer than that to a neighbour (in steps of
        START_RELIEF, down to `floor`, the bound STPIK keeps on the way out): a start inside the inflation left
        RRT-Connect and the direct path no valid start ("no Cartesian path out of the shelf") although the
        bottle then moves away."""
        p = self.params
        full = p.carried_clearance + p.stpik.act
        for m in np.arange(full, floor - 1e-9, -START_RELIEF):
            hand = HandProxy(p.hand_margin, [carried], attached_margin=float(m))
            if not hand.collides(*_mat(lifted), obs):
                return hand
        return HandProxy(p.hand_margin, [carried], attached_margin=full)

    def lane_blockers(self, removed: Iterable[str] = frozenset()) -> dict[str, tuple[BlockerSet, ...]]:
        """Every object's grasp-lane blockers at once (blockers.lane_blockers: the screen only, no planning)."""
        return lane_blockers(self, removed)

    def slot_problems(self) -> list[str]:
        """Why some of the scenario's slots cannot take a bottle (empty if all can): not on the bottom shelf with room
        for the open hand beside it, or the place or staging pose of a bottle of any size in the scene out of the
        arm's reach (grasp.check_pose)."""
        sc, p = self.scenario, self.params
        s = sc.shelf
        hand = max(abs(c.p1[0]) + c.radius for c in rd.CAPSULES if c.name.startswith("finger"))
        sizes: dict[tuple[float, float], str] = {}
        for b in sc.objects:
            sizes.setdefault((b.radius, b.height), b.id)
        out = []
        for k, (x, y) in enumerate(sc.slots):
            where = f"slot {k} {(round(x, 3), round(y, 3))}"
            r = max(rad for rad, _ in sizes)
            if not (s.x_front + r <= x <= s.x_back - r):
                out.append(f"{where} is not on the bottom shelf (x {s.x_front:.2f}-{s.x_back:.2f})")
                continue
            if not (s.y_min + hand + p.stpik.clearance <= y <= s.y_max - hand - p.stpik.clearance):
                out.append(f"{where}: no room for the open hand ({hand:.3f} m beside the axis) before a side panel")
                continue
            for oid in sizes.values():
                try:
                    _, release = self._carry_heights(oid)
                except WorkspaceError:
                    continue  # a bottle that cannot be carried at all is answered UNFEASIBLE, not placed
                try:
                    stage, _ = place_poses(sc, oid, (x, y), release, p.stage_distance)
                    check_pose(stage, f"staging pose of {oid} for {where}")
                except WorkspaceError as e:
                    out.append(str(e))
                    break
        return out

    def _placed_key(self, placed) -> str:
        """The bottles on the bottom shelf as geometry (where, which size), whatever their names: a carry planned
        for a removed set and the same carry in a relocation order see the same scene, so draw the same samples."""
        return repr(sorted((round(x, 4), round(y, 4), self.scenario.object(o).radius, self.scenario.object(o).height)
                           for o, (x, y) in placed))

    def question_rng(self, *question) -> np.random.Generator | None:
        """The random generator of one question (seed_per_query): seeded from a hash of the scene (shelf, bottles,
        slots), the question (object, removed set, and for a carry or home its start and placed bottles) and every
        planner parameter but the wall-clock safety nets; None (OMPL's process-wide RNG) otherwise."""
        if not self.params.seed_per_query:
            return None
        sc = self.scenario
        params = {k: v for k, v in dataclasses.asdict(self.params).items() if k not in UNSEEDED}
        params["stpik"] = {k: v for k, v in params["stpik"].items() if k not in UNSEEDED_STPIK}
        parts = [repr(sc.shelf), objects_key(sc.objects, sc.shelf.top_z), repr(sc.slots),  # objects_key: the seeds
                 repr(sorted(params.items()))]  # of every shipped scene as they were before objects had shapes
        if self.lying or self.gone:  # a standing scene's questions keep their seeds (the committed caches)
            parts += [repr(sorted(self.lying.items())), repr(sorted(self.gone))]
        for x in question:
            if isinstance(x, np.ndarray):
                parts.append(np.round(x, 9).tobytes().hex())
            elif isinstance(x, (set, frozenset)):
                parts.append(repr(sorted(x)))
            else:
                parts.append(repr(x))
        digest = hashlib.sha256("\x1f".join(parts).encode()).digest()
        return np.random.default_rng(int.from_bytes(digest[:16], "little"))

    # ---------------------------------------------------------------- Cartesian validity
    def yaw_tiers(self) -> list[list[float]]:
        """The approach yaws, tier by tier (grasp.yaw_tiers)."""
        p = self.params
        return yaw_tiers(p.n_yaws, p.max_yaw, p.wide_yaws, p.wide_max_yaw)

    def all_yaws(self) -> list[float]:
        """Every approach yaw of both tiers, in the order they are tried (the lanes of blockers.py)."""
        return [y for tier in self.yaw_tiers() for y in tier]

    def _candidates(self, object_id: str, obs: ObstacleSet, yaws: list[float] | None = None) -> list[Grasp]:
        """Grasps (of `yaws`, default every tier's) whose pre-grasp and straight approach are clear for the hand
        (the target excluded for the palm and fingers on the approach only)."""
        skip = {n: frozenset([object_id]) for n in HAND_PARTS}
        out = []
        for yaw in self.all_yaws() if yaws is None else yaws:
            try:
                g = side_grasp(self.scenario, object_id, yaw, self.params.pre_grasp_distance)
            except WorkspaceError:
                if yaw == 0.0:
                    raise
                continue
            if not self.rrt.contains(g.pre_grasp):
                continue
            if self.hand.collides(*_mat(g.pre_grasp), obs):
                continue
            if self.hand.path_clear([g.pre_grasp, g.grasp], obs, self.params.resolution, skip):
                out.append(g)
        return out

    def _stage(self, pose) -> np.ndarray:
        """In front of the shelf at the height and lateral position of `pose` (the start of a direct entry)."""
        x = min(pose[0], self.scenario.shelf.x_front - 0.06)
        return np.array([x, pose[1] - (pose[0] - x) * math.tan(pose[3]), pose[2], pose[3]])

    def _cartesian_path(self, start, goal, obs: ObstacleSet, hand: HandProxy, max_checks: int, deadline: float,
                        stats: QueryStats, first: bool, rng=None) -> list[np.ndarray] | None:
        """First attempt: the direct path start -> stage in front of the shelf -> goal, if clear; otherwise and on
        later attempts RRT-Connect."""
        if first and self.params.direct_first:
            direct = [np.asarray(start, float), self._stage(goal), np.asarray(goal, float)]
            if hand.path_clear(direct, obs, self.params.resolution):
                stats.direct_paths += 1
                return direct
        t = time.perf_counter()
        path = self.rrt.plan(start, goal, lambda s: not hand.collides(*_mat(s), obs), max_checks, deadline,
                             _draw_seed(rng))
        stats.rrt_time += time.perf_counter() - t
        stats.rrt_calls += 1
        return path

    def _track(self, q0, path, obs, deadline, stats, skip=None, arm: ArmGeometry | None = None,
               speed: float | None = None, ramp: float = 0.0, accel: float = 0.0, yaw_tol: float = 0.0
               ) -> StpikResult:
        t = time.perf_counter()
        stpik = self.stpik if arm is None else Stpik(self.kin, arm, self.params.stpik)
        r = stpik.track(q0, path, obs, deadline, skip, speed=speed, ramp=ramp, accel=accel, yaw_tol=yaw_tol)
        stats.stpik_time += time.perf_counter() - t
        if not r.ok:
            stats.stpik_reject.append(r.reason)
        return r

    # ---------------------------------------------------------------- feasibility (Eq. 11)
    def feasibility(self, object_id: str, removed: Iterable[str] = frozenset(),
                    timeout: float | None = None) -> FeasibilityAnswer:
        """g_T / g_O with the home -> pre-grasp -> grasp trajectory (100 Hz) if a path passes the STPIK check,
        g_U otherwise. Raises UnknownObjectError / ValueError / WorkspaceError on bad input, SafetyNetTimeout when
        the wall-clock `timeout` (default params.timeout) ran out before the work budget (no answer)."""
        t0 = time.perf_counter()
        removed = self._check(object_id, removed)
        if timeout is not None and not (isinstance(timeout, (int, float)) and math.isfinite(timeout)):
            raise ValueError(f"timeout must be a finite number of seconds, got {timeout!r}")
        budget = self.params.timeout if timeout is None or timeout <= 0 else float(timeout)
        deadline = t0 + budget
        stats = QueryStats()
        self.last_stats = stats
        ok_label = Label.TARGET if object_id == self.scenario.target_id else Label.OBSTACLE
        traj, attempts, msg = self._pick(object_id, removed, deadline, stats)
        dt = time.perf_counter() - t0
        if traj is None:  # with the lane blockers of the refused pick (docs/motion_planner.md, "Blockers")
            return FeasibilityAnswer(Label.UNFEASIBLE, dt, attempts, msg,
                                     blockers=answer_blockers(self, object_id, removed))
        return FeasibilityAnswer(ok_label, dt, attempts, msg, traj)

    def _pick(self, object_id, removed, deadline, stats) -> tuple[Trajectory | None, int, str]:
        """Home -> pre-grasp -> grasp for the yaws of the first tier; if none gave one, for the second
        (yaw_tiers): (trajectory or None, attempts, message). A lying or gone bottle: none (not_graspable)."""
        why = self.not_graspable(object_id)
        if why:
            return None, 0, why
        try:
            self._carry_heights(object_id)
        except WorkspaceError as e:  # it could be grasped but not carried away: not a relocation
            return None, 0, str(e)
        obs = self.scene.obstacles(removed)
        attempts, last = 0, ""
        for tier, yaws in enumerate(self.yaw_tiers()):
            cands = self._candidates(object_id, obs, yaws)
            if not cands:
                continue
            # the first tier's draws are those of a planner without the second (UNSEEDED)
            rng = self.question_rng("pick", object_id, removed, *(["wide"] if tier else []))
            budget = self.params.max_attempts if tier == 0 else max(self.params.max_attempts, len(cands))
            traj, n, last = self._pick_lanes(object_id, removed, obs, cands, budget, rng, deadline, stats)
            attempts += n
            if traj is not None:
                return traj, attempts, last
        if not attempts:
            return None, 0, "no collision-free pre-grasp and approach for any yaw"
        return None, attempts, f"{attempts} attempts failed; last: {last}"

    def _pick_lanes(self, object_id, removed, obs, cands: list[Grasp], budget: int, rng, deadline,
                    stats) -> tuple[Trajectory | None, int, str]:
        """Up to `budget` sampled paths over the grasps `cands` in turn (each one's direct path first):
        (trajectory or None, attempts, the grasp used or the last failure)."""
        p = self.params
        skip = {n: frozenset([object_id]) for n in HAND_PARTS}
        attempts, last = 0, ""
        while attempts < budget:
            g = cands[attempts % len(cands)]
            first = attempts < len(cands)
            attempts += 1
            path = self._cartesian_path(self.home, g.pre_grasp, obs, self.hand, p.rrt_max_checks, deadline, stats,
                                        first, rng)
            if path is None:
                last = f"no Cartesian path to the pre-grasp (yaw {g.yaw:+.2f})"
                continue
            r1 = self._track(rd.Q_HOME, path, obs, deadline, stats)
            if not r1.ok:
                last = f"STPIK rejected the path to the pre-grasp: {r1.reason}"
                continue
            r2 = self._track(r1.q[-1], [np.array(g.pre_grasp), np.array(g.grasp)], obs, deadline, stats, skip,
                             speed=p.stpik.approach_speed, yaw_tol=p.stpik.grasp_yaw_tol)
            if not r2.ok:
                last = f"STPIK rejected the approach: {r2.reason}"
                continue
            if p.certify_relocation:
                why = self._certify(object_id, removed, r2.q[-1])
                if why:
                    last = f"the rest of the relocation: {why}"
                    continue
            traj = Trajectory.from_steps(r1.q, r1.qdot, r1.dt, "to_pre_grasp").then(
                Trajectory.from_steps(r2.q, r2.qdot, r2.dt, "approach")).resample()
            self._pick_end[(object_id, removed)] = r2.q[-1]
            return traj, attempts, f"yaw {g.yaw:+.2f}, {len(path)} waypoints"
        return None, attempts, last

    def _certify(self, object_id: str, removed: frozenset[str], q_grasp) -> str:
        """'' if the rest of the relocation from the grasp q_grasp plans (carry to slot len(removed) with the removed
        bottles in the earlier slots, retreat, way home), else why not (certify_relocation)."""
        k = len(removed)
        try:
            placed = self.placed_default(removed, k)
            _, retreat = self.plan_carry(object_id, removed, k, q_start=q_grasp, placed=placed)
            self.plan_home(retreat.trajectory.positions[-1], removed | {object_id},
                           placed + [(object_id, self.scenario.slot(k))])
        except (PlanningError, WorkspaceError, ValueError) as e:
            return str(e)
        return ""

    # ---------------------------------------------------------------- execution: pick, carry, home
    def plan_pick(self, object_id: str, removed: Iterable[str] = frozenset()) -> list[Segment]:
        """Home -> pre-grasp -> grasp, then close the gripper. Raises PlanningError if unfeasible."""
        removed = self._check(object_id, removed)
        traj, _, msg = self._pick(object_id, removed, time.perf_counter() + self.params.carry_timeout, QueryStats())
        if traj is None:
            raise PlanningError(f"pick of {object_id!r}: {msg}")
        return [Segment("pick", traj, "close")]

    def placed_default(self, removed: frozenset[str], slot_index: int) -> list[tuple[str, tuple[float, float]]]:
        """Bottles assumed on the bottom shelf: the removed ones, in sorted order, in the slots other than
        slot_index."""
        slots = [k for k in range(len(self.scenario.slots)) if k != slot_index]
        return [(oid, self.scenario.slot(k)) for oid, k in zip(sorted(removed), slots)]

    def plan_carry(self, object_id: str, removed: Iterable[str], slot_index: int, q_start=None,
                   placed: list[tuple[str, tuple[float, float]]] | None = None) -> list[Segment]:
        """From the grasp (q_start, default: the end of the last plan_pick/feasibility of this object and set):
        lift, out of the shelf, down to the slot on the bottom shelf (`scenario.slot(slot_index)`), release
        ('open'), and retreat to the front of the bottom shelf.

        The bottle is modelled at its real size on the hand (STPIK's arm geometry and the Cartesian planner's hand
        proxy) with its own clearance bound `carried_clearance`; it may touch only the board it stands on, and only
        while it is lifted straight up off it (`lift` >= carried_clearance + stpik.act, so it clears the board
        before any motion out of the shelf). Then straight back out of the shelf at that height (or RRT-Connect if
        that is blocked), to the staging pose in front of the slot, and straight in at the release height. Raises
        PlanningError naming the stage that failed (a slot or a pose out of reach included)."""
        removed = self._check(object_id, removed)
        what = f"carry of {object_id!r} to slot {slot_index}"
        try:
            slot = self.scenario.slot(slot_index)
            lift, release = self._carry_heights(object_id)
            stage, place = (np.array(x) for x in place_poses(self.scenario, object_id, slot, release,
                                                               self.params.stage_distance))
            check_pose(stage, f"staging pose for slot {slot_index}")
        except (ValueError, WorkspaceError) as e:
            raise PlanningError(f"{what}: {e}") from None
        if q_start is None:
            q_start = self._pick_end.get((object_id, removed))
            if q_start is None:
                q_start = self.plan_pick(object_id, removed) and self._pick_end[(object_id, removed)]
        q_start = _check_q(q_start)
        p = self.params
        deadline = time.perf_counter() + p.carry_timeout
        stats = QueryStats()
        b = self.scenario.object(object_id)
        placed = self.placed_default(removed, slot_index) if placed is None else list(placed)
        scene = self._collision_scene(placed)
        obs = scene.obstacles(removed | {object_id})
        support = {CARRIED: frozenset(["board:top_shelf"])}
        carried, arm_start, arm_c = self._carried_models(b, q_start, obs, support)
        self.kin.update(q_start, jacobians=False)
        rot, pos = self.kin.tool_pose()
        start = np.array([*pos, math.atan2(rot[1, 2], rot[0, 2])])
        lifted = start + np.array([0.0, 0.0, lift, 0.0])
        bound = arm_start.specs[-1].clearance
        hand_c = self._carried_hand(carried, lifted, obs, p.carried_clearance if bound is None else bound)
        # 1. lift straight up: the only leg where the bottle may touch a board, the one it stands on
        up = self._track(q_start, [start, lifted], obs, deadline, stats, skip=support, arm=arm_start,
                         speed=p.stpik.approach_speed, ramp=p.carry_ramp,
                         accel=p.carry_accel)
        if not up.ok:
            raise PlanningError(f"{what}: lift: {up.reason}")
        # 2. out of the shelf at that height, to the staging pose, in to the slot at the release height
        # the bottle and the finger tips in front of the shelf by the arm's clearance (+ activation) before going down
        out = np.array(exit_pose(self.scenario, object_id, lifted,
                                 max(p.hand_margin, p.stpik.clearance + p.stpik.act) + 0.002))
        rng = self.question_rng("carry", object_id, removed, slot_index, q_start, self._placed_key(placed))
        carry = self._carry_legs(up.q[-1], [lifted, out, stage], place, obs, (arm_start, arm_c, hand_c), deadline,
                                 stats, what, rng)
        scene2 = self._collision_scene(placed + [(object_id, slot)])
        obs2 = scene2.obstacles(removed | {object_id})
        skip = {n: frozenset([f"placed:{object_id}"]) for n in HAND_PARTS}
        back = self._track(carry[1].q[-1], [place, stage], obs2, time.perf_counter() + p.carry_timeout, stats,
                           skip=skip, ramp=p.carry_ramp)
        if not back.ok:
            raise PlanningError(f"retreat after placing {object_id!r}: {back.reason}")
        moving = Trajectory.from_steps(up.q, up.qdot, up.dt, "lift").then(
            Trajectory.from_steps(carry[0].q, carry[0].qdot, carry[0].dt, "carry")).then(
            Trajectory.from_steps(carry[1].q, carry[1].qdot, carry[1].dt, "place"))
        return [Segment("carry", moving.resample(), "open"),
                Segment("retreat", Trajectory.from_steps(back.q, back.qdot, back.dt, "retreat").resample(), None)]

    def _carry_legs(self, q_lifted, direct: list, place, obs: ObstacleSet, carried: tuple, deadline: float,
                    stats: QueryStats, what: str, rng=None):
        """plan_carry's legs 2-3 with the bottle held (`carried`: its ArmGeometry out of the shelf and in to the
        slot, and its HandProxy): from the lifted
        pose out of the shelf to the staging pose (the `direct` poses lifted, out, stage first, then RRT-Connect;
        up to max_attempts), then in to the slot at `place`. (out leg, in leg) of STPIK; PlanningError naming the
        last leg that failed."""
        p = self.params
        arm_out, arm_c, hand_c = carried
        lifted, stage = direct[0], direct[-1]
        last = "no Cartesian path out of the shelf"
        mid: list | None
        for attempt in range(p.max_attempts):
            if attempt == 0 and p.direct_first and hand_c.path_clear(direct, obs, p.resolution):
                stats.direct_paths += 1
                mid = direct
            else:
                t = time.perf_counter()
                mid = self.rrt.plan(lifted, stage, lambda s_: not hand_c.collides(*_mat(s_), obs),
                                    4 * p.rrt_max_checks, deadline, _draw_seed(rng))
                stats.rrt_time += time.perf_counter() - t
                stats.rrt_calls += 1
                if mid is None:
                    continue
            r = self._track(q_lifted, mid, obs, deadline, stats, arm=arm_out, ramp=p.carry_ramp, accel=p.carry_accel)
            if not r.ok:
                last = f"out of the shelf: {r.reason}"
                continue
            # in to the slot at approach speed: 10 mm above and below the bottle in the shipped shelf's bottom
            # compartment, and the clearance tasks must not freeze it at the front edge
            r2 = self._track(r.q[-1], [stage, place], obs, deadline, stats, arm=arm_c, speed=p.stpik.approach_speed,
                             ramp=p.carry_ramp, accel=p.carry_accel)
            if r2.ok:
                return r, r2
            last = f"in to the slot: {r2.reason}"
        raise PlanningError(f"{what}: {last}")

    def joint_valid(self, q, obs: ObstacleSet, arm: ArmGeometry | None = None, margin: float = 0.0) -> bool:
        """Joint-space validity with the same collision checker: limits, self-collision, clearance."""
        arm = arm or self.arm
        p = self.params.stpik
        if np.any(q < rd.Q_LOWER + p.joint_margin) or np.any(q > rd.Q_UPPER - p.joint_margin):
            return False
        self.kin.update(q, jacobians=False)
        arm.pose()
        if arm.self_distances(p.self_clearance + margin):
            return False
        for _, _, d, _, _ in arm.obstacle_distances(obs, p.clearance + margin):
            if d == PENETRATION or d < p.clearance + margin:
                return False
        return True

    def plan_joint(self, q_from, q_to, obs: ObstacleSet, max_checks: int, deadline: float,
                   margin: float = 0.005, rng=None) -> Trajectory | None:
        """RRT-Connect in joint space (same collision checker), timed within Table 7 at 90 %; `rng`: the
        question's generator (question_rng), None for OMPL's."""
        q_from, q_to = _check_q(q_from), _check_q(q_to)
        lo = np.maximum(rd.Q_LOWER, np.minimum(q_from, q_to) - math.pi)
        hi = np.minimum(rd.Q_UPPER, np.maximum(q_from, q_to) + math.pi)
        rrt = JointRRT(lo, hi, self.params.joint_resolution, self.params.simplify_checks)
        path = rrt.plan(q_from, q_to, lambda q: self.joint_valid(q, obs, margin=margin), max_checks, deadline,
                        _draw_seed(rng))
        if path is None:
            return None
        return _time_joint_path(path, 0.9 * self.params.stpik.qdot_max, self.params.stpik.dt)

    def plan_home(self, q_from, removed: Iterable[str] = frozenset(),
                  placed: list[tuple[str, tuple[float, float]]] | None = None) -> Trajectory:
        """From q_from back to Q_HOME (joint-space RRT-Connect with the scene's clearance)."""
        removed = self.scenario.check_ids(removed)
        placed = self.placed_default(removed, -1) if placed is None else list(placed)
        obs = self._collision_scene(placed).obstacles(removed)
        via = self._home_via_stage(_check_q(q_from), obs, placed)
        if via is not None:
            return _time_joint_path(via, 0.9 * self.params.stpik.qdot_max, self.params.stpik.dt).resample()
        rng = self.question_rng("home", np.asarray(q_from, float), removed, self._placed_key(placed))
        traj = self.plan_joint(q_from, rd.Q_HOME, obs, 4 * self.params.rrt_max_checks,
                               time.perf_counter() + self.params.carry_timeout, rng=rng)
        if traj is None:
            raise PlanningError("no collision-free joint path back to the home configuration")
        return traj.resample()

    def _home_via_stage(self, q_from: np.ndarray, obs: ObstacleSet, placed: list) -> list[np.ndarray] | None:
        """The way home from the staging pose in front of a placed bottle's slot (where every retreat ends) without
        sampling: the straight joint motion to that pose's reference configuration, then the reference track
        reversed (`_stage_reference`); None if q_from is at no such pose or that motion is not clear (with the
        home planner's 5 mm margin)."""
        p = self.params
        self.kin.update(q_from, jacobians=False)
        rot, pos = self.kin.tool_pose()
        for oid, xy in placed:
            try:
                _, release = self._carry_heights(oid)
                stage = np.array(place_poses(self.scenario, oid, xy, release, p.stage_distance)[0])
            except WorkspaceError:
                continue
            if np.linalg.norm(pos - stage[:3]) > 2 * p.stpik.final_tol_pos or \
                    abs(math.atan2(rot[1, 2], rot[0, 2]) - stage[3]) > 2 * p.stpik.final_tol_ori:
                continue
            ref = self._stage_reference(stage, placed)
            if ref is None or not self._joint_motion_clear(q_from, ref[-1], obs):
                return None
            return [q_from] + ref[::-1]
        return None

    def _stage_reference(self, stage: np.ndarray, placed: list) -> list[np.ndarray] | None:
        """STPIK's track of the straight tool path from home to the staging pose `stage` with every bottle of the
        top shelf present and `placed` on the bottom one (None if rejected): clear for any removed set, so one per
        (staging pose, bottom shelf's geometry); a function of those only (cached: it is no history)."""
        key = (tuple(np.round(stage, 6)), self._placed_key(placed))
        if key not in self._stage_refs:
            obs = self._collision_scene(placed).obstacles(frozenset())
            r = self._track(rd.Q_HOME, [self.home, stage], obs, time.perf_counter() + self.params.carry_timeout,
                            QueryStats())
            self._stage_refs[key] = list(r.q) if r.ok else None
        return self._stage_refs[key]

    def _joint_motion_clear(self, a: np.ndarray, b: np.ndarray, obs: ObstacleSet, margin: float = 0.005) -> bool:
        """The straight joint motion a -> b valid (joint_valid) every joint_resolution."""
        n = max(1, int(math.ceil(float(np.max(np.abs(b - a))) / self.params.joint_resolution)))
        return all(self.joint_valid(a + (b - a) * (k / n), obs, margin=margin) for k in range(1, n + 1))

    def set_scenario(self, scenario: Scenario, lying: Mapping[str, Lying] | None = None,
                     gone: Iterable[str] = ()) -> None:
        """Replace the scene (same shelf; e.g. bottles as perceived): `lying`, the bottles of the top shelf that do
        not stand (obstacles as the cylinders they are, never graspable); `gone`, those that left the shelf (no
        obstacle, never graspable). Cached grasp ends are dropped."""
        self.scenario = scenario
        self.lying, self.gone = dict(lying or {}), frozenset(gone)
        self.scene = self._collision_scene()
        self._pick_end.clear()
        self._stage_refs.clear()

    def _collision_scene(self, placed: Sequence[tuple[str, tuple[float, float]]] = ()) -> CollisionScene:
        """The scenario's collision scene with `placed` on the bottom shelf, the lying bottles as they lie and the
        gone ones left out."""
        return CollisionScene(self.scenario, placed, self.lying, self.gone)

    def not_graspable(self, object_id: str) -> str:
        """Why the side grasp cannot take `object_id` whatever is removed ('' if it may): lying, or off the shelf."""
        if object_id in self.lying:
            return f"{object_id} is lying: no side grasp"
        if object_id in self.gone:
            return f"{object_id} left the shelf: nothing to grasp"
        return ""

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


def _draw_seed(rng: np.random.Generator | None) -> int | None:
    """The seed of one RRT-Connect solve drawn from the question's generator (None: OMPL's process-wide RNG)."""
    return None if rng is None else int(rng.integers(1, 2**31))


def _mat(pose) -> tuple[np.ndarray, np.ndarray]:
    from stpik_motion_planner.model.grasp import pose_matrix
    return pose_matrix(pose)


def _check_q(q) -> np.ndarray:
    q = np.asarray(q, dtype=float)
    if q.shape != (rd.N_JOINTS,) or not np.all(np.isfinite(q)):
        raise ValueError(f"a configuration must be {rd.N_JOINTS} finite joint angles (Q convention), got {q!r}")
    return q


def _time_joint_path(path: list[np.ndarray], vmax: np.ndarray, dt: float) -> Trajectory:
    """Straight joint segments at constant velocity, each scaled so every joint stays within vmax; steps of dt."""
    qs, qdots = [np.asarray(path[0], float)], []
    for a, b in zip(path[:-1], path[1:]):
        d = np.asarray(b) - np.asarray(a)
        n = max(1, int(math.ceil(float(np.max(np.abs(d) / vmax)) / dt)))
        for _ in range(n):
            qdots.append(d / (n * dt))
            qs.append(qs[-1] + d / n)
    return Trajectory.from_steps(np.array(qs), np.array(qdots), dt, "joint")
