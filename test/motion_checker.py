"""Independent motion checker: planned joint trajectories replayed kinematically in the project's MuJoCo model.

Nothing of the planner's collision model is used: the world is `jaco2_sim_driver.scene.build_model(scenario)`
(arm capsules, the simulator's finger bodies, every object of the scenario's world, its `unlisted:` ones included,
shelf boards, side and back panels, pedestal, floor), the
arm is posed by MuJoCo's own kinematics from the planned joint angles, a grasped bottle is attached to the hand
at the relative pose it had when the pick ended (as the simulator's weld does) and released bottles stand where
they were let go, on the board below them. Distances are MuJoCo's signed geom distances (`mj_geomDistance`, < 0
= penetration), after a numpy bounding-volume broad phase.

Pairs and what is asked of them:
- contact pairs (everything else): arm links (not the base and shoulder, which sit on the pedestal), fingers and
  the carried bottle against the world, and non-adjacent arm links against each other. Distance <= 0 is a
  contact; the smallest distance is the clearance reported.
- near pairs (no clearance asked, contact still counted): the hand (wrist, palm, fingers) and the bottle it is
  picking during the approach, the hand and the bottle it just released during the retreat, the wrist and palm and
  the bottle they hold; the fingers and the board a lying bottle lies on while they pick it from above (the
  approach) and lift it (within `support_band` of the grasp): the grasp from above closes them over that board.
- exempt: the fingers and the bottle they hold (the grasp is contact); the held bottle and the board it stands
  on while the tool is within `support_band` of where it grasped it (the lift) or released it (the place), if it
  does not enter that board by more than `support_tol`.
The description's static finger capsules are switched off as in the simulator (the moving fingers replace them);
the fingers are replayed open (their widest envelope).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import mujoco
import numpy as np

from jaco2_sim_driver.scene import DESCRIPTION_FINGER_GEOMS, HAND_BODY, build_model
from relocation_common import robot_description as rd

HAND_GEOMS = ("wrist", "palm", "finger_sim_1", "finger_sim_2", "finger_sim_3")
FINGER_GEOMS = ("finger_sim_1", "finger_sim_2", "finger_sim_3")
ARM_GEOMS = ("upper_arm", "forearm") + HAND_GEOMS
FIXED_ARM = ("base", "shoulder")
BOARDS = ("shelf_top_board", "shelf_ceiling_board", "shelf_bottom_board", "shelf_side_left", "shelf_side_right",
          "shelf_back_panel")
# arm pairs that touch by construction (robot_description.ADJACENT, in the simulator's geom names)
_SIM = {"finger_1": "finger_sim_1", "finger_2": "finger_sim_2", "finger_3": "finger_sim_3"}
ADJACENT = {frozenset(_SIM.get(n, n) for n in p) for p in rd.ADJACENT}


@dataclass
class Contact:
    segment: str
    time: float
    geom1: str
    geom2: str
    distance: float  # <= 0: penetration depth is -distance

    def __str__(self) -> str:
        return f"{self.segment} t={self.time:.2f} s: {self.geom1} - {self.geom2} {self.distance * 1000:+.1f} mm"


@dataclass
class Report:
    segments: int = 0
    samples: int = 0
    contacts: list[Contact] = field(default_factory=list)  # one per (segment, pair): its deepest sample
    min_clearance: float = math.inf  # contact pairs, arm and carried bottle (m)
    min_clearance_at: str = ""
    min_arm: float = math.inf  # arm links and fingers (m)
    min_arm_at: str = ""
    min_carried: float = math.inf  # the carried bottle against the world (m)
    min_carried_at: str = ""
    min_near: float = math.inf  # near pairs (m)
    min_near_at: str = ""
    support_depth: float = 0.0  # deepest entry of a held bottle into its support board while exempt (m)
    min_floor: float = math.inf  # the fingers over the board a lying bottle lies on, picked from above, or the hand,
    # picked along its axis (m; near pairs)
    min_floor_at: str = ""

    @property
    def max_depth(self) -> float:
        return max((-c.distance for c in self.contacts), default=0.0)

    def merge(self, other: "Report") -> None:
        self.segments += other.segments
        self.samples += other.samples
        self.contacts += other.contacts
        if other.min_clearance < self.min_clearance:
            self.min_clearance, self.min_clearance_at = other.min_clearance, other.min_clearance_at
        if other.min_arm < self.min_arm:
            self.min_arm, self.min_arm_at = other.min_arm, other.min_arm_at
        if other.min_carried < self.min_carried:
            self.min_carried, self.min_carried_at = other.min_carried, other.min_carried_at
        if other.min_near < self.min_near:
            self.min_near, self.min_near_at = other.min_near, other.min_near_at
        self.support_depth = max(self.support_depth, other.support_depth)
        if other.min_floor < self.min_floor:
            self.min_floor, self.min_floor_at = other.min_floor, other.min_floor_at

    def summary(self) -> str:
        return (f"{self.segments} segments, {self.samples} samples, {len(self.contacts)} contacts "
                f"(deepest {self.max_depth * 1000:.1f} mm), min clearance {self.min_clearance * 1000:.1f} mm "
                f"({self.min_clearance_at}), arm {self.min_arm * 1000:.1f} mm ({self.min_arm_at}), "
                f"carried bottle {self.min_carried * 1000:.1f} mm ({self.min_carried_at}),"
                f" near pairs {self.min_near * 1000:.1f} mm ({self.min_near_at}), "
                f"support entry {self.support_depth * 1000:.1f} mm" +
                (f", hand over the board under a lying bottle {self.min_floor * 1000:.1f} mm ({self.min_floor_at})"
                 if self.min_floor_at else ""))


def _quat(rot) -> np.ndarray:
    q = np.zeros(4)
    mujoco.mju_mat2Quat(q, np.asarray(rot, float).reshape(9))
    return q


class MotionChecker:
    """The scenario's MuJoCo world with the bottles where the relocations so far left them."""

    def __init__(self, scenario, distmax: float = 0.05, support_band: float = 0.04, support_tol: float = 0.001):
        self.scenario = scenario
        self.model = m = build_model(scenario)
        self.data = mujoco.MjData(m)
        self.distmax, self.support_band, self.support_tol = distmax, support_band, support_tol

        def gid(n):
            return mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, n)

        self.gid, self.name = gid, lambda g: mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_GEOM, g)
        for g in DESCRIPTION_FINGER_GEOMS:  # as in Jaco2Sim: the moving fingers replace them
            m.geom_contype[gid(g)] = m.geom_conaffinity[gid(g)] = 0
        self._qadr = np.array([m.joint(j).qposadr[0] for j in rd.JOINT_NAMES])
        self._fadr = np.array([m.joint(j).qposadr[0] for j in rd.FINGER_JOINT_NAMES])
        self._hand = m.body(HAND_BODY).id
        # every object the simulator builds, the scenario's `unlisted` ones too (the planner may not know them)
        self.bottle_geom = {b.id: gid(f"{b.id}_geom") for b in scenario.world}
        self._free = {b.id: m.jnt_qposadr[m.body_jntadr[m.body(b.id).id]] for b in scenario.world}
        self.arm = [gid(n) for n in ARM_GEOMS]
        self.world = [gid(n) for n in ("floor", "pedestal") + BOARDS]
        self._fingers = {gid(n) for n in FINGER_GEOMS}
        self._hand_geoms = {gid(n) for n in HAND_GEOMS}
        self._lying = {b.id for b in scenario.world if b.lying}
        self.floor = gid("floor")
        self.held: str | None = None
        self._rel: tuple[np.ndarray, np.ndarray] | None = None
        self._support: tuple[np.ndarray, int] | None = None  # (tool position, board) of the last grasp/release
        self.placed: dict[str, np.ndarray] = {}
        mujoco.mj_resetData(m, self.data)
        self.data.qpos[self._fadr] = 0.0
        self.set_q(rd.Q_HOME)

    # ---------------------------------------------------------------- state
    def set_q(self, q) -> None:
        self.data.qpos[self._qadr] = q
        if self.held is not None:
            mujoco.mj_kinematics(self.model, self.data)
            hp, hr = self.data.xpos[self._hand], self.data.xmat[self._hand].reshape(3, 3)
            a = self._free[self.held]
            self.data.qpos[a:a + 3] = hp + hr @ self._rel[0]
            self.data.qpos[a + 3:a + 7] = _quat(hr @ self._rel[1])
        mujoco.mj_kinematics(self.model, self.data)

    def tool(self) -> np.ndarray:
        return self.data.site_xpos[self.model.site("end_effector").id].copy()

    def bottle_pose(self, oid) -> tuple[np.ndarray, np.ndarray]:
        b = self.model.body(oid).id
        return self.data.xpos[b].copy(), self.data.xmat[b].reshape(3, 3).copy()

    def _board_below(self, p) -> int:
        s = self.scenario.shelf
        top = abs(p[2] - s.top_z) < abs(p[2] - s.bottom_z)
        return self.gid("shelf_top_board" if top else "shelf_bottom_board")

    def grasp(self, oid: str) -> None:
        """The hand holds oid from now on, at their present relative pose (the end of the pick)."""
        p, r = self.bottle_pose(oid)
        hp, hr = self.data.xpos[self._hand], self.data.xmat[self._hand].reshape(3, 3)
        self._rel = (hr.T @ (p - hp), hr.T @ r)
        self.held = oid
        self._support = (self.tool(), self._board_below(p))

    def release(self) -> np.ndarray:
        """The held bottle drops onto the board below it (kept upright as held); returns its base position."""
        oid, self.held = self.held, None
        p, r = self.bottle_pose(oid)
        board = self._board_below(p)
        z = self.scenario.shelf.top_z if board == self.gid("shelf_top_board") else self.scenario.shelf.bottom_z
        self._support = (self.tool(), board)
        a = self._free[oid]
        self.data.qpos[a:a + 3] = (p[0], p[1], z)
        self.data.qpos[a + 3:a + 7] = _quat(r)
        self.placed[oid] = np.array([p[0], p[1], z])
        mujoco.mj_kinematics(self.model, self.data)
        return self.placed[oid]

    # ---------------------------------------------------------------- checks
    def _pairs(self, picking: str | None, near_placed: str | None):
        """(geom a, geom b, kind) with kind 'contact', 'near', 'carried' or 'support'."""
        out = []
        statics = self.world + [g for o, g in self.bottle_geom.items() if o != self.held]
        hand = {self.gid(n) for n in HAND_GEOMS}
        fingers = {self.gid(n) for n in FINGER_GEOMS}
        near_ids = {self.bottle_geom[o] for o in (picking, near_placed) if o is not None}
        for a in self.arm:
            for b in statics:
                out.append((a, b, "near" if (a in hand and b in near_ids) else "contact"))
        arm_all = self.arm
        for i, a in enumerate(arm_all):  # self-collision of non-adjacent links
            for b in arm_all[i + 1:]:
                if frozenset((self.name(a), self.name(b))) not in ADJACENT and not (a in hand and b in hand):
                    out.append((a, b, "contact"))
        if self.held is not None:
            c = self.bottle_geom[self.held]
            for b in statics:
                out.append((c, b, "carried"))
            for a in self.arm:
                if a in fingers:
                    continue  # the grasp
                out.append((c, a, "near" if a in hand else "carried"))
        return out

    def check(self, traj, segment: str, picking: str | None = None, approach_from: float = 0.0,
              near_placed: str | None = None) -> Report:
        """Replay traj (every sample) and measure. `picking`: the bottle being picked: a near pair for the hand from
        `approach_from` (s) on. `near_placed`: the bottle just released (retreat)."""
        m, d = self.model, self.data
        rep = Report(segments=1)
        deepest: dict[tuple[int, int], Contact] = {}
        fromto = np.zeros(6)
        pairs_free = self._pairs(None, near_placed)
        pairs_pick = self._pairs(picking, near_placed) if picking else pairs_free
        for t, q in zip(traj.times, traj.positions):
            self.set_q(q)
            rep.samples += 1
            approaching = picking and t >= approach_from - 1e-9
            pairs = pairs_pick if approaching else pairs_free
            a_ids = np.array([p[0] for p in pairs])
            b_ids = np.array([p[1] for p in pairs])
            gap = self._gap(a_ids, b_ids)
            support_ok = (self._support is not None and self.held is not None
                          and np.linalg.norm(self.tool() - self._support[0]) <= self.support_band)
            # the fingers over the board a lying bottle lies on, picked from above and lifted: a near pair
            floor = self._board_below(self.bottle_pose(picking)[0]) if approaching and picking in self._lying else \
                self._support[1] if support_ok and self.held in self._lying and self._support else None
            # a lying bottle grasped along its axis (the hand horizontal): the whole hand comes FINGER_FLOOR near it
            level = floor is not None and abs(d.xmat[self._hand][8]) < 0.5
            over_floor = self._hand_geoms if level else self._fingers
            for k in np.nonzero(gap < self.distmax)[0]:
                a, b, kind = pairs[k]
                dist = mujoco.mj_geomDistance(m, d, int(a), int(b), self.distmax, fromto)
                if dist >= self.distmax:
                    continue
                where = f"{segment} t={t:.2f} {self.name(a)}-{self.name(b)}"
                if kind == "carried" and support_ok and b == self._support[1]:
                    if dist >= -self.support_tol:
                        rep.support_depth = max(rep.support_depth, -dist)
                        continue
                if dist <= 0.0:
                    key = (int(a), int(b))
                    if key not in deepest or dist < deepest[key].distance:
                        deepest[key] = Contact(segment, float(t), self.name(a), self.name(b), float(dist))
                if b == floor and a in over_floor:
                    if dist < rep.min_floor:
                        rep.min_floor, rep.min_floor_at = dist, where
                    continue
                if kind == "near":
                    if dist < rep.min_near:
                        rep.min_near, rep.min_near_at = dist, where
                    continue
                if dist < rep.min_clearance:
                    rep.min_clearance, rep.min_clearance_at = dist, where
                if kind == "carried":
                    if dist < rep.min_carried:
                        rep.min_carried, rep.min_carried_at = dist, where
                elif dist < rep.min_arm:
                    rep.min_arm, rep.min_arm_at = dist, where
        rep.contacts = list(deepest.values())
        return rep

    def _gap(self, a_ids: np.ndarray, b_ids: np.ndarray) -> np.ndarray:
        """Lower bound of the distance of each pair: bounding spheres, or sphere against a box's world AABB, or
        height above the floor plane."""
        m, d = self.model, self.data
        pa, ra = d.geom_xpos[a_ids], m.geom_rbound[a_ids]
        pb, rb = d.geom_xpos[b_ids], m.geom_rbound[b_ids]
        gap = np.linalg.norm(pa - pb, axis=1) - ra - rb
        box = m.geom_type[b_ids] == mujoco.mjtGeom.mjGEOM_BOX
        if np.any(box):
            k = np.nonzero(box)[0]
            half = np.abs(d.geom_xmat[b_ids[k]].reshape(-1, 3, 3)) @ m.geom_size[b_ids[k]][:, :, None]
            lo, hi = pb[k] - half[:, :, 0], pb[k] + half[:, :, 0]
            out = np.maximum(np.maximum(lo - pa[k], pa[k] - hi), 0.0)
            gap[k] = np.linalg.norm(out, axis=1) - ra[k]
        plane = b_ids == self.floor
        if np.any(plane):
            k = np.nonzero(plane)[0]
            gap[k] = pa[k, 2] - pb[k, 2] - ra[k]
        return gap


def replay_relocation(checker: MotionChecker, pick, carry_segments, home, object_id: str) -> Report:
    """pick (Trajectory ending at the grasp), carry segments [carry, retreat] (Trajectories), home (Trajectory):
    the motions of one relocation, checked in order with the bottle grasped after the pick and released after
    the carry."""
    rep = Report()
    phases = dict(pick.phases)
    rep.merge(checker.check(pick, f"{object_id}:pick", picking=object_id,
                            approach_from=phases.get("approach", 0.0)))
    checker.grasp(object_id)
    carry, retreat = carry_segments
    rep.merge(checker.check(carry, f"{object_id}:carry"))
    checker.release()
    rep.merge(checker.check(retreat, f"{object_id}:retreat", near_placed=object_id))
    rep.merge(checker.check(home, f"{object_id}:home"))
    return rep
