"""Action to pose (paper Sect. 4.1, step 1): the side grasp of a standing object, its pre-grasp, and the carry poses.

Tool frame (DH frame 7): z is the approach direction, x the closing direction of the fingers, origin the grasp
centre. A side grasp keeps the hand horizontal: tool z = (cos yaw, sin yaw, 0) points into the shelf from its
open side (-x), tool y = world z (vertical), tool x = y x z (horizontal). The tool origin is at the object's
mid-height, `grasp_standoff(half_depth)` short of its centre along the approach (`grasp_extent`: a cylinder's
radius, a box's half-size along the approach), so that the palm stops PALM_GAP from the object (the palm's front
is PALM_REACH behind the grasp centre; the open fingers still surround the object).
A Cartesian pose here is (x, y, z, yaw): position of the tool and yaw of the approach direction.
The robot's home pose (Q_HOME) is such a pose with yaw 0.

What the side grasp takes (`grasp_refusal`): a standing cylinder, approached at any yaw of the tiers (`yaw_tiers`),
or a standing box, approached square to one of its vertical faces (`face_yaws`: its yaw + k pi/2 within the tiers'
range), the fingers closing across the box's width perpendicular to that approach; either no wider there than the
open hand (`hand_opening`: the gap between the description's open finger capsules where the object's centre comes
to rest). A lying cylinder, a conservative object (a cluster no primitive fits), a wider cylinder or a box too
wide across every face it can be approached by is answered "no grasp: " and the reason: it stays an obstacle,
never relocated. A box is carried as held: square to the hand, so placed in its slot square to the shelf.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence, Union

import numpy as np

from relocation_common import robot_description as rd
from relocation_common.feasibility import NO_GRASP
from relocation_common.scenario import Scenario, ShelfObject
from relocation_common.shelf_object import UPRIGHT_TILT

Pose = Union[Sequence[float], np.ndarray]  # (x, y, z, yaw) of the tool: a side grasp's pose
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


def grasp_refusal(o: ShelfObject, max_yaw: float = math.pi) -> str:
    """Why the side grasp cannot take `o` ("no grasp: ..."), or "" when it may (module docstring): a conservative
    object, a box too wide across every face within `max_yaw` of straight in (`box_refusal`; default: any face),
    a cylinder lying (its axis more than UPRIGHT_TILT from the vertical), or a cylinder wider than the open hand
    where its axis comes to rest (`hand_fits`)."""
    if o.conservative:
        return (f"{NO_GRASP}{o.id} is a conservative obstacle (an unfitted cluster's bounding box, "
                f"{o.describe()}): an obstacle only")
    if o.shape == "box":
        return box_refusal(o, max_yaw)
    if o.axis_tilt > UPRIGHT_TILT:
        return f"{NO_GRASP}{o.id} is lying on its side: the side grasp takes standing objects only"
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


def approach_yaw(rot: np.ndarray) -> float:
    """Yaw (rad) of the approach direction (the tool's z axis) of a tool rotation: the inverse of side_rotation."""
    return float(math.atan2(rot[1, 2], rot[0, 2]))


def pose_matrix(pose4: Pose) -> tuple[np.ndarray, np.ndarray]:
    """(rotation, position) of an (x, y, z, yaw) side-grasp pose."""
    x, y, z, yaw = pose4
    return side_rotation(yaw), np.array([x, y, z], dtype=float)


def check_pose(pose4: Pose, where: str = "pose") -> np.ndarray:
    """Raise WorkspaceError unless pose4 is finite and the wrist centre is within the arm's reach."""
    p = np.asarray(pose4, dtype=float)
    if p.shape != (4,) or not np.all(np.isfinite(p)):
        raise WorkspaceError(f"{where}: need 4 finite numbers (x, y, z, yaw), got {pose4!r}")
    r, t = pose_matrix(p)
    wrist = t - r[:, 2] * rd.D67
    reach = float(np.linalg.norm(wrist - np.array([0.0, 0.0, rd.D1])))
    if reach > rd.D23 + rd.D45 - 0.02 or reach < 0.15:
        raise WorkspaceError(f"{where}: {np.round(p, 3).tolist()} is outside the arm's workspace "
                             f"(wrist {reach:.3f} m from the shoulder, reachable 0.15-{rd.D23 + rd.D45 - 0.02:.2f})")
    return p


@dataclass(frozen=True)
class Grasp:
    """A side grasp of one object: approach yaw, grasp and pre-grasp poses (x, y, z, yaw)."""

    object_id: str
    yaw: float
    grasp: tuple[float, float, float, float]
    pre_grasp: tuple[float, float, float, float]


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
    """The approach yaws of object `o` in the order they are tried: a cylinder's `yaw_tiers`; a box's face yaws
    (`face_yaws`) the open hand fits (`hand_fits`), within max_yaw first, then (with a second tier, wide_n > 0)
    those within wide_max_yaw."""
    if o.shape != "box":
        return yaw_tiers(n, max_yaw, wide_n, wide_max_yaw)
    fits = [y for y in face_yaws(o) if hand_fits(o, y)]
    first = [y for y in fits if abs(y) <= max_yaw + 1e-9]
    wide = [y for y in fits if max_yaw + 1e-9 < abs(y) <= wide_max_yaw + 1e-9] if wide_n else []
    return [first, wide] if wide else [first]


def side_grasp(scenario: Scenario, object_id: str, yaw: float, pre_grasp_distance: float) -> Grasp:
    """Grasp and pre-grasp poses of a standing object on the top shelf for one approach yaw (at its mid-height,
    `grasp_standoff` short of its centre: the module docstring)."""
    b = scenario.object(object_id)
    z = scenario.shelf.top_z + b.height / 2
    s = grasp_standoff(grasp_extent(b, yaw)[0])
    g = (b.x - s * math.cos(yaw), b.y - s * math.sin(yaw), z, yaw)
    d = s + pre_grasp_distance
    pre = (b.x - d * math.cos(yaw), b.y - d * math.sin(yaw), z, yaw)
    check_pose(g, f"grasp of {object_id}")
    return Grasp(object_id, yaw, g, pre)


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


def exit_pose(scenario: Scenario, object_id: str, pose: Pose, margin: float) -> tuple[float, float, float, float]:
    """`pose` moved back against its approach direction, at its height, until the held object (its centre
    `grasp_standoff` beyond the tool; a box square to the hand, its corners reaching `grasp_extent` along and
    across the approach) and the finger tips are `margin` in front of the shelf's front edge: out of the shelf,
    free to go down."""
    b = scenario.object(object_id)
    x, y, z, yaw = (float(v) for v in pose)
    c = math.cos(yaw)
    half_depth, width = grasp_extent(b, yaw)
    ahead = (grasp_standoff(half_depth) + half_depth) * c  # a cylinder: as its axis and radius always were
    if b.shape == "box":
        ahead += width / 2 * abs(math.sin(yaw))
    need = x + max(ahead, FINGER_REACH * c) - (scenario.shelf.x_front - margin)
    if need <= 0.0:
        return (x, y, z, yaw)
    back = need / c
    return (x - back * c, y - back * math.sin(yaw), z, yaw)


def place_poses(scenario: Scenario, object_id: str, slot_xy: tuple[float, float], drop: float,
                stage_distance: float, grasp_yaw: float) -> tuple[tuple, tuple]:
    """(staging pose in front of the bottom shelf, place pose at the slot), approach straight in (yaw 0).
    The tool is at the object's mid-height with its base `drop` above the bottom shelf (the release height of
    `carry_heights`) and its centre on the slot: `grasp_standoff` ahead, for the depth it was grasped by at
    `grasp_yaw` (a box is held square to the hand: `grasp_extent`)."""
    b = scenario.object(object_id)
    z = scenario.shelf.bottom_z + drop + b.height / 2
    place = (slot_xy[0] - grasp_standoff(grasp_extent(b, grasp_yaw)[0]), slot_xy[1], z, 0.0)
    stage = (min(slot_xy[0] - stage_distance, scenario.shelf.x_front - 0.07), slot_xy[1], z, 0.0)
    check_pose(place, f"place of {object_id} at slot {slot_xy}")
    return stage, place
