"""Action to pose (paper Sect. 4.1, step 1): the side grasp of a standing object, the grasp from above of a lying
cylinder, their pre-grasps, and the carry poses.

Tool frame (DH frame 7): z is the approach direction, x the closing direction of the fingers, origin the grasp
centre. A side grasp keeps the hand horizontal: tool z = (cos yaw, sin yaw, 0) points into the shelf from its
open side (-x), tool y = world z (vertical), tool x = y x z (horizontal). The tool origin is at the object's
mid-height, `grasp_standoff(half_depth)` short of its centre along the approach (`grasp_extent`: a cylinder's
radius, a box's half-size along the approach), so that the palm stops PALM_GAP from the object (the palm's front
is PALM_REACH behind the grasp centre; the open fingers still surround the object).
A Cartesian pose here is (x, y, z, yaw): position of the tool and yaw of the approach direction; or
(x, y, z, yaw, pitch), the approach tilted `pitch` below the horizontal about tool x (`tool_rotation`; pi/2:
straight down), tool x still horizontal; or (x, y, z, yaw, pitch, roll), the hand also turned `roll` about its
approach (a push's hand rolled half a turn, so that fingers 2 and 3 lead to its left: planning/push/motion.py). The
robot's home pose (Q_HOME) is such a pose with yaw 0.

What the grasps take (`grasp_refusal`): a standing cylinder, approached at any yaw of the tiers (`yaw_tiers`),
or a standing box, approached square to one of its vertical faces (`face_yaws`: its yaw + k pi/2 within the tiers'
range), the fingers closing across the box's width perpendicular to that approach; either no wider there than the
open hand (`hand_opening`: the gap between the description's open finger capsules where the object's centre comes
to rest). A cylinder lying flat (`lying`) is grasped from above (the section "from above": `grasp_from_above`,
`lying_pitch`): the hand comes down over it, fingers across its axis, where the shelf's headroom and the arm's
reach allow (else "no grasp: " with the headroom it needs in metres); carried out, it is stood up in the hand
(`stand_up_poses`) and placed standing. A leaning cylinder, a conservative object (a cluster no primitive fits), a
wider cylinder or a box too wide across every face it can be approached by is answered "no grasp: " and the
reason: it stays an obstacle, never relocated. A box is carried as held: square to the hand, so placed in its slot
square to the shelf.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence, Union

import numpy as np

from relocation_common import robot_description as rd
from relocation_common.feasibility import NO_GRASP
from relocation_common.scenario import Scenario, Shelf, ShelfObject
from relocation_common.shelf_object import UPRIGHT_TILT

Pose = Union[Sequence[float], np.ndarray]  # (x, y, z, yaw) of the tool, or (x, y, z, yaw, pitch[, roll])
_PALM = next(c for c in rd.CAPSULES if c.name == "palm")
PALM_REACH = rd.D67 - _PALM.p1[2] - _PALM.radius  # m from the grasp centre back to the palm's front (0.025)
PALM_GAP = 0.008  # m between the palm and a grasped bottle: 4 mm plus the 4 mm final tolerance of STPIK


def grasp_standoff(half_depth: float) -> float:
    """Distance of the grasp centre short of the object's centre along the approach, for an object reaching
    `half_depth` in front of its centre (a cylinder's radius; `grasp_extent`): the palm stays PALM_GAP away."""
    return max(0.0, half_depth + PALM_GAP - PALM_REACH)


def grasp_extent(o: ShelfObject, yaw: float) -> tuple[float, float]:
    """(half-depth along the approach of yaw `yaw`, width across it that the fingers close on) of a standing
    object: (r, 2r) for a cylinder; for a box, the half-size along the box axis nearest to the approach and the
    size along the other (a face yaw of `face_yaws` is square to that face)."""
    if o.shape != "box":
        return o.radius, 2 * o.radius
    along_x = abs(math.cos(yaw - o.yaw)) >= abs(math.sin(yaw - o.yaw))
    sx, sy, _ = o.size
    return (sx / 2, sy) if along_x else (sy / 2, sx)


def face_yaws(o: ShelfObject) -> list[float]:
    """The approach yaws square to a box's four vertical faces, in [-pi, pi): its yaw + k pi/2, straightest
    (smallest |yaw|) first."""
    out = [(o.yaw + k * math.pi / 2 + math.pi) % (2 * math.pi) - math.pi for k in range(4)]
    return sorted(out, key=abs)


_FINGERS = tuple(c for c in rd.CAPSULES if c.name.startswith("finger"))


def hand_opening(depth: float) -> float:
    """Width (m) between the open fingers `depth` m beyond the grasp centre along the approach, from the robot
    description's finger capsules (tool x is the closing direction: finger 1 on +x faces fingers 2 and 3 on -x):
    the inner faces' distance along x, each finger's axis interpolated at that depth."""
    z = rd.D67 + depth

    def x_at(c: rd.Capsule) -> float:
        t = (z - c.p0[2]) / (c.p1[2] - c.p0[2])
        return float(c.p0[0] + t * (c.p1[0] - c.p0[0]))

    inner = [x_at(c) - c.radius for c in _FINGERS if c.p0[0] > 0]
    outer = [x_at(c) + c.radius for c in _FINGERS if c.p0[0] < 0]
    return min(inner) - max(outer)


def hand_fits(o: ShelfObject, yaw: float) -> bool:
    """The open hand takes `o` approached at `yaw`: its width across the approach (`grasp_extent`) is no wider
    than `hand_opening` where its centre comes to rest (`grasp_standoff` beyond the grasp centre)."""
    half_depth, width = grasp_extent(o, yaw)
    return width <= hand_opening(grasp_standoff(half_depth))


def box_refusal(o: ShelfObject, max_yaw: float) -> str:
    """Why the side grasp cannot take the box `o` ("no grasp: ..."), or "": no face whose approach yaw
    (`face_yaws`) is within `max_yaw` of straight in is narrow enough for the open hand (`hand_fits`)."""
    faces = [y for y in face_yaws(o) if abs(y) <= max_yaw + 1e-9]
    if any(hand_fits(o, y) for y in faces):
        return ""
    narrow = min(face_yaws(o), key=lambda y: grasp_extent(o, y)[1])  # the straighter of its two yaws

    def across(yaw: float, which: str) -> str:
        half_depth, width = grasp_extent(o, yaw)
        return f"{width * 1000:.0f} mm across{which}, wider than the open hand " \
               f"({hand_opening(grasp_standoff(half_depth)) * 1000:.0f} mm between the fingers)"

    if not hand_fits(o, narrow):
        return f"{NO_GRASP}{o.id} is a box {across(narrow, ' every face')} ({o.describe()})"
    within = f"the narrowest face within {max_yaw:.2f} rad of straight in is " \
        f"{across(min(faces, key=lambda y: grasp_extent(o, y)[1]), '')}" if faces else \
        f"no face is within {max_yaw:.2f} rad of straight in"
    return (f"{NO_GRASP}{o.id} is a box ({o.describe()}): {within}; the face the hand fits "
            f"({grasp_extent(o, narrow)[1] * 1000:.0f} mm across) is turned {abs(narrow):.2f} rad from straight in")


def grasp_refusal(o: ShelfObject, face_limit: float | None = None) -> str:
    """Why the grasps cannot take `o` ("no grasp: ..."), or "" when they may (module docstring): a conservative
    object, a box too wide across every face within `face_limit` rad of straight in (`box_refusal`; None: any face),
    a cylinder leaning (its axis more than UPRIGHT_TILT from the vertical and not flat), or a cylinder wider than
    the open hand where its axis comes to rest (`hand_fits`). The headroom of a lying one's grasp from above is
    the shelf's: `lying_pitch`."""
    if o.conservative:
        return (f"{NO_GRASP}{o.id} is a conservative obstacle (an unfitted cluster's bounding box, "
                f"{o.describe()}): an obstacle only")
    if o.shape == "box":
        return box_refusal(o, math.pi if face_limit is None else face_limit)
    if o.axis_tilt > UPRIGHT_TILT and not (o.lying and o.tilt is None):
        return f"{NO_GRASP}{o.id} leans: the grasps take standing cylinders and cylinders lying flat only"
    opening = hand_opening(grasp_standoff(o.radius))
    if not hand_fits(o, 0.0):
        return (f"{NO_GRASP}{o.id} is {2 * o.radius * 1000:.0f} mm wide, wider than the open hand "
                f"({opening * 1000:.0f} mm between the fingers)")
    return ""


class WorkspaceError(ValueError):
    """A pose that is not a finite pose inside the arm's reach."""


def side_rotation(yaw: float) -> np.ndarray:
    """Rotation of a horizontal side grasp whose approach direction has the given yaw (rad)."""
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[-s, 0.0, c], [c, 0.0, s], [0.0, 1.0, 0.0]])


def tool_rotation(yaw: float, pitch: float, hand_roll: float = 0.0) -> np.ndarray:
    """Rotation of a grasp whose approach direction (tool z) has the given yaw and is tilted `pitch` rad below the
    horizontal (pi/2: straight down), the closing direction (tool x) horizontal: `side_rotation` turned about tool
    x; pitch 0 is `side_rotation` itself. `hand_roll` turns the hand about its approach (tool z) after that: pi swaps
    tool x and y for their opposites (joint 7 half a turn)."""
    if pitch == 0.0:
        rot = side_rotation(yaw)
    else:
        c, s, cp, sp = math.cos(yaw), math.sin(yaw), math.cos(pitch), math.sin(pitch)
        x, z = np.array([-s, c, 0.0]), np.array([cp * c, cp * s, -sp])
        rot = np.column_stack([x, np.cross(z, x), z])
    if hand_roll == 0.0:
        return rot
    cr, sr = math.cos(hand_roll), math.sin(hand_roll)
    return rot @ np.array([[cr, -sr, 0.0], [sr, cr, 0.0], [0.0, 0.0, 1.0]])


def tool_angles(rot: np.ndarray) -> tuple[float, float]:
    """(yaw, pitch) of a tool rotation: the inverse of tool_rotation (the yaw from the closing direction, defined
    also when the approach is vertical)."""
    return float(math.atan2(-rot[0, 0], rot[1, 0])), float(math.asin(max(-1.0, min(1.0, -rot[2, 2]))))


def pose_pitch(pose: Pose) -> float:
    """The approach's pitch of a pose: its fifth number, 0 for an (x, y, z, yaw) pose."""
    return float(pose[4]) if len(pose) > 4 else 0.0


def pose_roll(pose: Pose) -> float:
    """The hand's roll about its approach of a pose: its sixth number, 0 for a shorter pose."""
    return float(pose[5]) if len(pose) > 5 else 0.0


def approach_yaw(rot: np.ndarray) -> float:
    """Yaw (rad) of the approach direction (the tool's z axis) of a tool rotation: the inverse of side_rotation."""
    return float(math.atan2(rot[1, 2], rot[0, 2]))


def pose_matrix(pose4: Pose) -> tuple[np.ndarray, np.ndarray]:
    """(rotation, position) of an (x, y, z, yaw) side-grasp pose, an (x, y, z, yaw, pitch) one or an (x, y, z, yaw,
    pitch, roll) one."""
    return tool_rotation(float(pose4[3]), pose_pitch(pose4), pose_roll(pose4)), np.array(pose4[:3], dtype=float)


def check_pose(pose4: Pose, where: str = "pose") -> np.ndarray:
    """Raise WorkspaceError unless pose4 is finite and the wrist centre is within the arm's reach."""
    p = np.asarray(pose4, dtype=float)
    if p.shape not in ((4,), (5,), (6,)) or not np.all(np.isfinite(p)):
        raise WorkspaceError(f"{where}: need 4 finite numbers (x, y, z, yaw), 5 (and pitch) or 6 (and roll), got "
                             f"{pose4!r}")
    r, t = pose_matrix(p)
    wrist = t - r[:, 2] * rd.D67
    reach = float(np.linalg.norm(wrist - np.array([0.0, 0.0, rd.D1])))
    if reach > rd.D23 + rd.D45 - 0.02 or reach < 0.15:
        raise WorkspaceError(f"{where}: {np.round(p, 3).tolist()} is outside the arm's workspace "
                             f"(wrist {reach:.3f} m from the shoulder, reachable 0.15-{rd.D23 + rd.D45 - 0.02:.2f})")
    return p


@dataclass(frozen=True)
class Grasp:
    """A grasp of one object: approach yaw, grasp and pre-grasp poses ((x, y, z, yaw), and the pitch for a grasp
    from above: `grasp_from_above`)."""

    object_id: str
    yaw: float
    grasp: tuple[float, ...]
    pre_grasp: tuple[float, ...]


def grasp_yaws(n: int, max_yaw: float) -> list[float]:
    """Approach yaws to try, straight in first: 0, +d, -d, +2d, -2d, ... up to max_yaw (n values)."""
    if n <= 1:
        return [0.0]
    step = max_yaw / ((n - 1 + 1) // 2)
    out = [0.0]
    k = 1
    while len(out) < n:
        out.append(k * step)
        if len(out) < n:
            out.append(-k * step)
        k += 1
    return out


def yaw_tiers(n: int, max_yaw: float, wide_n: int, wide_max_yaw: float) -> list[list[float]]:
    """The approach yaws in the order they are tried: grasp_yaws(n, max_yaw) first; then, only for a question none
    of those answered, the yaws of grasp_yaws(wide_n, wide_max_yaw) not already tried (the wider grasp set)."""
    first = grasp_yaws(n, max_yaw)
    wide = [y for y in grasp_yaws(wide_n, wide_max_yaw) if all(abs(y - f) > 1e-9 for f in first)] if wide_n else []
    return [first, wide] if wide else [first]


def placed_sides(o: ShelfObject, turn: float) -> tuple[float, float]:
    """(side along x, side along y) of the upright rectangle about its slot that holds a box the side grasp placed
    there: held square to the hand and released pointing straight in (yaw 0), so its width across the fingers along
    y and its depth along x, for whichever face the hand fits it was held by (the widest and the deepest of them),
    turned by up to `turn` rad (the grasp's and the place's yaw tolerances)."""
    held = [grasp_extent(o, y) for y in face_yaws(o) if hand_fits(o, y)] or [grasp_extent(o, y) for y in face_yaws(o)]
    a, b = max(h[0] for h in held), max(h[1] for h in held) / 2
    c, s = math.cos(turn), math.sin(turn)
    return 2 * (a * c + b * s), 2 * (b * c + a * s)


def grasp_yaw_tiers(o: ShelfObject, n: int, max_yaw: float, wide_n: int, wide_max_yaw: float) -> list[list[float]]:
    """The approach yaws of object `o` in the order they are tried: a lying cylinder's axis yaw (`lying_axis_yaw`:
    the grasp from above); a standing cylinder's `yaw_tiers`; a box's face yaws
    (`face_yaws`) the open hand fits (`hand_fits`), within max_yaw first, then (with a second tier, wide_n > 0)
    those within wide_max_yaw."""
    if o.lying:
        return [[lying_axis_yaw(o)]]
    if o.shape != "box":
        return yaw_tiers(n, max_yaw, wide_n, wide_max_yaw)
    fits = [y for y in face_yaws(o) if hand_fits(o, y)]
    first = [y for y in fits if abs(y) <= max_yaw + 1e-9]
    wide = [y for y in fits if max_yaw + 1e-9 < abs(y) <= wide_max_yaw + 1e-9] if wide_n else []
    return [first, wide] if wide else [first]


def side_grasp(scenario: Scenario, object_id: str, yaw: float, pre_grasp_distance: float, clearance: float
               ) -> Grasp:
    """Grasp and pre-grasp poses of a standing object on the top shelf for one approach yaw (at its mid-height,
    `grasp_standoff` short of its centre: the module docstring); of a lying cylinder, `grasp_from_above` (its
    pitch and pre-grasp keeping `clearance` under the board above: `lying_pitch`), or where the board above leaves
    no room for it, `grasp_along_axis`."""
    b = scenario.object(object_id)
    if b.lying:
        pitch, pre_d, why = lying_pitch(scenario.shelf, b, pre_grasp_distance, clearance)
        if why:  # the grasp along its axis (the section "along the axis"), its reach and room checked
            why_along = along_axis_refusal(scenario.shelf, b, math.pi, clearance)
            if why_along:
                raise WorkspaceError(both_refusals(why, why_along))
            return grasp_along_axis(scenario.shelf, b, yaw, pre_grasp_distance, clearance)
        above = grasp_from_above(scenario.shelf, b, yaw, pitch, pre_d)
        check_pose(above.grasp, f"grasp of {object_id} from above")
        return above
    z = scenario.shelf.top_z + b.height / 2
    s = grasp_standoff(grasp_extent(b, yaw)[0])
    g = (b.x - s * math.cos(yaw), b.y - s * math.sin(yaw), z, yaw)
    d = s + pre_grasp_distance
    pre = (b.x - d * math.cos(yaw), b.y - d * math.sin(yaw), z, yaw)
    check_pose(g, f"grasp of {object_id}")
    return Grasp(object_id, yaw, g, pre)


# ---------------------------------------------------------------------------------------------- from above
# A lying cylinder is grasped from above: the hand comes down over it with the fingers closing across its axis (tool x
# horizontal, perpendicular to the axis; the axis along tool y, as a standing bottle's in the side grasp), tool z
# pointing down, tilted by `pitch` below the horizontal towards the back of the shelf along the bottle's axis yaw.
LYING_PITCHES = (math.pi / 2, 1.45)  # rad, steepest first: flatter, the lower of fingers 2 and 3 (22 mm apart
# along the axis) pushes the grasp centre more than the simulator's attach distance (25 mm) from the axis
FINGER_FLOOR = 0.008  # m: the finger tips above the board the bottle lies on (4 mm, plus the 4 mm of STPIK's final
# tolerance); the fingers may come this close to that board, and only on the approach and the lift (pick, carry)
LYING_TILT_YAW = math.pi / 4  # rad: a tilted hand leans along the axis: only for an axis this near to straight in
LYING_MIN_PRE = 0.03  # m: the shortest approach of a grasp from above (its pre-grasp this far back, and the lift)
_HAND = tuple(c for c in rd.CAPSULES if c.link == rd.LINK_NAMES[6])  # wrist, palm, fingers (link 7)


def hand_heights(pose: Pose) -> tuple[float, float]:
    """(lowest, highest) z of the hand (the wrist, palm and finger capsules of the robot description) at a pose."""
    r, t = pose_matrix(pose)
    p7 = t - r[:, 2] * rd.D67
    ends = [(float(r[2] @ np.asarray(e, float)) + p7[2], c.radius) for c in _HAND for e in (c.p0, c.p1)]
    return min(z - rad for z, rad in ends), max(z + rad for z, rad in ends)


def lying_axis_yaw(o: ShelfObject) -> float:
    """The approach yaw of a grasp from above of the lying cylinder `o`: its axis's yaw, turned by pi if need be so
    that a tilted hand leans towards the back of the shelf (in (-pi/2, pi/2])."""
    y = math.remainder(o.yaw, math.pi)
    return y if y > -math.pi / 2 else y + math.pi


def from_above_standoff(o: ShelfObject) -> float:
    """How far short of the lying cylinder's axis a grasp from above puts the grasp centre: `grasp_standoff`, or
    more so that the finger tips stay FINGER_FLOOR above the board it lies on at every pitch of LYING_PITCHES (the
    lowest finger lower the flatter the hand): one standoff, so the bottle is held alike at any of them."""
    s0 = grasp_standoff(o.radius)
    need = [s0]
    for pitch in LYING_PITCHES:
        z = tool_rotation(0.0, pitch)[:, 2]
        low = hand_heights((*(np.array([0.0, 0.0, o.radius]) - s0 * z), 0.0, pitch))[0]  # the board at z = 0
        need.append(s0 + (FINGER_FLOOR - low) / math.sin(pitch))
    return max(need)


def grasp_from_above(shelf: Shelf, o: ShelfObject, yaw: float, pitch: float, pre_grasp_distance: float) -> Grasp:
    """Grasp and pre-grasp of the lying cylinder `o` at approach `yaw` and `pitch` (the section's comment): the
    grasp centre on the line through the bottle's centre along the approach, `from_above_standoff` short of it;
    the pre-grasp `pre_grasp_distance` back along it. Not checked for the arm's reach (`check_pose`)."""
    support = shelf.top_z if o.support_z is None else o.support_z
    z = tool_rotation(yaw, pitch)[:, 2]
    centre = np.array([o.x, o.y, support + o.radius])
    s = from_above_standoff(o)
    g = tuple(float(v) for v in (*(centre - s * z), yaw, pitch))
    pre = tuple(float(v) for v in (*(centre - (s + pre_grasp_distance) * z), yaw, pitch))
    return Grasp(o.id, yaw, g, pre)


def held_standoff(o: ShelfObject, grasp_yaw: float) -> float:
    """How far beyond the tool the held object's centre is along tool z: `from_above_standoff` for a lying
    cylinder, else `grasp_standoff` for its depth at the grasp yaw (`grasp_extent`)."""
    return from_above_standoff(o) if o.lying else grasp_standoff(grasp_extent(o, grasp_yaw)[0])


def lying_pitch(shelf: Shelf, o: ShelfObject, pre_grasp_distance: float, clearance: float
                ) -> tuple[float, float, str]:
    """(pitch, pre-grasp distance, "") of the grasp from above of the lying cylinder `o`: the steepest of
    LYING_PITCHES within the arm's reach, tilted only from the open side (a bottle whose axis is within
    LYING_TILT_YAW of pointing into the shelf), whose hand keeps `clearance` under the board above at the pre-grasp,
    the lowest from which the finger tips clear the bottle's top by `clearance` (at least LYING_MIN_PRE back, at
    most `pre_grasp_distance`: the lower the hand, the more room the forearm has to come in under the board above);
    else (0, 0, "no grasp: " and the headroom needed, or the reach)."""
    support = shelf.top_z if o.support_z is None else o.support_z
    room = shelf.ceiling_z - support
    yaw = lying_axis_yaw(o)
    needs, far = [], ""
    for pitch in LYING_PITCHES:
        if pitch < math.pi / 2 and abs(yaw) > LYING_TILT_YAW:
            continue
        g = grasp_from_above(shelf, o, yaw, pitch, 0.0)
        low, high = (h - support for h in hand_heights(g.grasp))
        rise = math.sin(pitch)  # m up per m of approach
        approach = max(LYING_MIN_PRE, (2 * o.radius + clearance - low) / rise)  # the fingers over the bottle
        top = high + clearance  # the hand at the grasp, with its clearance
        if top + approach * rise > room:
            needs.append((top + approach * rise, pitch))
            continue
        try:
            check_pose(g.grasp, f"grasp of {o.id} from above")
        except WorkspaceError as e:
            far = str(e)
            continue
        return pitch, min(approach, pre_grasp_distance), ""
    if far or not needs:
        return 0.0, 0.0, f"{NO_GRASP}{o.id} lies out of the arm's reach for a grasp from above ({far})"
    need, pitch = min(needs)
    hand = "straight down" if pitch == math.pi / 2 else f"tilted {pitch:.2f} rad down"
    return 0.0, 0.0, (f"{NO_GRASP}{o.id} lies on the top shelf with {room:.2f} m of headroom; a grasp from above "
                      f"needs {need:.2f} m (the hand {hand}, its finger tips "
                      f"{clearance * 1000:.0f} mm over the bottle before it comes down and {clearance * 1000:.0f} "
                      f"mm under the board above)")


def home_pose() -> tuple[float, float, float, float]:
    """(x, y, z, yaw) of the tool at Q_HOME (hand horizontal, pointing at the shelf)."""
    t = rd.dh_fk(rd.Q_HOME)[-1]
    return (float(t[0, 3]), float(t[1, 3]), float(t[2, 3]), approach_yaw(t[:3, :3]))


def lift_pose(grasp: Grasp, lift: float) -> tuple[float, float, float, float]:
    """The grasp pose raised by `lift`."""
    x, y, z, yaw = grasp.grasp
    return (x, y, z + lift, yaw)


def carry_heights(scenario: Scenario, object_id: str, clearance: float, lift: float, drop: float
                  ) -> tuple[float, float]:
    """(lift, release height) of a bottle carried at its real size, keeping `clearance` to the boards above and
    below it: the lift off the top shelf (at least `clearance` so that the bottle clears the board before it moves
    out, at most what leaves `clearance` under the ceiling board; `lift` if that is within) and the height of its
    base above the bottom shelf while it is moved in and released (`drop`, or half of the room if that is less:
    the bottom compartment of the shipped shelf is 0.18 m high for 0.16 m bottles). WorkspaceError if the bottle is
    too tall for either compartment."""
    b = scenario.object(object_id)
    s = scenario.shelf
    top_room = s.ceiling_z - s.top_z - b.height
    if top_room < 2 * clearance:
        raise WorkspaceError(f"{object_id} ({b.height:.3f} m tall) cannot be lifted off the top shelf keeping "
                             f"{clearance * 1000:.0f} mm to its boards: {top_room * 1000:.0f} mm to spare")
    bottom_room = s.top_z - s.board_thickness - s.bottom_z - b.height
    release = min(drop, bottom_room / 2)
    if release < clearance:
        raise WorkspaceError(f"{object_id} ({b.height:.3f} m tall) does not fit in the bottom compartment keeping "
                             f"{clearance * 1000:.0f} mm to its boards: {bottom_room * 1000:.0f} mm to spare")
    return min(max(lift, clearance), top_room - clearance), release


# how far the open fingers reach beyond the grasp centre along the approach (their capsules' tips): 0.042 m
FINGER_REACH = max(c.p1[2] + c.radius for c in rd.CAPSULES if c.name.startswith("finger")) - rd.D67


_FINGER_SPHERE = max(math.hypot(math.hypot(c.p1[0], c.p1[1]), c.p1[2] - rd.D67) + c.radius
                     for c in rd.CAPSULES if c.name.startswith("finger"))  # m: the finger tips from the grasp centre


def exit_pose(scenario: Scenario, object_id: str, pose: Pose, margin: float) -> tuple[float, ...]:
    """`pose` moved back against its approach direction, at its height, until the held object (its centre
    `grasp_standoff` beyond the tool; a box square to the hand, its corners reaching `grasp_extent` along and
    across the approach) and the finger tips are `margin` in front of the shelf's front edge: out of the shelf,
    free to go down. A bottle grasped from above (a pose with a pitch) is drawn straight out (along -x, the way the
    hand came in: pick.front_of_shelf), free to be stood up there (`stand_up_pose`): all of it and the finger tips
    `margin` in front, however the hand turns about the tool origin."""
    b = scenario.object(object_id)
    x, y, z, yaw = (float(v) for v in pose[:4])
    c = math.cos(yaw)
    half_depth, width = grasp_extent(b, yaw)
    ahead = (grasp_standoff(half_depth) + half_depth) * c  # a cylinder: as its axis and radius always were
    if b.shape == "box":
        ahead += width / 2 * abs(math.sin(yaw))
    reach = FINGER_REACH * c
    if b.lying and len(pose) < 5:  # held along its axis (grasp_along_axis): its far end and its flank
        ahead = (along_axis_standoff(b) + b.height / 2) * c + b.radius * abs(math.sin(yaw))
    if len(pose) > 4:  # straight out, until what the hand holds clears the shelf as it is stood up and turned
        ahead = stand_up_reach(b, yaw, float(pose[4]))
        return (min(x, scenario.shelf.x_front - margin - ahead), y, z, yaw, *(float(v) for v in pose[4:]))
    need = x + max(ahead, reach) - (scenario.shelf.x_front - margin)
    if need <= 0.0:
        return tuple(float(v) for v in pose)
    back = need / c
    return (x - back * c, y - back * math.sin(yaw), z, yaw, *(float(v) for v in pose[4:]))


def held_tilt(pitch: float) -> float:
    """Angle (rad) of a bottle grasped from above at `pitch` between its axis and tool y, towards tool z: its axis
    is horizontal along the approach's yaw, so (0, sin pitch, cos pitch) in the tool frame; 0 straight down, as a
    standing bottle's in the side grasp (pitch 0 there: tool y vertical)."""
    return math.pi / 2 - pitch


def stand_up_poses(pose: Pose) -> list[tuple[float, float, float, float, float]]:
    """A pose from above out of the shelf raised to the home pose's height (the arm unfolded: lower, so near the
    robot, the wrist and elbow turn against their limits), turned there to face the shelf (yaw 0, about the
    approach: the wrist's last joint for a hand straight down), then until the bottle held stands: its pitch less
    pi/2 (about tool x: tilted up by `held_tilt`, level for a grasp from straight above)."""
    x, y, z, yaw, pitch = (float(v) for v in pose)
    z = max(z, home_pose()[2])
    return [(x, y, z, yaw, pitch), (x, y, z, 0.0, pitch), (x, y, z, 0.0, pitch - math.pi / 2)]


def stand_up_reach(o: ShelfObject, yaw: float, pitch: float) -> float:
    """How far (m) along x in front of the tool the lying cylinder `o` held from above at (yaw, pitch) and the finger
    tips reach while `stand_up_poses` turns them (sampled every 0.05 rad), its axis in the tool frame as
    `held_tilt` has it."""
    s, t = from_above_standoff(o), held_tilt(pitch)
    axis, centre = np.array([0.0, math.cos(t), math.sin(t)]), np.array([0.0, 0.0, s])
    ends = [centre + axis * o.height / 2, centre - axis * o.height / 2]
    turns = [(y, pitch) for y in np.linspace(yaw, 0.0, 32)] + \
        [(0.0, p) for p in np.linspace(pitch, pitch - math.pi / 2, 32)]
    out = 0.0
    for y, p in turns:
        r = tool_rotation(y, p)
        a = r @ axis
        out = max(out, max(float((r @ e)[0]) for e in ends) + o.radius * math.sqrt(max(0.0, 1.0 - a[0] ** 2)),
                  _FINGER_SPHERE)
    return out


def place_poses(scenario: Scenario, object_id: str, slot_xy: tuple[float, float], drop: float,
                stage_distance: float, grasp_yaw: float, grasp_pitch: float) -> tuple[tuple, tuple]:
    """(staging pose in front of the bottom shelf, place pose at the slot), approach straight in (yaw 0).
    The tool is at the object's mid-height with its base `drop` above the bottom shelf (the release height of
    `carry_heights`) and its centre on the slot: `held_standoff` ahead, for the depth it was grasped by at
    `grasp_yaw` (a box is held square to the hand: `grasp_extent`). A bottle grasped from above at `grasp_pitch`
    stands in the hand tilted up by `held_tilt` (`stand_up_pose`): its centre `held_standoff` along that tilt. A
    lying cylinder grasped along its axis (`grasp_pitch` 0) is placed lying along x, its centre on the slot and its
    lowest point `drop` above the bottom shelf; its staging pose far enough back that it is out of the shelf."""
    b = scenario.object(object_id)
    if b.lying and grasp_pitch == 0.0:  # held along its axis: placed lying along x, the bottle out of the shelf
        s = along_axis_standoff(b)  # at the staging pose
        z = scenario.shelf.bottom_z + drop + b.radius + along_axis_raise(b)
        x = slot_xy[0] - s
        stage = (min(x - stage_distance, scenario.shelf.x_front - 0.03 - s - b.height / 2), slot_xy[1], z, 0.0)
        check_pose((x, slot_xy[1], z, 0.0), f"place of {object_id} at slot {slot_xy}")
        return stage, (x, slot_xy[1], z, 0.0)
    z = scenario.shelf.bottom_z + drop + b.height / 2
    s = held_standoff(b, grasp_yaw)
    if b.lying:
        t = held_tilt(grasp_pitch)
        x, z = slot_xy[0] - s * math.cos(t), z - s * math.sin(t)
        stage5 = (min(slot_xy[0] - stage_distance, scenario.shelf.x_front - 0.07), slot_xy[1], z, 0.0, -t)
        place5 = (x, slot_xy[1], z, 0.0, -t)
        check_pose(place5, f"place of {object_id} at slot {slot_xy}")
        return stage5, place5
    place = (slot_xy[0] - s, slot_xy[1], z, 0.0)
    stage = (min(slot_xy[0] - stage_distance, scenario.shelf.x_front - 0.07), slot_xy[1], z, 0.0)
    check_pose(place, f"place of {object_id} at slot {slot_xy}")
    return stage, place


# ---------------------------------------------------------------------------------------------- along the axis
# Under a board too low for a hand from above (`lying_pitch` refuses it), a lying cylinder is grasped with the hand
# horizontal (pitch 0: `side_rotation`), approaching along its axis from its end nearer to the open side (the approach
# yaw `lying_axis_yaw`, within the tiers' range), the fingers closing horizontally across the axis around that
# end: the palm PALM_GAP from the end cap, the grasp centre on the axis's vertical plane, raised above the axis only
# as much as keeps the hand's lowest capsule (the palm, 45 mm round the tool axis) FINGER_FLOOR above the board; the
# hand (wrist, palm, fingers) may come that near the board on the approach and the lift (context.grasp_skip). Held
# along tool z, its centre `along_axis_standoff` beyond the tool and `along_axis_raise` below the tool axis; it is
# carried and placed lying, along x (no hand turns a bottle held so upright under the bottom shelf's board).
AXIS_GRASP_MAX_RAISE = 0.025  # m: the grasp centre at most this far from the axis (the fingers close on its upper
# flank: at 25 mm over a 33 mm radius, 2 x 21 mm apart); the simulator attaches within the same (GRASP_RADIAL_TOL)


def along_axis_raise(o: ShelfObject) -> float:
    """How far (m) above the lying cylinder's axis the grasp along it puts the grasp centre: the hand's lowest
    capsule (`hand_heights` at pitch 0) FINGER_FLOOR above the board, or on the axis if that is already so."""
    return max(0.0, FINGER_FLOOR - hand_heights((0.0, 0.0, 0.0, 0.0))[0] - o.radius)


def along_axis_standoff(o: ShelfObject) -> float:
    """How far (m) beyond the grasp centre, along the approach, the centre of the lying cylinder grasped along its
    axis is: half its length, less the near end cap's place (PALM_GAP in front of the palm, PALM_REACH behind the
    grasp centre)."""
    return o.height / 2 + PALM_GAP - PALM_REACH


def grasp_along_axis(shelf: Shelf, o: ShelfObject, yaw: float, pre_grasp_distance: float, clearance: float) -> Grasp:
    """Grasp and pre-grasp of the lying cylinder `o` along its axis at approach `yaw` (the section's comment): the
    grasp centre `along_axis_standoff` short of its centre along the approach, `along_axis_raise` above its axis;
    the pre-grasp `pre_grasp_distance` back and raised until the hand's lowest capsule keeps `clearance` over the
    board (the Cartesian planner's and STPIK's bound: the approach comes down the rest). Not checked for reach."""
    support = shelf.top_z if o.support_z is None else o.support_z
    s, c, si = along_axis_standoff(o), math.cos(yaw), math.sin(yaw)
    z = support + o.radius + along_axis_raise(o)
    rise = max(0.0, clearance - FINGER_FLOOR)
    g = (o.x - s * c, o.y - s * si, z, yaw)
    pre = (o.x - (s + pre_grasp_distance) * c, o.y - (s + pre_grasp_distance) * si, z + rise, yaw)
    return Grasp(o.id, yaw, tuple(float(v) for v in g), tuple(float(v) for v in pre))


def along_axis_refusal(shelf: Shelf, o: ShelfObject, max_yaw: float, clearance: float) -> str:
    """Why the grasp along the axis cannot take the lying cylinder `o` ("no grasp: ..."), or "": its approach yaw
    (`lying_axis_yaw`) more than `max_yaw` from straight in, the grasp centre more than AXIS_GRASP_MAX_RAISE above the
    axis, the hand not `clearance` under the board above at the pre-grasp, or the grasp out of the arm's reach."""
    yaw = lying_axis_yaw(o)
    if abs(yaw) > max_yaw + 1e-9:
        return (f"{NO_GRASP}{o.id} lies with its axis {abs(yaw):.2f} rad from pointing into the shelf; a grasp along "
                f"it approaches within {max_yaw:.2f} rad of straight in")
    raise_ = along_axis_raise(o)
    if raise_ > AXIS_GRASP_MAX_RAISE:
        return (f"{NO_GRASP}{o.id} ({o.radius * 1000:.0f} mm radius) is too thin for a grasp along its axis: the "
                f"hand's centre {raise_ * 1000:.0f} mm above it, at most {AXIS_GRASP_MAX_RAISE * 1000:.0f} mm")
    support = shelf.top_z if o.support_z is None else o.support_z
    g = grasp_along_axis(shelf, o, yaw, 0.0, clearance)
    need = hand_heights(g.pre_grasp)[1] - support + clearance
    if need > shelf.ceiling_z - support:
        return (f"{NO_GRASP}{o.id} lies with {shelf.ceiling_z - support:.2f} m of headroom; a grasp along its axis "
                f"needs {need:.2f} m")
    try:
        check_pose(g.grasp, f"grasp of {o.id} along its axis")
    except WorkspaceError as e:
        return f"{NO_GRASP}{o.id} lies out of the arm's reach for a grasp along its axis ({e})"
    return ""


def both_refusals(above: str, along: str) -> str:
    """The reason a lying cylinder is not grasped: the grasp from above's (`lying_pitch`), then the grasp along its
    axis's (`along_axis_refusal`), one "no grasp: "."""
    return f"{above}; nor along its axis: {along.removeprefix(NO_GRASP)}"
