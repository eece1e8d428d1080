"""What every scene maker draws and writes alike: the shelf of paper_experiment_10 with its marker and slots, a
generated scene's scenario mapping (`scene_data`), bottles at random free spots (`free_spots`: `free_scene`,
`extend_scene`), and the scenario file after its "made by" header (`write_scene`, `made_by`)."""
from __future__ import annotations

import copy
import math
import random
from collections.abc import Callable, Iterator
from pathlib import Path

import yaml

from relocation_common.scenario import parse_scenario

COMMAND = "python -m relocation_app.evaluation.scenes"  # the scene maker (scenes/cli.py)

SHELF = {"x_front": 0.62, "depth": 0.36, "width": 0.80, "y_center": 0.0, "board_thickness": 0.02,
         "top_z": 0.02, "ceiling_z": 0.28, "bottom_z": -0.18}
MARKER = {"id": 7, "dictionary": "DICT_4X4_50", "size": 0.07, "position": [0.625, -0.345, 0.09],
          "rpy": [1.5707963, 0.0, -1.5707963]}
SLOTS12 = [[0.76, -0.06], [0.76, 0.06], [0.76, -0.18], [0.76, 0.18], [0.76, -0.30], [0.76, 0.30],
           [0.68, -0.06], [0.68, 0.06], [0.68, -0.18], [0.68, 0.18], [0.68, -0.30], [0.68, 0.30]]
RADIUS = 0.033
MAX_REACH = 0.92  # m from the base axis in xy: beyond it the side grasp is out of the arm's workspace
X_FREE = (0.655, 0.93)  # m: x of a bottle drawn at a free spot (the shelf's front edge plus a bottle's radius on)
Y_FREE = 0.33  # m: largest |y| of a bottle drawn at a free spot
DRAWS = 20000  # spots drawn before a layout is given up


def made_by(kind: str) -> str:
    """The scene maker's command line for `kind` (the scenario headers name it)."""
    return f"`{COMMAND} {kind}`"


def scene_data(rng, seed, name, target, pts, radius: float = RADIUS) -> dict:
    """The scenario file's data of a generated scene: the target at `target`, obstacles at `pts` with random
    weights (`rng`), the shelf, marker and slots of this project's geometry."""
    tx, ty = target
    obstacles = sorted(pts, key=lambda p: (round(p[0], 2), p[1]))
    objects = [{"id": f"o{k + 1}", "weight": round(rng.uniform(0.05, 0.95), 2), "xy": [round(x, 3), round(y, 3)]}
               for k, (x, y) in enumerate(obstacles)]
    objects.append({"id": "T", "xy": [round(tx, 3), round(ty, 3)]})
    n = len(pts)
    return {"name": name, "description": f"Generated (seed {seed}): {n} obstacles, target T blocked.",
            "shelf": dict(SHELF), "defaults": {"radius": radius, "height": 0.16}, "marker": dict(MARKER),
            "target": "T", "objects": objects, "slots": SLOTS12 if n + 1 <= len(SLOTS12) else "auto"}


def free_spots(pts: list, draw: Callable[[], tuple[float, float]], gap: float) -> Iterator[tuple[float, float]]:
    """Up to DRAWS spots from `draw()`: each within the arm's reach, |y| <= Y_FREE and `gap` (centre distance) from
    every point of `pts` is appended to `pts`, rounded to the mm, and yielded."""
    for _ in range(DRAWS):
        x, y = draw()
        if abs(y) <= Y_FREE and math.hypot(x, y) <= MAX_REACH and all(math.hypot(x - a, y - b) >= gap
                                                                      for a, b in pts):
            pts.append((round(x, 3), round(y, 3)))
            yield pts[-1]


def free_scene(seed: int, n: int, name: str, radius: float = RADIUS) -> dict:
    """n obstacles of `radius` at random non-overlapping spots in front of and beside a back-row target (no
    lattice), possibly behind a column straight in front of the target: a removal chain of as many bottles as
    the shelf's depth holds (3 of radius 0.033, 4 of 0.025)."""
    rng = random.Random(seed)
    tx, ty = rng.uniform(0.87, 0.91), rng.uniform(-0.1, 0.1)
    spread = rng.uniform(min(0.12 + 0.012 * (n - 5), 0.28), 0.33)  # room for n bottles
    pts: list[tuple[float, float]] = [(tx, ty)]
    pitch = (2 * radius + 0.006, 2 * radius + 0.019)
    for _ in range(rng.randint(0, int((0.89 - X_FREE[0]) / pitch[0]))):  # the column in front of the target
        pts.append((round(pts[-1][0] - rng.uniform(*pitch), 3), round(ty + rng.uniform(-0.01, 0.01), 3)))
    if pts[-1][0] < X_FREE[0]:
        pts.pop()
    spots = free_spots(pts, lambda: (rng.uniform(X_FREE[0], tx + 0.02), ty + rng.uniform(-spread, spread)),
                       2 * radius + 0.002)
    while len(pts) < n + 1 and next(spots, None) is not None:
        pass
    if len(pts) < n + 1:
        raise RuntimeError(f"seed {seed}: cannot place {n} obstacles")
    return scene_data(rng, seed, name, pts[0], pts[1:], radius)


def extend_scene(base: dict, seed: int, n: int, name: str) -> dict | None:
    """`base` (a smaller scene whose tree has the paper's shape) with obstacles added at random free spots up to
    n: blocked ones add edges to every node, removable ones add nodes. None if they do not fit."""
    rng = random.Random(seed)
    d = copy.deepcopy(base)
    d["name"] = name
    pts = [tuple(o["xy"]) for o in d["objects"]]
    k = sum(1 for o in d["objects"] if o["id"] != d["target"])
    spots = free_spots(pts, lambda: (round(rng.uniform(*X_FREE), 3), round(rng.uniform(-Y_FREE, Y_FREE), 3)),
                       2 * d.get("defaults", {}).get("radius", RADIUS) + 0.002)
    while k < n and (spot := next(spots, None)) is not None:
        k += 1
        d["objects"].insert(-1, {"id": f"o{k}", "weight": round(rng.uniform(0.05, 0.95), 2), "xy": list(spot)})
    if k < n:
        return None
    d["slots"] = "auto" if n + 1 > 12 else d["slots"]
    return d


def write_scene(data: dict, path: str | Path, header: str) -> Path:
    """Validate `data` as a scenario and write it as YAML to `path`, after the comment `header`."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    parse_scenario(data, str(path))  # validate before writing
    text = yaml.safe_dump(data, sort_keys=False, default_flow_style=None, width=120)
    path.write_text((header.rstrip() + "\n" if header else "") + text)
    return path
