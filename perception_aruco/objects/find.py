"""The objects of one frame from its clusters: a primitive per cluster, listed objects by identity, the rest
unlisted (docs/perception.md, "Objects"). A listed standing cylinder is placed by the circle of its known radius
(localize.locate_cylinder: sub-millimetre where the free fit is a few millimetres); when that fit is doubtful, or
two listed fits overlap, or one lies outside the shelf, the listed object is reported missing with the reason and
its cluster published as an unlisted object: occupied space is never left out. A cluster within a found object's
space is a piece of it (`part_of`); one within the last pose of a listed object held unseen (`held_tol`: its
identity not established in this frame) is that object, kept at its last pose, never a new unlisted object."""
from __future__ import annotations

import math
from dataclasses import replace
from typing import Callable, Iterable

import numpy as np

from relocation_common.scenario import Scenario, ShelfObject

from ..localize import FitError, LocalizeParams, circle_points, locate_cylinder
from ..segmentation import SegmentationParams
from .clusters import Cluster
from .fragments import merge_fragments
from .identity import NO_MATCH, Fitted, Memory, assign, colour_name, listed_box, listed_costs, unlisted_ids
from .model import BOX, CYLINDER, PerceivedObject, inside, weight_estimate
from .noise import DepthNoise, cap_below, top_face
from .params import ObjectParams
from .primitives import fit_primitive

BOARD_APART = 0.05  # m: supports further apart than this are different boards
KEPT = "; a cluster within its last pose: that object, kept there"


def fit_clusters(clusters: list[Cluster], image_points: np.ndarray, camera: np.ndarray, seg: SegmentationParams,
                 params: ObjectParams, loc: LocalizeParams, noise: DepthNoise) -> list[Fitted]:
    """Each cluster's best primitive (primitives.fit_primitive) and its circle points (its top face told apart by the
    depth noise at the cluster's own depth, noise.cap_below); the pieces of one object merged
    (fragments.merge_fragments)."""
    def fit(c: Cluster, search: bool = True) -> Fitted:
        top = float(np.percentile(c.points[:, 2], 99.5))
        sigma = noise.at(c.points)
        xy, clear = circle_points(c.rows, c.cols, image_points, top, camera, loc, cap_below(top, loc.cap_margin, sigma))
        prim = fit_primitive(c.points, xy, clear, top, top_face(top, sigma), c.support, camera, params, noise.shelf,
                             loc.inlier_tol, search)
        return Fitted(c, prim, xy, (int(np.median(c.cols)), int(np.median(c.rows))))
    return merge_fragments([fit(c) for c in clusters], lambda c: fit(c, False), seg, params.merge_gap)


def listed_object(b: ShelfObject, f: Fitted, camera: np.ndarray, params: ObjectParams,
                  loc: LocalizeParams) -> PerceivedObject:
    """Listed object b as cluster f shows it: a box where its fitted box or the one face it shows puts it
    (identity.listed_box); a cylinder lying where its lying fit puts it (a tipped bottle; one end cap hidden: its
    known length laid from the other), else standing on the circle of its known radius (FitError when that fit is
    doubtful)."""
    p, c = f.prim, f.cluster
    rgb = tuple(float(v) for v in np.clip(c.colour / 255.0, 0, 1))
    if b.shape == BOX:  # at its known size (identity.listed_costs matched it: the pose exists)
        pose = listed_box(b, f, camera, params, loc)
        if pose is None:
            raise FitError(f"{b.id!r}: its cluster shows no box of its size")
        return PerceivedObject(b.id, b.label, (rgb[0], rgb[1], rgb[2]), b.weight, "", b.is_target, True, BOX,
                               pose.x, pose.y, c.support, 0.0, b.height, b.size, pose.yaw, False, False, p.rms,
                               c.size, f.pixel)
    if p.shape == CYLINDER and p.lying:
        x, y, rms, n = p.x, p.y, p.rms, c.size
        if p.ends_seen[0] != p.ends_seen[1] and p.height < b.height:  # one end hidden: the length from the other
            shift = (b.height - p.height) / 2 * (1.0 if p.ends_seen[0] else -1.0)
            x, y = x + shift * math.cos(p.yaw), y + shift * math.sin(p.yaw)
    else:
        (x, y), rms, n = locate_cylinder(f.circle_xy, b.radius, camera, loc, b.id)
        spread = float(np.percentile(np.hypot(c.points[:, 0] - x, c.points[:, 1] - y), 95))
        if spread > b.radius + 2 * loc.inlier_tol:   # its circle must hold its cluster (a fit on a fragment's edge)
            raise FitError(f"the circle of {b.id!r}'s radius fitted to its cluster leaves its points "
                           f"{(spread - b.radius) * 1000:.0f} mm outside")
    return PerceivedObject(b.id, b.label, (rgb[0], rgb[1], rgb[2]), b.weight, "", b.is_target, True, CYLINDER,
                           float(x), float(y), c.support, b.radius, b.height, (2 * b.radius, 2 * b.radius, b.height),
                           p.yaw if p.lying else 0.0, p.lying, False, float(rms), int(n), f.pixel)


def room_above(support: float, scenario: Scenario) -> float:
    """Height of the compartment above a board (m): to the ceiling board, or to the top board's underside."""
    s = scenario.shelf
    return (s.ceiling_z if support > s.top_z - s.board_thickness / 2 else s.top_z - s.board_thickness) - support


def unlisted_object(f: Fitted, params: ObjectParams, seg: SegmentationParams, room: float) -> PerceivedObject:
    """Cluster f as an object the scenario does not list (its id set by `unlisted_ids`), weight estimated. Its top
    not seen (something nearer hides it): as tall as its compartment (`room`), said in its weight note."""
    p, c = f.prim, f.cluster
    rgb = tuple(float(v) for v in np.clip(c.colour / 255.0, 0, 1))
    h, size = p.height, p.size
    if not p.top_seen and not p.lying:
        h, size = max(h, room), (size[0], size[1], max(h, room))
    o = PerceivedObject("", colour_name(c.colour, c.clipped, seg), (rgb[0], rgb[1], rgb[2]), 0.0, "", False, False,
                        p.shape, p.x, p.y, c.support, p.radius, h, size, p.yaw, p.lying, p.conservative,
                        p.rms, c.size, f.pixel)
    w, note = weight_estimate(o, params.unlisted_density)
    if h != p.height:
        note += f"; top not seen: as tall as its compartment ({h * 1000:.0f} mm, {p.height * 1000:.0f} mm seen)"
    return replace(o, weight=w, weight_note=note + (f"; conservative: {p.why}" if p.conservative else ""))


def part_of(f: Fitted, listed: Iterable[PerceivedObject], params: ObjectParams, tol: float) -> str | None:
    """The id of an object whose space cluster f lies in (all but `absorb_outside` of its points within `tol` of
    its primitive), or None. An object found: a piece of it the clustering kept apart (an edge seen past a nearer
    object, a rim), already explained by it; a listed object held unseen at its last pose: that object, seen
    without its identity (`find_objects`). Not an object of its own either way."""
    pts = f.cluster.points
    return next((o.id for o in listed if float(np.mean(inside(o, pts, tol))) >= 1.0 - params.absorb_outside), None)


def _doubtful(found: dict[str, PerceivedObject], scenario: Scenario, tol: float) -> dict[str, str]:
    """Listed fits outside the shelf, and pairs on one board whose footprints overlap by more than 2 tol (each shrunk
    by tol still sharing area): id -> why."""
    sh, out = scenario.shelf, {}
    for i, d in found.items():
        hx, hy = d.half_extent  # not the bounding circle: a bottle lying along the front edge is inside the shelf
        if not (sh.x_front + hx - tol <= d.x <= sh.x_back - hx + tol
                and sh.y_min + hy - tol <= d.y <= sh.y_max - hy + tol):
            out[i] = f"fit at ({d.x:.3f}, {d.y:.3f}) is not inside the shelf: not this object"
    ids = [i for i in found if i not in out]
    shrunk = {i: _outline(found[i]).footprint(-tol) for i in ids}  # overlapping by more than 2 tol: sharing area
    for a, i in enumerate(ids):
        for j in ids[a + 1:]:
            di, dj = found[i], found[j]
            if abs(di.z - dj.z) <= BOARD_APART and not (di.lying or dj.lying) and shrunk[i].overlaps(shrunk[j]):
                gap = math.hypot(di.x - dj.x, di.y - dj.y) - di.reach - dj.reach
                by = f" by {-gap * 1000:.0f} mm" if di.shape == dj.shape == CYLINDER else ""
                why = f"overlaps {{}}{by}: identity in doubt"
                out[i], out[j] = why.format(j), why.format(i)
    return out


def _outline(o: PerceivedObject) -> ShelfObject:
    """A perceived object as the ShelfObject whose footprint (ShelfObject.footprint) it has: a box's rectangle, not
    its bounding circle."""
    return ShelfObject(o.id, o.label, o.rgb, 1.0, o.x, o.y, o.radius, o.height, False, o.shape, o.size, o.yaw,
                       o.lying, support_z=o.z)


def _why_missing(j: int, b: ShelfObject, cost: np.ndarray, taken: dict[int, str], fitted: list[Fitted],
                 max_cost: float) -> str:
    """Why listed object j matched no cluster."""
    m = int(np.argmin(cost[j])) if cost.shape[1] else -1
    if m < 0 or cost[j, m] >= NO_MATCH:
        return f"no cluster of its colour {b.label!r} and size in view (hidden or out of view)"
    at = f"the cluster at ({fitted[m].prim.x:.3f}, {fitted[m].prim.y:.3f})"
    if m in taken:
        return f"{at}, its best match, is {taken[m]}"
    return f"{at}, its best match, costs {cost[j, m]:.1f} (bound {max_cost:g})"


def find_objects(clusters: list[Cluster], image_points: np.ndarray, scenario: Scenario, memory: Memory,
                 seg: SegmentationParams, params: ObjectParams, loc: LocalizeParams, camera: np.ndarray,
                 noise: DepthNoise, new_unlisted: Callable[[np.ndarray], bool] = lambda points: True
                 ) -> tuple[dict[str, PerceivedObject], dict[str, str], int]:
    """(objects by id: listed ones first in scenario order, then unlisted; missing listed id -> reason; clusters
    left out). new_unlisted(points) False (the arm in the shelf, near those points): a cluster that is no listed
    object and no known unlisted one is left out, not made a new object (counted): the arm's body between joint
    states, the object in its hand and the pieces it cuts out of others are where such clusters come from; new
    objects there are taken from frames with the arm away."""
    fitted = fit_clusters(clusters, image_points, camera, seg, params, loc, noise)
    cost = listed_costs(fitted, scenario.objects, memory, seg, params, loc, camera)
    found: dict[str, PerceivedObject] = {}
    cluster_of: dict[str, int] = {}
    missing: dict[str, str] = {}
    for j, m in assign(cost, params.max_cost):
        b = scenario.objects[j]
        try:
            found[b.id] = listed_object(b, fitted[m], camera, params, loc)
            cluster_of[b.id] = m
        except FitError as e:
            missing[b.id] = f"{e}; its cluster published as an unlisted object"
    for i, why in _doubtful(found, scenario, loc.inlier_tol).items():
        missing[i] = f"{why}; its cluster published as an unlisted object"
        del found[i], cluster_of[i]
    taken = {m: i for i, m in cluster_of.items()}
    for j, b in enumerate(scenario.objects):
        if b.id not in found and b.id not in missing:
            missing[b.id] = _why_missing(j, b, cost, taken, fitted, params.max_cost)
    held = [o for i, o in memory.held().items() if i not in found]
    rest: list[PerceivedObject] = []
    rest_points: list[np.ndarray] = []
    for m, f in enumerate(fitted):
        if m in taken or part_of(f, found.values(), params, params.absorb_tol) is not None:
            continue
        at = part_of(f, held, params, params.held_tol)
        if at is not None:   # its last pose's space: that object, kept there, not a new one (e.g. its colour hidden)
            why = missing.get(at, "not identified").replace("; its cluster published as an unlisted object", "")
            missing[at] = why + ("" if why.endswith(KEPT) else KEPT)
            continue
        rest.append(unlisted_object(f, params, seg, room_above(f.cluster.support, scenario)))
        rest_points.append(f.cluster.points)
    ids = unlisted_ids(rest, memory, params.unlisted_gate)
    known = memory.unlisted()
    objects = {b.id: found[b.id] for b in scenario.objects if b.id in found}
    objects.update({i: replace(o, id=i) for i, o, pts in zip(ids, rest, rest_points)
                    if i in known or new_unlisted(pts)})
    return objects, missing, sum(1 for i in ids if i not in objects)
