"""Disturbances of the simulated shelf (no ROS): nudge, tip or move a bottle, drop the carried one.

The paper ran its robot open-loop; these make the world differ from the plan, as a real shelf does, so that the
task planner's closed loop (verify after each relocation, re-plan) can be exercised and measured.

- `nudge`: a horizontal push by (dx, dy). The bottle slides until it would touch another bottle or leave the
  shelf (a neighbour stops it), so the applied push may be shorter than the one asked for; both are recorded.
- `tip`: the bottle lies on its side on the board it stood on, along the first direction with room for it.
- `move_to`: the bottle stands upright at a given pose (refused where it would overlap another or leave the shelf).
- `drop_grasped` / `CarryDropper`: the carried bottle slips out of the closed hand (the grasp weld off, its
  weight back, no contact with the fingers until it is clear of them); the fingers then close on nothing.

Each function changes the MuJoCo state at once (a teleport of the bottle, velocities zeroed) and returns an
`Applied` record; the caller steps the physics (the driver's loop, or a test). `DisturbancePlan` draws K seeded
disturbances at moments of an execution ("after relocation i", "during carry j") and serialises them for the
report's `disturbances` list.
"""
from __future__ import annotations

import dataclasses
import json
import math
import random
from dataclasses import dataclass, field, replace
from typing import Any, Iterable, Protocol

import mujoco
import numpy as np
from numpy.typing import ArrayLike

from relocation_common import geometry
from relocation_common.scenario import Scenario, ShelfObject
from relocation_common.shelf_object import Footprint, at_pose

MARGIN = 0.003  # m left between a disturbed bottle and its neighbours or the shelf's sides
SLIP_CLEAR = 0.01  # m: a dropped bottle touches the hand again once this far from every finger and arm geom
PUSH_STEP = 0.001  # m: resolution of the slide of a nudge
TIP_DIRECTIONS = 12  # directions tried (evenly spaced from the asked one) for room to lie down
KINDS = ("nudge", "tip", "move", "drop")


class SimState(Protocol):
    """What a disturbance reads and changes of the simulation (sim.Jaco2Sim; named here, not imported: sim.py reads
    the driver's parameters, which read this module's plans)."""

    model: Any  # mujoco.MjModel
    data: Any  # mujoco.MjData
    scenario: Scenario
    grasped: str | None  # the bottle welded to the hand
    q_home: np.ndarray

    @property
    def time(self) -> float:
        """Simulated time (s)."""

    @property
    def q(self) -> np.ndarray:
        """The arm's joint angles (rad)."""

    def object_poses(self) -> list[Any]:
        """Every bottle's pose (sim.ObjectPose)."""


class DisturbanceError(ValueError):
    """A disturbance that cannot be applied (unknown or grasped bottle, no room); the message says why."""


@dataclass(frozen=True)
class Applied:
    """What a disturbance did: kind, bottle, simulated time, and the numbers (asked and applied)."""

    kind: str
    object_id: str
    sim_time: float
    detail: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready record for the report's `disturbances` list."""
        return {"kind": self.kind, "object": self.object_id, "sim_time": round(self.sim_time, 4), **self.detail}


# ------------------------------------------------------------------------------------------------ geometry helpers
def _body(sim: SimState, object_id: str) -> int:
    sim.scenario.world_object(object_id)  # UnknownObjectError naming the known ids
    return int(sim.model.body(object_id).id)


def _free_adr(sim: SimState, body: int) -> tuple[int, int]:
    j = sim.model.body_jntadr[body]
    return int(sim.model.jnt_qposadr[j]), int(sim.model.jnt_dofadr[j])


def _set_pose(sim: SimState, object_id: str, position: ArrayLike, quat_wxyz: ArrayLike) -> None:
    """Teleport an object (its body frame: base centre as built, orientation), at rest but awake (a sleeping body
    would hang where put)."""
    adr, vadr = _free_adr(sim, _body(sim, object_id))
    sim.data.qpos[adr:adr + 3] = position
    sim.data.qpos[adr + 3:adr + 7] = quat_wxyz
    sim.data.qvel[vadr:vadr + 6] = 0.0
    sim.data.qvel[vadr + 2] = -0.02
    mujoco.mj_forward(sim.model, sim.data)


def _pose(sim: SimState, object_id: str) -> tuple[np.ndarray, np.ndarray]:
    b = _body(sim, object_id)
    return sim.data.xpos[b].copy(), sim.data.xquat[b].copy()


def tilt(sim: SimState, object_id: str) -> float:
    """Angle (rad) between the object's body z axis (a cylinder's axis) and the vertical: 0 standing, pi/2 lying."""
    return geometry.tilt(sim.data.xmat[_body(sim, object_id)].reshape(3, 3))


def _rotation(sim: SimState, object_id: str) -> np.ndarray:
    return np.asarray(sim.data.xmat[_body(sim, object_id)], float).reshape(3, 3).copy()


def current(sim: SimState, object_id: str) -> ShelfObject:
    """The object as it is now (its primitive at the simulated pose: shelf_object.at_pose)."""
    o = sim.scenario.world_object(object_id)
    rot = _rotation(sim, object_id)
    return at_pose(o, sim.data.xpos[_body(sim, object_id)] + rot[:, 2] * o.size[2] / 2, rot)


def _half_extent(o: ShelfObject, rot: np.ndarray, u: np.ndarray) -> float:
    """Half the extent along the unit vector u of the object's primitive (as built) turned by rot."""
    if o.shape == "box":
        return float(sum(o.size[i] / 2 * abs(float(rot[:, i] @ u)) for i in range(3)))
    c = abs(float(rot[:, 2] @ u))
    return o.height / 2 * c + o.radius * math.sqrt(max(0.0, 1.0 - c * c))


Others = list[tuple[str, float, Footprint]]  # (id, support height, footprint) of the objects around one


def _others(sim: SimState, object_id: str) -> Others:
    """Every other object not in the hand, as it is now: its support height and footprint."""
    out = []
    for other in sim.scenario.world:
        if other.id != object_id and other.id != sim.grasped:
            now = current(sim, other.id)
            out.append((other.id, float(now.support_z or 0.0), now.footprint()))
    return out


def _room(sim: SimState, candidate: ShelfObject, others: Others | None = None) -> str | None:
    """Why `candidate` (an object at a pose it may be put at) does not fit, or None: its footprint must stay within
    the shelf's sides and depth and keep MARGIN from every other object resting near its height (`others`: those
    objects, `_others`, when a caller tries many poses)."""
    sh = sim.scenario.shelf
    if not candidate.footprint().inside(sh.x_front, sh.x_back - MARGIN, sh.y_min + MARGIN, sh.y_max - MARGIN):
        return "it would leave the shelf"
    grown = candidate.footprint(MARGIN)
    for oid, support, footprint in _others(sim, candidate.id) if others is None else others:
        if abs(support - float(candidate.support_z or 0.0)) > 0.05:
            continue  # on another board, or in the air
        if grown.overlaps(footprint):
            return f"it would overlap {oid}"
    return None


def _not_grasped(sim: SimState, object_id: str, kind: str) -> None:
    if sim.grasped == object_id:
        raise DisturbanceError(f"cannot {kind} {object_id}: it is in the hand (use drop_grasped)")


# ------------------------------------------------------------------------------------------------ disturbances
def nudge(sim: SimState, object_id: str, dx: float, dy: float) -> Applied:
    """Push an object horizontally by (dx, dy) m: it slides along the push, in PUSH_STEP increments, as far as it
    goes without touching another object or leaving the shelf. `detail`: asked and applied displacement."""
    _not_grasped(sim, object_id, "nudge")
    p, q = _pose(sim, object_id)
    now = current(sim, object_id)
    push = np.array([dx, dy], float)
    length = float(np.linalg.norm(push))
    if not math.isfinite(length):
        raise DisturbanceError(f"nudge of {object_id}: dx, dy must be finite, got {dx}, {dy}")
    steps = max(1, math.ceil(length / PUSH_STEP))
    done = np.zeros(2)
    others = _others(sim, object_id)
    for k in range(1, steps + 1):
        d = push * k / steps
        if _room(sim, replace(now, x=now.x + float(d[0]), y=now.y + float(d[1])), others) is not None:
            break
        done = d
    _set_pose(sim, object_id, (p[0] + done[0], p[1] + done[1], p[2]), q)
    return Applied("nudge", object_id, sim.time, {"asked": [float(dx), float(dy)],
                                                  "applied": [round(float(done[0]), 4), round(float(done[1]), 4)]})


def _tip_directions(now: ShelfObject, direction: float) -> list[float]:
    """The directions a tip tries, the asked one first: a cylinder, TIP_DIRECTIONS evenly spaced; a box, the normals
    of its four side faces (it falls over an edge onto a face), nearest the asked one first."""
    if now.shape != "box":
        return [direction + 2 * math.pi * k / TIP_DIRECTIONS for k in range(TIP_DIRECTIONS)]
    faces = [now.yaw + k * math.pi / 2 for k in range(4)]
    return sorted(faces, key=lambda a: abs(math.remainder(a - direction, 2 * math.pi)))


def tip(sim: SimState, object_id: str, direction: float = 0.0) -> Applied:
    """Tip an object over: it turns a quarter turn over its edge towards `direction` (rad, in the base frame's xy
    plane) and lies on its side on its board, beside where it stood; or towards the next direction with room
    (`_tip_directions`). DisturbanceError if none."""
    _not_grasped(sim, object_id, "tip")
    o, now, rot = sim.scenario.world_object(object_id), current(sim, object_id), _rotation(sim, object_id)
    centre = np.array([now.x, now.y]) if now.lying or now.shape == "box" else \
        np.asarray(sim.data.xpos[_body(sim, object_id)][:2], float)
    why, others = "no direction tried", _others(sim, object_id)
    for a in _tip_directions(now, direction):
        d = np.array([math.cos(a), math.sin(a), 0.0])
        turned = geometry.rotvec_matrix(np.cross([0.0, 0.0, 1.0], d) * math.pi / 2) @ rot
        xy = centre + d[:2] * (_half_extent(o, rot, d) + MARGIN + _half_extent(o, turned, d))
        c = np.array([xy[0], xy[1], float(now.support_z or 0.0) + _half_extent(o, turned, np.array([0, 0, 1.0]))])
        why = _room(sim, at_pose(o, c, turned), others) or ""
        if not why:
            _set_pose(sim, object_id, c - turned[:, 2] * o.size[2] / 2, geometry.quat_wxyz(turned))
            return Applied("tip", object_id, sim.time, {"direction": round(a % (2 * math.pi), 4)})
    raise DisturbanceError(f"cannot tip {object_id}: no room to lie down ({why} in every direction)")


def move_to(sim: SimState, object_id: str, x: float, y: float, z: float | None = None) -> Applied:
    """Stand an object at (x, y) on the board at height z (default: the top shelf, where objects stand): a
    cylinder upright, a box as built. DisturbanceError when it would overlap another object or leave the shelf."""
    _not_grasped(sim, object_id, "move")
    z = sim.scenario.shelf.top_z if z is None else float(z)
    o = sim.scenario.world_object(object_id)
    upright = replace(o, x=float(x), y=float(y), support_z=z, lying=False, tilt=None,
                      yaw=o.yaw if o.shape == "box" else 0.0)
    why = _room(sim, upright)
    if why:
        raise DisturbanceError(f"cannot move {object_id} to ({x:.3f}, {y:.3f}, {z:.3f}): {why}")
    before, _ = _pose(sim, object_id)
    _set_pose(sim, object_id, (x, y, z), geometry.quat_wxyz(upright.rotation()))
    return Applied("move", object_id, sim.time, {"from": [round(float(v), 4) for v in before],
                                                 "to": [round(float(x), 4), round(float(y), 4), round(z, 4)]})


def clear_of_hand(sim: SimState, object_id: str) -> bool:
    """True when the bottle is SLIP_CLEAR from every geom of the arm and the fingers (contype 2)."""
    m, g = sim.model, int(sim.model.geom(f"{object_id}_geom").id)
    hand = [k for k in range(m.ngeom) if m.geom_contype[k] & 2]
    return all(mujoco.mj_geomDistance(m, sim.data, g, k, SLIP_CLEAR, None) >= SLIP_CLEAR for k in hand)


def drop_grasped(sim: SimState) -> Applied | None:
    """The carried bottle slips out of the hand now (None when nothing is grasped): the grasp weld is switched off,
    its weight comes back, and it stops touching the fingers (it would stay wedged between them) until
    `CarryDropper.update` (or `restore_contacts`, once `clear_of_hand`) gives the contacts back. The fingers stay
    commanded closed."""
    oid = sim.grasped
    if oid is None:
        return None
    b = _body(sim, oid)
    sim.data.eq_active[sim.model.equality(f"grasp_{oid}").id] = 0
    sim.model.body_gravcomp[b] = 0.0
    sim.grasped = None
    g = int(sim.model.geom(f"{oid}_geom").id)
    sim.model.geom_contype[g] = 0  # no contact with the fingers and arm (contype 2); still with boards and bottles
    sim.model.geom_conaffinity[g] = 1
    sim.data.qvel[_free_adr(sim, b)[1] + 2] = -0.02  # awake: a body held still sleeps with the hand (sim._let_go)
    p, _ = _pose(sim, oid)
    return Applied("drop", oid, sim.time, {"at": [round(float(v), 4) for v in p]})


def restore_contacts(sim: SimState, object_id: str) -> None:
    """Give a dropped bottle its contacts with the fingers back (the bottle class: contype 1, conaffinity 3)."""
    g = int(sim.model.geom(f"{object_id}_geom").id)
    sim.model.geom_contype[g], sim.model.geom_conaffinity[g] = 1, 3


def restore_all_contacts(sim: SimState) -> None:
    """Every bottle's contacts as built (Jaco2Sim.reset restores the data, not these model fields): call it with a
    scene reset, in case a dropped bottle was still slipping."""
    for b in sim.scenario.world:
        restore_contacts(sim, b.id)


class CarryDropper:
    """Drops the carried bottle during some carries, called once per loop of the simulator (`update`).

    Each new grasp is a carry (counted from 0); the bottle is dropped `delay` s of simulated time after the grasp
    (seeded, uniform in `delay_range`) when the carry index is in `carries`, or with `probability` otherwise.
    A dropped bottle gets its contacts with the hand back once it is SLIP_CLEAR from the fingers and the arm."""

    def __init__(self, probability: float = 0.0, seed: int = 0, carries: Iterable[int] = (),
                 delay_range: tuple[float, float] = (0.3, 1.0)) -> None:
        if not 0.0 <= probability <= 1.0:
            raise ValueError(f"drop probability must be in [0, 1], got {probability!r}")
        if not 0.0 <= delay_range[0] <= delay_range[1]:
            raise ValueError(f"delay_range must be (lo, hi) with 0 <= lo <= hi, got {delay_range!r}")
        self.probability, self.carries, self.delay_range = probability, frozenset(carries), delay_range
        self.rng = random.Random(seed)
        self.carry = -1  # index of the current (or last) carry
        self._held: str | None = None
        self._drop_at: float | None = None  # simulated time of the planned drop of this carry
        self._slipping: str | None = None  # a dropped bottle without contacts with the hand yet
        self.applied: list[Applied] = []

    def update(self, sim: SimState) -> Applied | None:
        """Count grasps, drop when due, give contacts back; returns the drop made now, if any."""
        if self._slipping is not None and clear_of_hand(sim, self._slipping):
            restore_contacts(sim, self._slipping)
            self._slipping = None
        if sim.grasped != self._held:
            self._held = sim.grasped
            self._drop_at = None
            if sim.grasped is not None:
                self.carry += 1
                draw, delay = self.rng.random(), self.rng.uniform(*self.delay_range)  # both drawn: reproducible
                if self.carry in self.carries or draw < self.probability:
                    self._drop_at = sim.time + delay
        if self._drop_at is not None and sim.grasped is not None and sim.time >= self._drop_at:
            applied = drop_grasped(sim)
            self._drop_at, self._held = None, None
            if applied is not None:
                self._slipping = applied.object_id
                self.applied.append(applied)
                return Applied("drop", applied.object_id, applied.sim_time, {**applied.detail, "carry": self.carry})
        return None


# ------------------------------------------------------------------------------------------------ seeded plans
@dataclass(frozen=True)
class Disturbance:
    """One planned disturbance: what, when (after relocation i: before the next one starts; during carry i: while
    relocation i carries its bottle), on which bottle (`choice` in [0, 1) picks among those standing on the top
    shelf at that moment, in id order) and how much (nudge: `amount` m towards `direction` rad; tip: towards
    `direction`; move: to the fractions `where` of the shelf's depth and width)."""

    kind: str
    moment: str  # "after" or "during"
    relocation: int  # 0-based index of the relocation executed (whatever its object)
    choice: float = 0.0
    amount: float = 0.0
    direction: float = 0.0
    where: tuple[float, float] = (0.5, 0.5)

    @property
    def when(self) -> str:
        """'after relocation 2' or 'during carry 3' (1-based, as a user counts)."""
        return f"after relocation {self.relocation + 1}" if self.moment == "after" else \
            f"during carry {self.relocation + 1}"

    def pick(self, candidates: Iterable[str]) -> str | None:
        """The bottle this disturbance acts on among `candidates` (None if there are none)."""
        c = sorted(candidates)
        return c[min(len(c) - 1, int(self.choice * len(c)))] if c else None

    def to_dict(self) -> dict[str, Any]:
        """The planned disturbance, JSON-ready."""
        d: dict[str, Any] = {"kind": self.kind, "when": self.when, "moment": self.moment,
                             "relocation": self.relocation}
        if self.kind == "nudge":
            d.update(amount=round(self.amount, 4), direction=round(self.direction, 4))
        elif self.kind == "tip":
            d.update(direction=round(self.direction, 4))
        elif self.kind == "move":
            d.update(where=[round(w, 4) for w in self.where])
        return d


@dataclass(frozen=True)
class DisturbancePlan:
    """K seeded disturbances at moments of an execution of `relocations` relocations (the target's included)."""

    seed: int
    disturbances: tuple[Disturbance, ...]

    @classmethod
    def draw(cls, k: int, seed: int, relocations: int, kinds: Iterable[str] = KINDS,
             nudge_range: tuple[float, float] = (0.01, 0.04)) -> "DisturbancePlan":
        """K disturbances drawn with random.Random(seed): a kind from `kinds`, a moment (a drop: during one of the
        carries; the others: after one of the first relocations - 1, i.e. with a relocation still to come), a
        choice of bottle, an amount. Sorted by moment; the same arguments give the same plan."""
        kinds = tuple(kinds)
        unknown = set(kinds) - set(KINDS)
        if unknown or not kinds:
            raise ValueError(f"kinds must be among {', '.join(KINDS)}, got {sorted(unknown) or 'none'}")
        if k < 0 or relocations < 1:
            raise ValueError(f"need k >= 0 and relocations >= 1, got k={k}, relocations={relocations}")
        if relocations == 1 and k and "drop" not in kinds:
            raise ValueError("with one relocation only a drop (during its carry) has a moment: add 'drop' to kinds")
        rng = random.Random(seed)
        out = []
        for _ in range(k):
            kind = rng.choice(kinds if relocations > 1 else ("drop",))
            moment = "during" if kind == "drop" else "after"
            i = rng.randrange(relocations if kind == "drop" else relocations - 1)
            out.append(Disturbance(kind, moment, i, choice=rng.random(), amount=rng.uniform(*nudge_range),
                                   direction=rng.uniform(0, 2 * math.pi), where=(rng.random(), rng.random())))
        order = {"after": 1, "during": 0}
        return cls(seed, tuple(sorted(out, key=lambda d: (d.relocation, order[d.moment]))))

    def at(self, moment: str, relocation: int) -> list[Disturbance]:
        """The disturbances due at that moment."""
        return [d for d in self.disturbances if d.moment == moment and d.relocation == relocation]

    def to_list(self) -> list[dict[str, Any]]:
        """The report's `disturbances` (planned; `apply` records add what was done)."""
        return [d.to_dict() for d in self.disturbances]

    def to_json(self) -> str:
        """The whole plan as one JSON string (a string parameter of the driver), read back by `from_json`."""
        return json.dumps({"seed": self.seed, "disturbances": [dataclasses.asdict(d) for d in self.disturbances]})

    @classmethod
    def from_json(cls, text: str) -> "DisturbancePlan":
        """The plan of `to_json`; ValueError naming what is wrong."""
        try:
            data = json.loads(text)
            ds = tuple(Disturbance(**{**d, "where": tuple(d.get("where", (0.5, 0.5)))}) for d in data["disturbances"])
            plan = cls(int(data["seed"]), ds)
        except (ValueError, KeyError, TypeError) as e:
            raise ValueError(f"not a disturbance plan (DisturbancePlan.to_json): {e}") from None
        bad = [d for d in ds if d.kind not in KINDS or d.moment not in ("after", "during") or d.relocation < 0]
        if bad:
            raise ValueError(f"disturbance plan: bad entry {bad[0]}")
        return plan


def on_top_shelf(sim: SimState, tol: float = 0.02) -> list[str]:
    """Ids of the objects standing on the top shelf (support within tol of top_z, not lying), not in the hand."""
    top = sim.scenario.shelf.top_z
    return [p.id for p in sim.object_poses() if p.id != sim.grasped and
            abs(float(current(sim, p.id).support_z or 0.0) - top) < tol and tilt(sim, p.id) < math.radians(20)]


def apply(sim: SimState, d: Disturbance) -> dict[str, Any]:
    """Apply a planned disturbance now; the report record: the plan's entry plus what was done (`object`,
    `sim_time` and the numbers) or `skipped` with the reason (nothing in the hand to drop, no bottle, no room)."""
    record = d.to_dict()
    try:
        if d.kind == "drop":
            done = drop_grasped(sim)
            if done is None:
                return {**record, "skipped": "nothing in the hand"}
            return {**record, **done.to_dict()}
        oid = d.pick(on_top_shelf(sim))
        if oid is None:
            return {**record, "skipped": "no bottle on the top shelf"}
        if d.kind == "nudge":
            done = nudge(sim, oid, d.amount * math.cos(d.direction), d.amount * math.sin(d.direction))
        elif d.kind == "tip":
            done = tip(sim, oid, d.direction)
        else:
            done = _move_somewhere(sim, oid, d.where)
        return {**record, **done.to_dict()}
    except DisturbanceError as e:
        return {**record, "skipped": str(e)}


def _move_somewhere(sim: SimState, object_id: str, where: tuple[float, float]) -> Applied:
    """move_to the first free spot of a 1 cm grid on the top shelf, nearest to the fractions `where`."""
    sh, o = sim.scenario.shelf, sim.scenario.world_object(object_id)
    r = max(o.size[0], o.size[1]) / 2  # the grid's margin from the edges: move_to checks the footprint itself
    x0, x1 = sh.x_front + r, sh.x_back - r - MARGIN
    y0, y1 = sh.y_min + r + MARGIN, sh.y_max - r - MARGIN
    want = np.array([x0 + where[0] * (x1 - x0), y0 + where[1] * (y1 - y0)])
    grid = [np.array([x, y]) for x in np.arange(x0, x1 + 1e-9, 0.01) for y in np.arange(y0, y1 + 1e-9, 0.01)]
    yaw = o.yaw if o.shape == "box" else 0.0
    others = _others(sim, object_id)
    for xy in sorted(grid, key=lambda g: float(np.linalg.norm(g - want))):
        spot = replace(o, x=float(xy[0]), y=float(xy[1]), support_z=sh.top_z, lying=False, tilt=None, yaw=yaw)
        if _room(sim, spot, others) is None:
            return move_to(sim, object_id, float(xy[0]), float(xy[1]))
    raise DisturbanceError(f"cannot move {object_id}: no free spot on the top shelf")


class DisturbanceSchedule:
    """Applies a DisturbancePlan while an execution goes on, from what the simulator shows (the driver calls
    `update` once per loop): carry j begins with the (j+1)-th grasp, and relocation i has ended once the (i+1)-th
    carried bottle was released (or dropped) and the arm is back within `home_tol` rad of home (the motion
    planner's home_tol, config/motion_planner.yaml: its relocation ends there). A drop happens `drop_delay` s after
    its carry's grasp; a disturbance whose moment has passed is recorded as skipped."""

    def __init__(self, plan: DisturbancePlan, home_tol: float, drop_delay: float = 0.5) -> None:
        self.plan, self.home_tol, self.drop_delay = plan, home_tol, drop_delay
        self.pending = list(plan.disturbances)
        self.records: list[dict[str, Any]] = []  # the report's `disturbances`, in the order they happened
        self.carries = self.ended = 0
        self._held: str | None = None
        self._grasped_at = 0.0
        self._slipping: str | None = None

    def at_home(self, sim: SimState) -> bool:
        """The arm within home_tol of its home angles (continuous joints compared modulo 2 pi)."""
        d = (np.asarray(sim.q) - np.asarray(sim.q_home) + math.pi) % (2 * math.pi) - math.pi
        return float(np.max(np.abs(d))) < self.home_tol

    def update(self, sim: SimState) -> list[dict[str, Any]]:
        """Track grasps and releases, apply what is due; returns the records made now."""
        if self._slipping is not None and clear_of_hand(sim, self._slipping):
            restore_contacts(sim, self._slipping)
            self._slipping = None
        if sim.grasped != self._held:
            self.ended += self._held is not None
            if sim.grasped is not None:
                self.carries, self._grasped_at = self.carries + 1, sim.time
            self._held = sim.grasped
        out = []
        for d in list(self.pending):
            n = d.relocation + 1
            if d.moment == "during":
                due = self.carries == n and sim.grasped is not None and sim.time - self._grasped_at >= self.drop_delay
                missed = self.carries > n or self.ended >= n
            else:
                due = self.ended >= n and sim.grasped is None and self.at_home(sim)
                missed = self.carries > n
            if due or missed:
                self.pending.remove(d)
                record = apply(sim, d) if due else {**d.to_dict(), "skipped": "its moment has passed"}
                if due and d.kind == "drop" and "object" in record:
                    self._slipping = record["object"]
                out.append(record)
        self.records += out
        return out


GRASPED = "grasped"  # the command's object for "the bottle in the hand" (a drop)


def command(sim: SimState, object_id: str, relative: bool, translation: Iterable[float],
            rotation_xyzw: Iterable[float] = (0.0, 0.0, 0.0, 1.0)) -> dict[str, Any]:
    """One disturbance as a transform command (the driver's geometry_msgs/TransformStamped on its disturb topic):
    object GRASPED: drop the bottle in the hand; `relative` (the transform is in the bottle's own frame): a
    rotation other than the identity tips the bottle towards where it turns the bottle's axis, else a nudge by
    the translation's (x, y); absolute (the base frame): move the bottle, upright, to the translation. Returns the
    record (as `apply`'s); a command that cannot be applied (unknown bottle, no room, nothing in the hand) is
    recorded as `skipped` with the reason, and changes nothing."""
    t = [float(v) for v in translation]
    qx, qy, qz, qw = (float(v) for v in rotation_xyzw)
    record: dict[str, Any] = {"command": {"object": object_id, "relative": bool(relative), "translation": t,
                                          "rotation_xyzw": [qx, qy, qz, qw]}}
    try:
        if not all(math.isfinite(v) for v in (*t, qx, qy, qz, qw)):
            raise DisturbanceError("the transform has NaN or Inf")
        if object_id == GRASPED:
            done = drop_grasped(sim)
            if done is None:
                raise DisturbanceError("nothing in the hand to drop")
        elif not relative:
            done = move_to(sim, object_id, t[0], t[1], t[2])
        elif abs(abs(qw) - 1.0) > 1e-6:  # the bottle's z axis turned by the rotation: the tip's direction
            ax, ay, _ = geometry.xyzw_matrix((qx, qy, qz, qw))[:, 2]
            if math.hypot(ax, ay) < 1e-6:
                raise DisturbanceError("a rotation about the bottle's own axis does not tip it")
            done = tip(sim, object_id, math.atan2(ay, ax))
        else:
            done = nudge(sim, object_id, t[0], t[1])
    except (DisturbanceError, KeyError) as e:
        return {**record, "skipped": str(e.args[0] if isinstance(e, KeyError) and e.args else e)}
    return {**record, **done.to_dict()}
