"""What every phase of the motion planner shares (pick.py, carry.py, home.py, certify.py; planner.MotionPlanner is
one): the scene (the scenario, its lying and gone bottles, collision scenes with bottles placed on the bottom shelf),
the robot's models (kinematics, arm capsules, the Cartesian planner's hand proxy), the planners (RRT-Connect, STPIK),
the question's random generator (seed_per_query), the caches that are no history (a pick's grasp configuration and
near set, the staging poses' reference tracks, certifications by grasp) and the objects a pick comes near
(`near_objects`: reuse across answers).
"""
from __future__ import annotations

import dataclasses
import hashlib
import math
import time
from typing import Iterable, Sequence

import numpy as np

from relocation_common import robot_description as rd
from relocation_common.feasibility import NO_GRASP
from relocation_common.scenario import Scenario, UnknownObjectError
from relocation_common.shelf_object import objects_key
from stpik_motion_planner.model.collision import (
    HAND_PARTS,
    ArmGeometry,
    CollisionScene,
    HandProxy,
    Lying,
    ObstacleSet,
    approach_skip,
)
from stpik_motion_planner.model.grasp import (
    WorkspaceError,
    along_axis_refusal,
    approach_yaw,
    both_refusals,
    carry_heights,
    grasp_refusal,
    grasp_yaw_tiers,
    home_pose,
    lying_pitch,
    pose_matrix,
    side_grasp,
)
from stpik_motion_planner.model.kinematics import Kinematics
from stpik_motion_planner.planning.params import PlannerParams
from stpik_motion_planner.planning.results import QueryStats
from stpik_motion_planner.planning.rrt import CartesianRRT, seed_ompl
from stpik_motion_planner.planning.stpik import Stpik, StpikResult, TrackMemo

# left out of question_rng's seed: the safety nets (wall clock), and the second yaw tier's settings, so that the
# first tier's draws, and every answer it gives, are those of a planner without the second tier; the grasp's yaw
# tolerance (stpik.*), so that every path that converged without it is drawn and ends as before; reuse_distance
# (what an answer reports, not how it is planned); flat_tilt (how a perceived pose is read: the scene it gives is in the
# seed); the push's settings (push.*: a pick's draws are those of a planner without the push; a push question's
# seed has them in its question). certify_relocation is in the seed as true (SEEDED_AS): a lazy
# pick draws what the eager one drew, so the lane a certification accepts is the eager answer's
UNSEEDED = ("timeout", "carry_timeout", "wide_yaws", "wide_max_yaw", "reuse_distance", "flat_tilt", "push")
SEEDED_AS = {"certify_relocation": True}
UNSEEDED_STPIK = ("grasp_yaw_tol",)
Placed = list[tuple[str, tuple[float, float]]]  # objects on the bottom shelf: (id, slot xy)


class PlanningContext:
    """The planner's scene, models and shared steps (the module docstring); `params` default:
    config/motion_planner.yaml."""

    def __init__(self, scenario: Scenario, params: PlannerParams | None = None) -> None:
        self.scenario = scenario
        self.params = params if params is not None else PlannerParams.load()  # config/motion_planner.yaml
        seed_ompl(self.params.seed)
        self.kin = Kinematics()
        self.lying: dict[str, Lying] = {}  # bottles of the top shelf that lean (neither stand nor lie flat)
        self.gone: frozenset[str] = frozenset()  # bottles that left the shelf
        self.scene = self.collision_scene()
        self.arm = ArmGeometry(self.kin)
        p = self.params
        self.stpik = Stpik(self.kin, self.arm, p.stpik)
        self.stpik.memo = TrackMemo()  # the picks' checks reused across questions (stpik.TrackMemo)
        # the screen (and the Cartesian planner) keep STPIK's own bound when screen_at_clearance: a lane reported
        # clear is then clear for the fingers STPIK drives to the grasp (docs/motion_planner.md, "Blockers")
        self.hand_margin = max(p.hand_margin, p.stpik.clearance) if p.screen_at_clearance else p.hand_margin
        self.hand = HandProxy(self.hand_margin)
        self.reach = HandProxy(p.reuse_distance)  # the hand proxy inflated to reuse_distance (near_objects)
        self.rrt = CartesianRRT(p.workspace_lo, p.workspace_hi, p.resolution, p.simplify_checks)
        self.home = np.array(home_pose())
        self.last_stats = QueryStats()
        self.pick_end: dict[tuple[str, frozenset[str]], np.ndarray] = {}  # (object, removed) -> grasp configuration
        self.pick_near: dict[tuple[str, frozenset[str]], frozenset[str] | None] = {}  # -> near_objects
        self.stage_refs: dict[tuple[object, ...], list[np.ndarray] | None] = {}  # home.stage_reference's tracks
        self.certified: dict[tuple[str, frozenset[str], bytes], str] = {}  # (object, removed, grasp) -> certify.certify
        self.near_cache: dict[tuple, frozenset[str]] = {}  # near_objects' answers
        self._seed_scene: tuple[Scenario, tuple[str, ...], tuple[str, ...]] | None = None  # seed_scene's

    # ---------------------------------------------------------------- the question
    def check_question(self, object_id: str, removed: Iterable[str]) -> frozenset[str]:
        """The removed set of a question about `object_id`, checked: UnknownObjectError, TypeError, ValueError."""
        if not isinstance(object_id, str):
            raise UnknownObjectError(f"object id must be a string, got {object_id!r}")
        self.scenario.object(object_id)
        if isinstance(removed, str):
            raise TypeError("removed must be a collection of ids, not a string")
        removed = self.scenario.check_ids(removed)
        if object_id in removed:
            raise ValueError(f"object {object_id!r} is in the removed set: it is no longer on the shelf")
        return removed

    def question_rng(self, *question: object) -> np.random.Generator | None:
        """The random generator of one question (seed_per_query): seeded from a hash of the scene (shelf, bottles,
        slots), the question (object, removed set, and for a carry or home its start and placed bottles) and every
        planner parameter but the wall-clock safety nets; None (OMPL's process-wide RNG) otherwise."""
        if not self.params.seed_per_query:
            return None
        parts = list(self.seed_scene())
        for x in question:
            if isinstance(x, np.ndarray):
                parts.append(np.round(x, 9).tobytes().hex())
            elif isinstance(x, (set, frozenset)):
                parts.append(repr(sorted(x)))
            else:
                parts.append(repr(x))
        digest = hashlib.sha256("\x1f".join(parts).encode()).digest()
        return np.random.default_rng(int.from_bytes(digest[:16], "little"))

    def seed_scene(self) -> tuple[str, ...]:
        """The part of question_rng's seed that is the same for every question: the scene (shelf, bottles, slots;
        the lying and gone bottles if any) and the parameters; computed again when any of them changed."""
        key = (repr(self.params), repr(sorted(self.lying.items())), repr(sorted(self.gone)))
        got = self._seed_scene
        if got is not None and got[0] is self.scenario and got[1] == key:
            return got[2]
        sc = self.scenario
        params = {k: v for k, v in dataclasses.asdict(self.params).items() if k not in UNSEEDED} | SEEDED_AS
        params["stpik"] = {k: v for k, v in params["stpik"].items() if k not in UNSEEDED_STPIK}
        params["stpik"]["qdot_max"] = rd.QDOT_MAX.copy()  # Table 7, the robot's: in the seed as when it was a parameter
        parts = [repr(sc.shelf), objects_key(sc.objects, sc.shelf.top_z), repr(sc.slots),  # objects_key: the seeds
                 repr(sorted(params.items()))]  # of every shipped scene as they were before objects had shapes
        if self.lying or self.gone:  # a standing scene's questions keep their seeds (the committed caches)
            parts += [key[1], key[2]]
        self._seed_scene = (sc, key, tuple(parts))
        return self._seed_scene[2]

    # ---------------------------------------------------------------- the scene
    def collision_scene(self, placed: Sequence[tuple[str, tuple[float, float]]] = ()) -> CollisionScene:
        """The scenario's collision scene with `placed` on the bottom shelf, the lying bottles as they lie and the
        gone ones left out."""
        stpik = self.params.stpik  # a placed box turned by the grasp's and the place's yaw tolerances at most
        return CollisionScene(self.scenario, placed, self.lying, self.gone, stpik.grasp_yaw_tol + stpik.final_tol_ori)

    def not_graspable(self, object_id: str) -> str:
        """Why the grasps cannot take `object_id` whatever is removed ('' if they may): off the shelf, or
        "no grasp: " and why (grasp.grasp_refusal: a conservative object, a cylinder leaning as perceived, too wide
        for the open hand, a box too wide across every face the approach yaws of both tiers can take it by; a
        cylinder lying flat, from the scenario or tipped over as perceived, that neither the grasp from above
        (grasp.lying_pitch: the headroom or its reach) nor the grasp along its axis (grasp.along_axis_refusal)
        takes: both reasons)."""
        if object_id in self.gone:
            return f"{object_id} left the shelf: nothing to grasp"
        p = self.params
        o, max_yaw = self.scenario.object(object_id), p.wide_max_yaw if p.wide_yaws else p.max_yaw
        why = grasp_refusal(o, max_yaw)
        if why:
            return why
        if o.lying:
            above = lying_pitch(self.scenario.shelf, o, p.pre_grasp_distance, self.ceiling_clearance)[2]
            along = along_axis_refusal(self.scenario.shelf, o, max_yaw, self.ceiling_clearance) if above else ""
            return both_refusals(above, along) if along else ""
        return self.out_of_reach(object_id)

    def along_axis(self, object_id: str) -> bool:
        """`object_id` is a lying cylinder grasped along its axis (grasp.grasp_along_axis): the board above leaves no
        room for a grasp from above (its pitch 0)."""
        return self.scenario.object(object_id).lying and self.grasp_pitch(object_id) == 0.0

    def out_of_reach(self, object_id: str) -> str:
        """"no grasp: " for an object standing where the straight side grasp is out of the arm's workspace: a fact
        of the shelf, answered g_U, the target's too (a target knocked out of reach in the closed loop was a refused
        question, and the re-plan ended "training aborted" instead of its proof that no retrieval is left)."""
        try:
            side_grasp(self.scenario, object_id, 0.0, self.params.pre_grasp_distance, self.ceiling_clearance)
        except WorkspaceError as e:
            return f"{NO_GRASP}{object_id} stands out of the arm's reach for the side grasp ({e})"
        return ""

    def grasp_pitch(self, object_id: str) -> float:
        """The pitch of the grasp of `object_id`: a lying cylinder's grasp from above (grasp.lying_pitch), else 0."""
        o = self.scenario.object(object_id)
        if not o.lying:
            return 0.0
        return lying_pitch(self.scenario.shelf, o, self.params.pre_grasp_distance, self.ceiling_clearance)[0]

    def grasp_skip(self, object_id: str) -> dict[str, frozenset[str]]:
        """What the hand may touch on the straight approach to the grasp of `object_id` and on its lift
        (collision.approach_skip); a lying cylinder grasped along its axis (grasp.grasp_along_axis): the whole hand
        (wrist, palm, fingers) also the board it lies on, which its lowest capsule comes grasp.FINGER_FLOOR near."""
        skip = approach_skip(self.scenario.object(object_id))
        if not self.along_axis(object_id):
            return skip
        board = frozenset(["board:top_shelf"])
        return {n: skip.get(n, frozenset([object_id])) | board for n in ("wrist", *HAND_PARTS)}

    @property
    def ceiling_clearance(self) -> float:
        """What the hand keeps under the board above at a grasp from above: STPIK's bound and activation band."""
        return self.params.stpik.clearance + self.params.stpik.act

    def placed_default(self, removed: frozenset[str], slot_index: int) -> Placed:
        """Bottles assumed on the bottom shelf: the removed ones, in sorted order, in the slots other than
        slot_index."""
        slots = [k for k in range(len(self.scenario.slots)) if k != slot_index]
        return [(oid, self.scenario.slot(k)) for oid, k in zip(sorted(removed), slots)]

    def placed_key(self, placed: Iterable[tuple[str, tuple[float, float]]]) -> str:
        """The objects on the bottom shelf as geometry (where, which size: a bottle's radius, a box's size), whatever
        their names: a carry planned for a removed set and the same carry in a relocation order see the same scene,
        so draw the same samples."""
        objs = [(x, y, self.scenario.object(o)) for o, (x, y) in placed]
        return repr(sorted((round(x, 4), round(y, 4), b.size if b.shape == "box" else b.radius, b.height)
                           for x, y, b in objs))

    def carry_heights(self, object_id: str) -> tuple[float, float]:
        """(lift, release height) of the object carried at its real size (grasp.carry_heights); WorkspaceError if
        it is too tall for the compartments."""
        p = self.params
        return carry_heights(self.scenario, object_id, p.carried_clearance + p.stpik.act, p.lift, p.drop)

    # ---------------------------------------------------------------- the approach yaws
    def yaw_tiers(self, object_id: str) -> list[list[float]]:
        """The approach yaws of `object_id`, tier by tier (grasp.grasp_yaw_tiers: a box's face yaws)."""
        p = self.params
        return grasp_yaw_tiers(self.scenario.object(object_id), p.n_yaws, p.max_yaw, p.wide_yaws, p.wide_max_yaw)

    def all_yaws(self, object_id: str) -> list[float]:
        """Every approach yaw of `object_id` of both tiers, in the order they are tried (the lanes of
        blockers.py)."""
        return [y for tier in self.yaw_tiers(object_id) for y in tier]

    def grasp_yaw(self, q_grasp: object) -> float:
        """The approach yaw of the tool at the grasp configuration `q_grasp` (which face of a box the hand holds)."""
        self.kin.update(check_q(q_grasp), jacobians=False)
        return approach_yaw(self.kin.tool_pose()[0])

    # ---------------------------------------------------------------- the STPIK check
    def track(self, q0: np.ndarray, path: Sequence[np.ndarray], obs: ObstacleSet, deadline: float,
              stats: QueryStats, skip: dict[str, frozenset[str]] | None = None, arm: ArmGeometry | None = None,
              speed: float | None = None, ramp: float = 0.0, accel: float = 0.0, yaw_tol: float = 0.0,
              from_rest: bool = False) -> StpikResult:
        """STPIK tracking `path` from q0 (Eq. 9-10; with `arm`, the arm holding a bottle; `from_rest`: Stpik.track's),
        its time and rejection counted in `stats`."""
        t = time.perf_counter()
        stpik = self.stpik if arm is None else Stpik(self.kin, arm, self.params.stpik)
        r = stpik.track(q0, path, obs, deadline, skip, speed=speed, ramp=ramp, accel=accel, yaw_tol=yaw_tol,
                        from_rest=from_rest)
        stats.stpik_time += time.perf_counter() - t
        if not r.ok:
            stats.stpik_reject.append(r.reason)
        return r


# ---------------------------------------------------------------- reuse across answers
# The objects a pick's motion comes near (relocation_common.feasibility, "Reuse"; docs/motion_planner.md, "Reuse
# across answers"): the answer's `near` set. An object enters a check of a pick only within the widest band any check
# of it looks at (PlannerParams.checked_distance: the hand proxy's inflation in the Cartesian planner, STPIK's
# candidate band clearance + buffer). `near_objects` lists every top-shelf bottle, removed or not, whose place some arm
# capsule (at each IK step of the tracked motion) or the hand proxy (along the tool path, at the Cartesian planner's
# resolution) comes within `reuse_distance` (>= that band) of, by axis-aligned boxes (a superset of the true
# distances: never too few). A bottle outside that set took part in no check of the motion whether it stood there or
# not, so the motion stays valid and is tracked identically in any scene that differs from the question's only in such
# bottles.
def near_objects(ctx: PlanningContext, object_id: str, steps: Sequence[np.ndarray], tool_path: Sequence[np.ndarray]
                 ) -> frozenset[str]:
    """The bottles (other than `object_id`, removed or not) within reuse_distance of the arm at the IK `steps` or of
    the hand proxy along `tool_path` ((x, y, z, yaw) poses); kept by object, steps and path (the same for every
    removed set: ctx.near_cache, emptied with the scene)."""
    d = ctx.params.reuse_distance
    h = hashlib.blake2b(digest_size=32)
    for x in [*steps, None, *tool_path]:  # None: where the path starts
        a = np.zeros(0) if x is None else np.asarray(x, float)
        h.update(len(a).to_bytes(4, "little") + a.tobytes())
    key = (object_id, d, ctx.params.resolution, h.digest())
    got = ctx.near_cache.get(key)
    if got is None:
        got = ctx.near_cache[key] = _near_objects(ctx, object_id, steps, tool_path)
    return got


def _near_objects(ctx: PlanningContext, object_id: str, steps: Sequence[np.ndarray],
                  tool_path: Sequence[np.ndarray]) -> frozenset[str]:
    """near_objects computed."""
    d = ctx.params.reuse_distance
    bottles = [o for i, o in ctx.scene.bottles.items() if i != object_id]
    if not bottles:
        return frozenset()
    obs = ObstacleSet(bottles)
    arm_lo, arm_hi = arm_boxes(ctx, steps)
    hand_lo, hand_hi = proxy_boxes(ctx, tool_path)
    lo, hi = np.vstack([arm_lo, hand_lo - d]), np.vstack([arm_hi, hand_hi + d])
    gap = np.maximum(np.maximum(obs.lo[None] - hi[:, None], lo[:, None] - obs.hi[None]), 0.0)
    near = np.nonzero((np.einsum("ijk,ijk->ij", gap, gap) < d * d).any(axis=0))[0]
    return frozenset(str(bottles[k].object_id) for k in near)


def proxy_boxes(ctx: PlanningContext, tool_path: Sequence[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Axis-aligned boxes (lo, hi: one row per shape and pose) of the Cartesian planner's hand proxy, uninflated,
    at every pose its checks visit along the polyline `tool_path` (every `resolution` m, as HandProxy.path_clear)."""
    proxy, res = ctx.hand, ctx.params.resolution
    poses = []
    for a, b in zip(tool_path[:-1], tool_path[1:]):
        a, b = np.asarray(a, float), np.asarray(b, float)
        turn = float(abs(b[3] - a[3])) if len(a) < 5 else float(np.abs(b[3:] - a[3:]).max())
        n = max(1, int(math.ceil(max(float(np.linalg.norm(b[:3] - a[:3])), 0.25 * turn) / res)))
        poses.append(a + (b - a) * (np.arange(n + 1) / n)[:, None])
    pose = np.vstack(poses)
    if pose.shape[1] > 4:  # a grasp from above (or a push's rolled hand): grasp.tool_rotation of each pose
        rot = np.array([pose_matrix(p)[0] for p in pose])
    else:
        c, s = np.cos(pose[:, 3]), np.sin(pose[:, 3])
        rot = np.zeros((len(pose), 3, 3))  # grasp.side_rotation of each yaw
        rot[:, 0, 0], rot[:, 0, 2], rot[:, 1, 0], rot[:, 1, 2], rot[:, 2, 1] = -s, c, c, s, 1.0
    p7 = pose[:, :3] - rot[:, :, 2] * rd.D67  # link 7's origin (HandProxy.hits)
    p0 = np.einsum("nij,cj->nci", rot, proxy.p0) + p7[:, None]
    p1 = np.einsum("nij,cj->nci", rot, proxy.p1) + p7[:, None]
    rad = np.array([sp.radius for sp in proxy.specs])[None, :, None]
    return (np.minimum(p0, p1) - rad).reshape(-1, 3), (np.maximum(p0, p1) + rad).reshape(-1, 3)


def arm_boxes(ctx: PlanningContext, steps: Sequence[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Axis-aligned boxes (lo, hi: one row per arm capsule and step) of the arm's capsules (robot_description.
    CAPSULES) at every configuration of `steps`: the frames of all steps first, then every capsule at once."""
    caps = rd.CAPSULES
    fids = sorted({ctx.kin.fid[c.link] for c in caps})
    row = np.array([fids.index(ctx.kin.fid[c.link]) for c in caps])
    frames = np.empty((len(steps), len(fids), 4, 4))
    view = ctx.kin.placement_view
    for s, q in enumerate(steps):
        ctx.kin.update(q, jacobians=False)
        for k, fid in enumerate(fids):
            frames[s, k] = view(fid).homogeneous
    m = frames[:, row]  # steps x capsules x 4 x 4
    p0 = np.einsum("scij,cj->sci", m[..., :3, :3], np.array([c.p0 for c in caps])) + m[..., :3, 3]
    p1 = np.einsum("scij,cj->sci", m[..., :3, :3], np.array([c.p1 for c in caps])) + m[..., :3, 3]
    rad = np.array([c.radius for c in caps])[None, :, None]
    return (np.minimum(p0, p1) - rad).reshape(-1, 3), (np.maximum(p0, p1) + rad).reshape(-1, 3)


def draw_seed(rng: np.random.Generator | None) -> int | None:
    """The seed of one RRT-Connect solve drawn from the question's generator (None: OMPL's process-wide RNG)."""
    return None if rng is None else int(rng.integers(1, 2**31))


def check_q(q: object) -> np.ndarray:
    """A configuration as 7 finite joint angles (Q convention); ValueError otherwise."""
    q = np.asarray(q, dtype=float)
    if q.shape != (rd.N_JOINTS,) or not np.all(np.isfinite(q)):
        raise ValueError(f"a configuration must be {rd.N_JOINTS} finite joint angles (Q convention), got {q!r}")
    return q
