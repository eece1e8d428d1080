"""A scene update checked against the scenario before any of it is merged (ROS-free).

A scene (perception's or the driver's ObjectArray) names the scenario's objects, once each, and may hold objects the
scenario does not list (`listed: false`: perception found them, or only the simulator knows them): those must not
take an id the scenario lists. Every pose is finite and on or near the shelf unit. One fault drops the whole
message (never merged in part): a listed bottle renamed by a bad message would otherwise stay in the planner's scene
as a phantom obstacle that no relocation removes, and every later training would end without a sequence
(docs/reliability.md, "Never report success that is not true").
"""
from __future__ import annotations

import math
from typing import Collection, Iterable

from .scenario import Scenario, ScenarioError

NEAR_SHELF = 0.5  # m: an object's frame farther than this outside the shelf unit's box is not a scene of this shelf


def check_scene(scenario: Scenario, objects: Iterable[tuple[str, float, float, float]], source: str = "scene",
                unlisted: Collection[str] = ()) -> None:
    """ScenarioError naming the first fault of `objects` = (id, x, y, z) of each object: a listed id the scenario
    does not have, an unlisted one (in `unlisted`: the message says `listed: false`) that it does, an id twice, a
    non-finite coordinate, or a pose away from the shelf by more than NEAR_SHELF."""
    s = scenario.shelf
    box = ((s.x_front - NEAR_SHELF, s.x_back + NEAR_SHELF), (s.y_min - NEAR_SHELF, s.y_max + NEAR_SHELF),
           (s.bottom_z - NEAR_SHELF, s.ceiling_z + NEAR_SHELF))
    seen: set[str] = set()
    for k, (oid, *xyz) in enumerate(objects):
        where = f"{source}: objects[{k}]"
        if oid in unlisted and oid in scenario.ids:
            raise ScenarioError(f"{where}: {oid!r} is marked unlisted, but scenario {scenario.name!r} lists that id")
        if oid not in scenario.ids and oid not in unlisted:
            raise ScenarioError(f"{where}: id {oid!r} is not in scenario {scenario.name!r} (known: "
                                f"{', '.join(scenario.ids)}; an object the scenario does not list must be marked "
                                "listed: false)")
        if oid in seen:
            raise ScenarioError(f"{where}: {oid!r} appears twice")
        seen.add(oid)
        if not all(isinstance(v, (int, float)) and math.isfinite(v) for v in xyz):
            raise ScenarioError(f"{where} ({oid}): pose {tuple(xyz)} is not finite")
        if not all(lo <= v <= hi for v, (lo, hi) in zip(xyz, box)):
            raise ScenarioError(f"{where} ({oid}): pose ({xyz[0]:.3g}, {xyz[1]:.3g}, {xyz[2]:.3g}) is more than "
                                f"{NEAR_SHELF} m away from the shelf")


def foreign_ids(planner_ids: Iterable[str], scene_ids: Iterable[str]) -> str:
    """The text added to 'training did not find a sequence': the objects the motion planner's scene holds that the
    task's scene does not (obstacles no relocation of this task removes), or '' when there are none."""
    extra = sorted(set(planner_ids) - set(scene_ids))
    if not extra:
        return ""
    return (f"; the motion planner's scene holds {', '.join(extra)}, which this scene does not (no relocation can "
            "remove them): restart the motion planner with this scene's scenario, or publish the scene it knows")
