"""Collision scene with python-fcl: arm capsules vs shelf boards vs objects (the clearance tasks of Eq. 10).

Obstacles are the shelf boards (top shelf, ceiling board, bottom shelf, side panels, back panel), the floor, the
pedestal under the robot and every object of the scene, listed in the scenario or not, as the primitive it is
(`object_obstacle`: a cylinder standing or lying, an oriented box; a conservative object is its bounding box);
objects already relocated may stand on the bottom shelf (`placed`: a bottle as its cylinder, a box as the upright
box that holds it as the side grasp placed it, `grasp.placed_sides`). The set of removed objects is a parameter of
every query (`CollisionScene.obstacles(removed)`). A numpy AABB broad phase keeps only the capsule/obstacle pairs
closer than an activation distance; fcl computes their exact distances and witness points (in the base frame). fcl
returns -1 on penetration.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Iterable, Iterator, Mapping, Sequence

import fcl
import numpy as np
from numpy.typing import ArrayLike

from relocation_common import robot_description as rd
from relocation_common.geometry import wxyz_matrix
from relocation_common.scenario import Scenario, ShelfObject
from stpik_motion_planner.model.grasp import placed_sides
from stpik_motion_planner.model.kinematics import Kinematics

PENETRATION = -1.0  # what fcl.distance returns for intersecting shapes
Skip = Mapping[str, frozenset[str]]  # a shape's name -> the bottles and boards it may touch in one query


@dataclass
class Obstacle:
    """One collision object of the scene: a shelf board or an object, with its axis-aligned bounding box."""

    name: str
    object_id: str | None  # object id, None for a board
    obj: fcl.CollisionObject
    lo: np.ndarray
    hi: np.ndarray


@dataclass
class ObstacleSet:
    """The obstacles present in one query (boards + bottles not removed)."""

    items: list[Obstacle]
    lo: np.ndarray = field(init=False)
    hi: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        self.lo = np.array([o.lo for o in self.items]).reshape(-1, 3)
        self.hi = np.array([o.hi for o in self.items]).reshape(-1, 3)
        self.lo_neg_hi = np.hstack([self.lo, -self.hi])  # AABB overlap in one comparison (HandProxy.collides)


def _key(o: Obstacle) -> str:
    """What a query's `skip` names an obstacle by: the bottle id, or the board's name (e.g. "board:top_shelf")."""
    return o.object_id if o.object_id is not None else o.name


def _box(name: str, lo: ArrayLike, hi: ArrayLike) -> Obstacle:
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    obj = fcl.CollisionObject(fcl.Box(*(hi - lo)), fcl.Transform(np.eye(3), (lo + hi) / 2))
    return Obstacle(name, None, obj, lo, hi)


def cylinder(name: str, object_id: str | None, x: float, y: float, z0: float, radius: float,
             height: float) -> Obstacle:
    """A vertical cylinder (bottle) standing at z0."""
    obj = fcl.CollisionObject(fcl.Cylinder(radius, height), fcl.Transform(np.eye(3), np.array([x, y, z0 + height / 2])))
    return Obstacle(name, object_id, obj, np.array([x - radius, y - radius, z0]),
                    np.array([x + radius, y + radius, z0 + height]))


@dataclass(frozen=True)
class Lying:
    """A bottle that does not stand (tipped over, lying on the top board): the centre of its base (base frame, m)
    and its orientation as a quaternion in MuJoCo's order (w, x, y, z): the node reorders ObjectState's pose."""

    base: tuple[float, float, float]
    quat: tuple[float, float, float, float]


def lying_cylinder(name: str, object_id: str | None, pose: Lying, radius: float, height: float) -> Obstacle:
    """A bottle at any orientation, as the simulator has it: a cylinder along its own z axis from its base centre."""
    rot = wxyz_matrix(pose.quat)
    base = np.asarray(pose.base, float)
    top = base + rot[:, 2] * height
    obj = fcl.CollisionObject(fcl.Cylinder(radius, height), fcl.Transform(rot, (base + top) / 2))
    return Obstacle(name, object_id, obj, np.minimum(base, top) - radius, np.maximum(base, top) + radius)


def object_obstacle(o: ShelfObject, top_z: float) -> Obstacle:
    """Any object of the scene as the primitive it is, named "bottle:<id>" (a query's `skip` names it by its id): an
    upright cylinder standing on the top shelf (`top_z`) as `cylinder` has always modelled it; a lying or leaning
    cylinder along its axis, a box turned by its yaw, both at the primitive's centre (shelf_object.ShelfObject.centre,
    on its own support or the top shelf). A conservative object is a box (its bounding box) like any other."""
    name = f"bottle:{o.id}"
    if o.shape == "cylinder" and o.axis_tilt == 0.0:
        return cylinder(name, o.id, o.x, o.y, top_z, o.radius, o.height)
    placed = o if o.support_z is not None else replace(o, support_z=top_z)
    rot, centre = placed.rotation(), placed.centre()
    if o.shape == "box":
        shape: fcl.CollisionGeometry = fcl.Box(*o.size)
        half = np.abs(rot) @ (np.asarray(o.size, float) / 2)
    else:
        shape = fcl.Cylinder(o.radius, o.height)
        axis = np.abs(rot[:, 2])  # the cylinder's extent along each world axis: its axis's, plus the disc's
        half = axis * o.height / 2 + o.radius * np.sqrt(np.maximum(0.0, 1.0 - axis ** 2))
    obj = fcl.CollisionObject(shape, fcl.Transform(rot, centre))
    return Obstacle(name, o.id, obj, centre - half, centre + half)


# The rest of the world of the simulator's scene (jaco2_sim_driver/scene.py, which this layer cannot import; the
# independent motion checker in the tests replays plans in that scene and finds any difference): the floor
# FLOOR_DROP below the bottom board, the shelf's side and back panels down to it, the pedestal under the robot base.
FLOOR_DROP = 0.30
PEDESTAL = ((-0.11, -0.09), (0.07, 0.09))  # (x, y) of its lower and upper corners; its top is the base frame z = 0


def shelf_boards(scenario: Scenario) -> list[Obstacle]:
    """The boards, the floor and the pedestal (named board:*: a query's `skip` may name them)."""
    s = scenario.shelf
    t = s.board_thickness
    x0, x1, y0, y1 = s.x_front, s.x_back, s.y_min, s.y_max
    floor = s.bottom_z - FLOOR_DROP
    (px0, py0), (px1, py1) = PEDESTAL
    return [
        _box("board:top_shelf", (x0, y0, s.top_z - t), (x1, y1, s.top_z)),
        _box("board:ceiling", (x0, y0, s.ceiling_z), (x1, y1, s.ceiling_z + t)),
        _box("board:bottom_shelf", (x0, y0, s.bottom_z - t), (x1, y1, s.bottom_z)),
        _box("board:side_right", (x0, y0 - t, floor), (x1, y0, s.ceiling_z + t)),
        _box("board:side_left", (x0, y1, floor), (x1, y1 + t, s.ceiling_z + t)),
        _box("board:back", (x1, y0 - t, floor), (x1 + t, y1 + t, s.ceiling_z + t)),
        _box("board:floor", (-1.5, -1.5, floor - 0.1), (1.5, 1.5, floor)),
        _box("board:pedestal", (px0, py0, floor), (px1, py1, 0.0)),
    ]


def placed_obstacle(o: ShelfObject, x: float, y: float, z0: float, turn: float) -> Obstacle:
    """An object the side grasp placed standing on the board at z0, centred on (x, y), named "placed:<id>" (a
    query's `skip` names it so): a bottle as its cylinder; a box as the upright box of `grasp.placed_sides` (square
    to the shelf, holding it turned by up to `turn` rad)."""
    name = f"placed:{o.id}"
    if o.shape != "box":
        return cylinder(name, name, x, y, z0, o.radius, o.height)
    half = np.array([*placed_sides(o, turn), o.height]) / 2
    centre = np.array([x, y, z0 + o.height / 2])
    obj = fcl.CollisionObject(fcl.Box(*(2 * half)), fcl.Transform(np.eye(3), centre))
    return Obstacle(name, name, obj, centre - half, centre + half)


class CollisionScene:
    """Boards and objects of a scenario (every one, listed or not, as its primitive: `object_obstacle`). `placed`: (id,
    (x, y)) of objects standing on the bottom shelf (centred there; a box turned up to `placed_turn` rad from square to
    the shelf: `placed_obstacle`); `lying`: bottles of the top shelf that do not stand as perception saw them
    (scene_update.lying_pose); `gone`: objects that left the shelf (on the floor), no obstacle."""

    def __init__(self, scenario: Scenario, placed: Sequence[tuple[str, tuple[float, float]]] = (),
                 lying: Mapping[str, Lying] | None = None, gone: Iterable[str] = (), placed_turn: float = 0.0) -> None:
        self.scenario = scenario
        self.boards = shelf_boards(scenario)
        z0 = scenario.shelf.top_z
        lying, gone = lying or {}, frozenset(gone)
        self.bottles = {b.id: lying_cylinder(f"bottle:{b.id}", b.id, lying[b.id], b.radius, b.height)
                        if b.id in lying else object_obstacle(b, z0)
                        for b in scenario.objects if b.id not in gone}
        zb = scenario.shelf.bottom_z
        self.placed = [placed_obstacle(scenario.object(oid), x, y, zb, placed_turn) for oid, (x, y) in placed]
        self._cache: dict[tuple[frozenset, frozenset], ObstacleSet] = {}

    def obstacles(self, removed: Iterable[str] = frozenset(), exclude: Iterable[str] = frozenset()) -> ObstacleSet:
        """Boards, placed bottles and the top-shelf objects that are neither removed nor excluded."""
        key = (frozenset(removed), frozenset(exclude))
        got = self._cache.get(key)
        if got is None:
            gone = key[0] | key[1]
            got = ObstacleSet(self.boards + self.placed + [o for i, o in self.bottles.items() if i not in gone])
            self._cache[key] = got
        return got


@dataclass(frozen=True)
class CapsuleSpec:
    """A capsule (or cylinder) of the collision model in its link's frame, with fcl's frame of it."""

    name: str
    link: str
    p0: np.ndarray
    p1: np.ndarray
    radius: float
    rot: np.ndarray  # fcl capsule frame (z along p0->p1) in the link frame
    centre: np.ndarray
    length: float
    cylinder: bool = False  # a cylinder between p0 and p1 instead of a capsule (for obstacles)
    clearance: float | None = None  # its own clearance bound to obstacles (None: the planner's)
    box: tuple[float, float, float] | None = None  # a box of these sides (x, y, z of `rot`) instead (`radius`:
    # half its diagonal across z, for the broad phase and the self-distances, which see it as that capsule)


def capsule_spec(name: str, link: str, p0: ArrayLike, p1: ArrayLike, radius: float, cylinder: bool = False,
                 clearance: float | None = None, box: tuple[float, float, float] | None = None) -> CapsuleSpec:
    """CapsuleSpec of the segment p0-p1 of radius `radius` in `link`'s frame."""
    p0, p1 = np.asarray(p0, float), np.asarray(p1, float)
    axis = p1 - p0
    length = float(np.linalg.norm(axis))
    z = axis / length
    x = np.cross([0.0, 1.0, 0.0], z) if abs(z[1]) < 0.9 else np.cross([1.0, 0.0, 0.0], z)
    x /= np.linalg.norm(x)
    return CapsuleSpec(name, link, p0, p1, radius, np.column_stack([x, np.cross(z, x), z]), (p0 + p1) / 2, length,
                       cylinder, clearance, box)


def carried_bottle(radius: float, height: float, standoff: float = 0.0,
                   clearance: float | None = None, tilt: float = 0.0) -> CapsuleSpec:
    """The grasped bottle at its real size: a cylinder on link 7 (its axis along tool y, tilted by `tilt` towards
    tool z for a grasp from above: grasp.held_tilt; the bottle's centre `standoff` beyond the tool origin along tool
    z, the tool at its mid-height, as `grasp.side_grasp` places it).
    `clearance`: its bound to obstacles (None: the arm's). Contact where it is intended (the board the bottle stands
    on while it is lifted) is exempted by the caller with the `skip` of a query, never by shrinking the model."""
    half = height / 2
    z = rd.D67 + standoff
    if tilt:
        a, b = half * math.cos(tilt), half * math.sin(tilt)
        return capsule_spec(CARRIED, rd.LINK_NAMES[6], (0, -a, z - b), (0, a, z + b), radius, cylinder=True,
                            clearance=clearance)
    return capsule_spec(CARRIED, rd.LINK_NAMES[6], (0, -half, z), (0, half, z), radius, cylinder=True,
                        clearance=clearance)


def carried_box(depth: float, width: float, height: float, standoff: float, turn: float,
                clearance: float | None = None) -> CapsuleSpec:
    """The grasped box at its real size as `grasp.side_grasp` takes it: `depth` along the approach (tool z),
    `width` across it (tool x, the fingers' closing direction), `height` along tool y (vertical), its centre
    `standoff` beyond the tool origin along tool z at the tool's height, turned by `turn` (rad, counter-clockwise
    seen from above) from square to the hand (the tool's yaw error at the grasp). Named and exempted as
    `carried_bottle`."""
    half = height / 2
    z = rd.D67 + standoff
    # capsule_spec's frame of a segment along link y: its x is link z (the approach), its y link x (closing), its z
    # link y (up): a turn seen from above is a turn about its z
    spec = capsule_spec(CARRIED, rd.LINK_NAMES[6], (0, -half, z), (0, half, z), math.hypot(depth, width) / 2,
                        clearance=clearance, box=(depth, width, height))
    c, s = math.cos(turn), math.sin(turn)
    return replace(spec, rot=spec.rot @ np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]))


def _fcl_shape(s: CapsuleSpec, inflate: float = 0.0) -> fcl.CollisionGeometry:
    if s.box is not None:
        return fcl.Box(*(np.asarray(s.box, float) + 2 * inflate))
    if s.cylinder:
        return fcl.Cylinder(s.radius + inflate, s.length + 2 * inflate)
    return fcl.Capsule(s.radius + inflate, s.length)


HAND_PARTS = ("palm", "finger_1", "finger_2", "finger_3")
CARRIED = "carried"  # name of the attached bottle's shape


def approach_skip(o: ShelfObject) -> dict[str, frozenset[str]]:
    """What the hand may touch on the straight approach to a grasp of `o` and on its lift: the object (the palm and
    fingers); for a grasp from above of a lying cylinder, the fingers also the board it lies on, which they come
    grasp.FINGER_FLOOR near."""
    board = frozenset(["board:top_shelf"]) if o.lying else frozenset()
    return {n: frozenset([o.id]) | (board if n.startswith("finger") else frozenset()) for n in HAND_PARTS}


def closed_fingers() -> dict[str, CapsuleSpec]:
    """The description's finger capsules (their radius) with the fingers closed on nothing, as the simulator's
    hinges turn them (robot_description.FINGER_HINGES, FINGER_CLOSED): from the hinge to the tip, which comes to
    about 2 mm from the tool axis, 20 mm beyond the grasp centre. The hand of a push (planning/push/)."""
    out = {}
    for k, (x, y, sign) in enumerate(rd.FINGER_HINGES):
        c = next(c for c in rd.CAPSULES if c.name == f"finger_{k + 1}")
        a = sign * rd.FINGER_CLOSED  # about the link's y axis
        tx, _, tz = rd.finger_tip(k)
        tip = (x + tx * math.cos(a) + tz * math.sin(a), y, rd.FINGER_BASE_Z - tx * math.sin(a) + tz * math.cos(a))
        out[c.name] = capsule_spec(c.name, c.link, (x, y, rd.FINGER_BASE_Z), tip, c.radius)
    return out


def _hand_specs(names: Iterable[str], fingers: Mapping[str, CapsuleSpec] | None) -> list[CapsuleSpec]:
    """The description's capsules of `names`, the fingers replaced by `fingers` (closed_fingers) when given."""
    by = {c.name: c for c in rd.CAPSULES}
    return [fingers[n] if fingers and n in fingers else capsule_spec(n, by[n].link, by[n].p0, by[n].p1, by[n].radius)
            for n in names]


class ArmGeometry:
    """The arm's capsules (plus attached ones, e.g. a carried bottle), posed from a Kinematics update; `fingers`:
    finger capsules in place of the open ones (closed_fingers)."""

    def __init__(self, kin: Kinematics, attached: Sequence[CapsuleSpec] = (),
                 fingers: Mapping[str, CapsuleSpec] | None = None) -> None:
        self.kin = kin
        self.specs = _hand_specs([c.name for c in rd.CAPSULES], fingers) + list(attached)
        self.n = len(self.specs)
        self.fids = [kin.fid[s.link] for s in self.specs]
        self.radius = np.array([s.radius for s in self.specs])
        self.objs = [fcl.CollisionObject(_fcl_shape(s), fcl.Transform()) for s in self.specs]
        names = [s.name for s in self.specs]
        self.index = {n: i for i, n in enumerate(names)}
        # base and shoulder never leave the robot's pedestal: not checked against the shelf
        self.moving = np.array([i for i, s in enumerate(self.specs) if s.name not in ("base", "shoulder")])
        hand = set(HAND_PARTS) | {"wrist", CARRIED}
        # forearm-palm: the wrist capsule lies between them; within joint 6's limits (Table 6) they stay more
        # than 0.02 m apart, so the pair is left out like the adjacent ones. The carried bottle and the hand holding
        # it: fixed to each other (the fingers touch it by design).
        adjacent = set(rd.ADJACENT) | {frozenset((CARRIED, h)) for h in hand} | {frozenset(("forearm", "palm"))}
        self.self_pairs = [(i, j) for i in range(self.n) for j in range(i + 1, self.n)
                           if frozenset((names[i], names[j])) not in adjacent]
        self._si = np.array([i for i, _ in self.self_pairs])
        self._sj = np.array([j for _, j in self.self_pairs])
        self._l0 = np.array([s.p0 for s in self.specs])
        self._l1 = np.array([s.p1 for s in self.specs])
        self._links = sorted(set(self.fids))
        self._li = np.array([self._links.index(f) for f in self.fids])  # capsule -> row of the link arrays
        self._rot = np.zeros((len(self._links), 3, 3))
        self._pos = np.zeros((len(self._links), 3))
        self._frames = np.zeros((len(self._links), 4, 4))  # pose's work array
        self._li2 = np.concatenate([self._li, self._li])  # both endpoints' rows, p0's then p1's
        self._ends = np.vstack([self._l0, self._l1])
        self._dirty = [True] * self.n
        self._names = names
        self._distance_request = fcl.DistanceRequest(enable_nearest_points=True)  # read, never written, by fcl
        self.p0 = np.zeros((self.n, 3))
        self.p1 = np.zeros((self.n, 3))

    def pose(self) -> None:
        """Place every capsule from the current Kinematics data (call after kin.update): all links at once, both
        endpoints of every capsule in one product (each row as its own product: the same numbers)."""
        frames, view = self._frames, self.kin.placement_view
        for k, fid in enumerate(self._links):
            frames[k] = view(fid).homogeneous
        self._rot[:] = frames[:, :3, :3]
        self._pos[:] = frames[:, :3, 3]
        ends = np.einsum("nij,nj->ni", self._rot[self._li2], self._ends)
        ends += self._pos[self._li2]
        self.p0, self.p1 = ends[:self.n], ends[self.n:]
        rad = self.radius[:, None]
        self._lo = np.minimum(self.p0, self.p1) - rad  # AABBs for both broad phases
        self._hi = np.maximum(self.p0, self.p1) + rad
        self._moving_lo, self._moving_hi = self._lo[self.moving], self._hi[self.moving]
        self._dirty = [True] * self.n

    def moving_boxes(self) -> tuple[np.ndarray, np.ndarray]:
        """(lo, hi) of the axis-aligned boxes of the capsules near_pairs looks at, at the current pose."""
        return self._moving_lo, self._moving_hi

    def _fcl(self, i: int) -> fcl.CollisionObject:
        """The fcl object of capsule i at its current pose (transforms are set lazily)."""
        if self._dirty[i]:
            k = self._li[i]
            r, p = self._rot[k], self._pos[k]
            s = self.specs[i]
            self.objs[i].setTransform(fcl.Transform(r @ s.rot, r @ s.centre + p))
            self._dirty[i] = False
        return self.objs[i]

    def near_pairs(self, obs: ObstacleSet, d_act: float) -> tuple[np.ndarray, np.ndarray]:
        """Broad phase: (capsule, obstacle) index pairs whose AABBs are closer than d_act."""
        idx = self.moving
        lo, hi = self._moving_lo, self._moving_hi
        gap = np.maximum(np.maximum(obs.lo[None] - hi[:, None], lo[:, None] - obs.hi[None]), 0.0)
        ci, oi = np.nonzero(np.einsum("ijk,ijk->ij", gap, gap) < d_act * d_act)
        return idx[ci], oi

    def obstacle_distances(self, obs: ObstacleSet, d_act: float, skip: Skip | None = None
                           ) -> list[tuple[int, Obstacle, float, np.ndarray, np.ndarray]]:
        """[(capsule index, obstacle, distance, point on capsule, point on obstacle)] for pairs nearer than d_act
        (by AABB). Distance PENETRATION (-1) means intersecting. `skip`: capsule name -> object ids (bottles) or
        board names ("board:top_shelf") to ignore."""
        out = []
        req = self._distance_request
        for ci, oi in zip(*self.near_pairs(obs, d_act)):
            o = obs.items[oi]
            if skip and _key(o) in skip.get(self._names[ci], ()):
                continue
            res = fcl.DistanceResult()
            d = fcl.distance(self._fcl(ci), o.obj, req, res)
            out.append((int(ci), o, float(d), res.nearest_points[0], res.nearest_points[1]))
        return out

    def self_distances(self, d_act: float) -> list[tuple[int, int, float, np.ndarray, np.ndarray]]:
        """[(i, j, distance, point on i, point on j)] of non-adjacent capsule pairs nearer than d_act."""
        out = []
        lo, hi = self._lo, self._hi
        gap = np.maximum(np.maximum(lo[self._si] - hi[self._sj], lo[self._sj] - hi[self._si]), 0.0)
        for k in np.nonzero(np.einsum("ij,ij->i", gap, gap) < d_act * d_act)[0]:
            i, j = self.self_pairs[k]
            d, pi, pj = segment_distance(self.p0[i], self.p1[i], self.p0[j], self.p1[j])
            d -= self.radius[i] + self.radius[j]
            if d < d_act:
                out.append((i, j, d, pi, pj))
        return out


def segment_distance(a0: np.ndarray, a1: np.ndarray, b0: np.ndarray, b1: np.ndarray
                     ) -> tuple[float, np.ndarray, np.ndarray]:
    """Closest points of segments a0-a1 and b0-b1 (Ericson, Real-Time Collision Detection 5.1.9)."""
    d1, d2, r = a1 - a0, b1 - b0, a0 - b0
    a, e, f = d1 @ d1, d2 @ d2, d2 @ r
    c, b = d1 @ r, d1 @ d2
    den = a * e - b * b
    s = min(max((b * f - c * e) / den, 0.0), 1.0) if den > 1e-12 else 0.0
    t = (b * s + f) / e
    if t < 0.0:
        t, s = 0.0, min(max(-c / a, 0.0), 1.0)
    elif t > 1.0:
        t, s = 1.0, min(max((b - c) / a, 0.0), 1.0)
    pa, pb = a0 + d1 * s, b0 + d2 * t
    return float(np.linalg.norm(pa - pb)), pa, pb


class HandProxy:
    """The hand (wrist, palm, fingers), an optional carried bottle and a stub of the forearm, rigidly placed at
    a tool pose, inflated by `margin`: the validity check of the Cartesian RRT-Connect (no IK needed). It keeps the
    last CLEAR_POSES poses whose broad phase found no pair, with their gaps: a pose near one of them (as the next
    state of a motion check is, 1 cm on) is clear without the broad phase (`_near_clear`), the same answer."""

    FOREARM_STUB = 0.12
    # the stub stands for the forearm near the hand; at a staging pose low in front of the bottom shelf it points
    # back at the pedestal, which the real forearm (rising to the elbow) stays far above: STPIK checks the arm
    STUB_IGNORES = ("board:pedestal",)
    # nor does it stand for the forearm of a hand tilted down more than STUB_TILT (a grasp from above: grasp.py): the
    # forearm then bends at the wrist (joint 6) to come in under the board above, where STPIK checks it
    STUB_TILT = math.sin(math.radians(30))

    def __init__(self, margin: float, attached: Sequence[CapsuleSpec] = (), attached_margin: float | None = None,
                 fingers: Mapping[str, CapsuleSpec] | None = None) -> None:
        """`attached_margin`: inflation of the attached shapes (default `margin`); `fingers`: ArmGeometry's."""
        specs = _hand_specs(("wrist",) + HAND_PARTS, fingers)
        specs.append(capsule_spec("forearm_stub", rd.LINK_NAMES[6], (0, 0, 0), (0, 0, -self.FOREARM_STUB), 0.04))
        am = margin if attached_margin is None else attached_margin
        margins = [margin] * len(specs) + [am] * len(attached)
        self.specs = specs + list(attached)
        self.objs = [fcl.CollisionObject(_fcl_shape(s, m), fcl.Transform()) for s, m in zip(self.specs, margins)]
        self.reach = np.array([s.radius + m for s, m in zip(self.specs, margins)])
        self.p0 = np.array([s.p0 for s in self.specs])
        self.p1 = np.array([s.p1 for s in self.specs])
        self._reach = np.hstack([self.reach[:, None].repeat(3, 1), self.reach[:, None].repeat(3, 1)])
        self._box = np.empty_like(self._reach)  # hits' work array
        self.req = fcl.CollisionRequest()
        self._lever: list[float] = []  # each shape's farthest endpoint from the tool origin (_keep_clear sets it)
        self._lever_max = 0.0
        self._clear_obs: ObstacleSet | None = None  # the obstacle set of the clear poses
        self._last_obs: ObstacleSet | None = None  # that of the last broad phase
        self._clear: list[tuple[list[float], list[float], list[float], float]] = []

    def collides(self, r_tool: np.ndarray, p_tool: np.ndarray, obs: ObstacleSet,
                 skip: Skip | None = None) -> bool:
        """Any shape in contact with an obstacle (not skipped): AABB broad phase, then fcl.collide."""
        return bool(self.hits(r_tool, p_tool, obs, skip, first=True))

    def hits(self, r_tool: np.ndarray, p_tool: np.ndarray, obs: ObstacleSet,
             skip: Skip | None = None, first: bool = False) -> set[int]:
        """Indices (in obs.items) of the obstacles some shape is in contact with (not skipped); `first`: stop at
        the first one. A pose near a clear one (`_near_clear`) has none, without the broad phase."""
        out: set[int] = set()
        if obs is self._clear_obs and self._near_clear(r_tool, p_tool):
            return out
        again, self._last_obs = obs is self._last_obs, obs  # a clear pose is kept from a second check of obs on
        p7 = p_tool - r_tool[:, 2] * rd.D67  # link 7 frame = tool frame moved back by D67 along z
        rt = r_tool.T
        a = self.p0 @ rt
        a += p7
        b = self.p1 @ rt
        b += p7
        # (hi, -lo) of each shape's AABB against (lo, -hi) of each obstacle's: they overlap where all six hold
        box = self._box
        np.maximum(a, b, out=box[:, :3])
        np.minimum(a, b, out=box[:, 3:])
        np.negative(box[:, 3:], out=box[:, 3:])
        box += self._reach
        ci, oi = np.nonzero(np.logical_and.reduce(obs.lo_neg_hi[None] <= box[:, None], axis=2))
        if not len(ci):
            if again:  # each shape's gap: the smallest over the obstacles of the largest of (lo - hi, lo' - hi')
                gap = np.maximum.reduce(obs.lo_neg_hi[None] - box[:, None], axis=2)
                self._keep_clear(r_tool, p_tool, obs, np.minimum.reduce(gap, axis=1, initial=math.inf).tolist())
            return out
        posed = set()
        for c, k in zip(ci, oi):
            o = obs.items[k]
            s = self.specs[c]
            if k in out or skip and _key(o) in skip.get(s.name, ()) or \
                    s.name == "forearm_stub" and (o.name in self.STUB_IGNORES or -r_tool[2, 2] > self.STUB_TILT):
                continue
            if c not in posed:
                self.objs[c].setTransform(fcl.Transform(r_tool @ s.rot, r_tool @ s.centre + p7))
                posed.add(c)
            if fcl.collide(self.objs[c], o.obj, self.req, fcl.CollisionResult()):
                out.add(int(k))
                if first:
                    break
        return out

    CLEAR_POSES = 32  # clear poses kept (the most recently used first)
    CLEAR_EPS = 1e-9  # m: kept from every box by more than the rounding of its coordinates

    def _keep_clear(self, r_tool: np.ndarray, p_tool: np.ndarray, obs: ObstacleSet, gaps: list[float]) -> None:
        """Remember a pose whose shapes' boxes overlap no obstacle's box, with each shape's smallest gap."""
        if not self._lever:  # made on first use: many a proxy (blockers') checks a few poses only
            tool = np.array([0.0, 0.0, rd.D67])
            self._lever = np.maximum(np.linalg.norm(self.p0 - tool, axis=1), np.linalg.norm(self.p1 - tool, axis=1)
                                     ).tolist()
            self._lever_max = max(self._lever)
        if obs is not self._clear_obs:
            self._clear_obs, self._clear = obs, []
        self._clear.insert(0, (r_tool.ravel().tolist(), p_tool.tolist(), gaps, min(gaps)))
        del self._clear[self.CLEAR_POSES:]

    def _near_clear(self, r_tool: np.ndarray, p_tool: np.ndarray) -> bool:
        """Whether the pose is so near a kept clear pose (same obstacles) that no shape's box can reach an obstacle's
        box: the broad phase would find no pair. A shape's endpoint y (tool frame) moves by R y + p - (R' y + p'),
        at most |p - p'| + ||R - R'||_F |y| (the Frobenius norm bounds the spectral one, for any matrices), and
        each coordinate of its box by no more; a box that moves less than its gap (less CLEAR_EPS) overlaps nothing."""
        r, p = r_tool.ravel().tolist(), p_tool.tolist()
        for k, (r0, p0, gaps, smallest) in enumerate(self._clear):
            dp = math.dist(p, p0) + self.CLEAR_EPS
            if dp >= smallest:
                continue
            dr = math.dist(r, r0)
            if dp + dr * self._lever_max < smallest or \
                    all(dp + dr * lever < gap for lever, gap in zip(self._lever, gaps)):
                if k:
                    self._clear.insert(0, self._clear.pop(k))
                return True
        return False

    def path_clear(self, poses: Sequence[ArrayLike], obs: ObstacleSet, resolution: float, skip: Skip | None = None
                   ) -> bool:
        """The proxy is clear at every pose along the polyline of (x, y, z, yaw) poses (grasp.py), sampled every
        `resolution` m (a yaw change counts 0.25 m per rad): the straight approach of a grasp lane (feasibility's
        candidates, blockers' screen) and a direct Cartesian path."""
        return all(not self.collides(*m, obs, skip) for m in _path_poses(poses, resolution))

    def path_hits(self, poses: Sequence[ArrayLike], obs: ObstacleSet, resolution: float, skip: Skip | None = None
                  ) -> set[int]:
        """Indices (in obs.items) of every obstacle the proxy meets along the polyline (`path_clear`'s poses): the
        OR of the contacts, so the obstacles each of which alone would block it."""
        out: set[int] = set()
        for m in _path_poses(poses, resolution):
            out |= self.hits(*m, obs, skip)
        return out


def _path_poses(poses: Sequence[ArrayLike], resolution: float) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """(rotation, position) of the tool every `resolution` m along a polyline of (x, y, z, yaw) poses, or (x, y, z,
    yaw, pitch[, roll]) ones (a change of an angle counts 0.25 m per rad), both ends of each segment included."""
    from stpik_motion_planner.model.grasp import pose_matrix

    for a, b in zip(poses[:-1], poses[1:]):
        a, b = np.asarray(a, float), np.asarray(b, float)
        turn = float(abs(b[3] - a[3])) if len(a) < 5 else float(np.abs(b[3:] - a[3:]).max())
        n = max(1, int(math.ceil(max(float(np.linalg.norm(b[:3] - a[:3])), 0.25 * turn) / resolution)))
        for k in range(n + 1):
            yield pose_matrix(a + (b - a) * k / n)
