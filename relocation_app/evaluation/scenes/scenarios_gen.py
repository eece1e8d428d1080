"""Seeded scene generator on the real shelf (paper_experiment_10's geometry) and the scene search used to make the
evaluation scenarios (Sect. 5.1: 5, 10, 15 obstacles; Table 4: ten random 5-obstacle scenes).

`random_scene(seed, n, name)` places a target in the back half of the shelf and n obstacles, mostly in front of
it, at least MIN_GAP apart (centre distance 2 r + gap), weights phi_i uniform in [0.05, 0.95] (2 decimals).
`accept(report, ...)` is the admission rule: target blocked at the start, a unique optimal set of obstacles, at least
two feasible sequences from at least two minimal freeing sets (an alternative to
learn against). Feasibility comes from the real planner through the disk cache (feasibility_cache).
"""
from __future__ import annotations

import math
import random
from pathlib import Path

import yaml

from relocation_common.scenario import parse_scenario

SHELF = {"x_front": 0.62, "depth": 0.36, "width": 0.80, "y_center": 0.0, "board_thickness": 0.02,
         "top_z": 0.02, "ceiling_z": 0.28, "bottom_z": -0.18}
MARKER = {"id": 7, "dictionary": "DICT_4X4_50", "size": 0.07, "position": [0.625, -0.345, 0.09],
          "rpy": [1.5707963, 0.0, -1.5707963]}
SLOTS12 = [[0.76, -0.06], [0.76, 0.06], [0.76, -0.18], [0.76, 0.18], [0.76, -0.30], [0.76, 0.30],
           [0.68, -0.06], [0.68, 0.06], [0.68, -0.18], [0.68, 0.18], [0.68, -0.30], [0.68, 0.30]]
RADIUS = 0.033
MIN_GAP = 0.02  # m between bottle surfaces (room for nothing: the hand cannot pass between two such bottles)
X_RANGE = (0.69, 0.93)
Y_HALF = 0.36
MAX_REACH = 0.92  # m from the base axis in xy: beyond it the side grasp is out of the arm's workspace


LATTICE = {0.69: (-0.28, -0.14, 0.0, 0.14, 0.28), 0.79: (-0.33, -0.21, -0.07, 0.07, 0.21, 0.33),
           0.89: (-0.24, -0.12, 0.0, 0.12, 0.24)}  # three staggered rows (scenario3_15's layout)


def lattice_scene(seed: int, n: int, name: str, spread: float = 0.3, jitter: float = 0.01) -> dict:
    """Like random_scene, but the bottles stand on the staggered three-row lattice (jittered): the target in the
    back row, the n obstacles on lattice points within `spread` of it laterally (rows of a real shelf)."""
    rng = random.Random(seed)
    ty = rng.choice((-0.12, 0.0, 0.12))
    tx = 0.89
    cands = [(x, y) for x, ys in LATTICE.items() for y in ys if abs(y - ty) <= spread and (x, y) != (tx, ty)
             and math.hypot(x, y) <= MAX_REACH]
    if len(cands) < n:
        raise RuntimeError(f"seed {seed}: only {len(cands)} lattice points within {spread} m of the target")
    chosen = rng.sample(cands, n)
    pts = [(x + rng.uniform(-jitter, jitter), y + rng.uniform(-jitter, jitter)) for x, y in chosen]
    return scene_data(rng, seed, name, (tx + rng.uniform(-jitter, jitter), ty), pts)


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


def random_scene(seed: int, n: int, name: str, spread: float = 0.22) -> dict:
    """A scenario mapping (load with parse_scenario) with n obstacles o1..on and target T, from `seed`."""
    rng = random.Random(seed)
    while True:
        tx, ty = rng.uniform(0.85, X_RANGE[1]), rng.uniform(-0.18, 0.18)
        if math.hypot(tx, ty) <= MAX_REACH:
            break
    pts = [(tx, ty)]
    tries = 0
    while len(pts) < n + 1:
        tries += 1
        if tries > 20000:
            raise RuntimeError(f"seed {seed}: cannot place {n} obstacles")
        x = rng.uniform(X_RANGE[0], min(X_RANGE[1], tx + 0.03))
        y = rng.uniform(max(-Y_HALF, ty - spread), min(Y_HALF, ty + spread))
        if math.hypot(x, y) > MAX_REACH:
            continue
        if all((x - a) ** 2 + (y - b) ** 2 >= (2 * RADIUS + MIN_GAP) ** 2 for a, b in pts):
            pts.append((x, y))
    return scene_data(rng, seed, name, pts[0], pts[1:])


def accept(report, min_sequences: int = 2) -> bool:
    """Admission rule for an evaluation scene (module docstring)."""
    return (not report.target_free_at_start and report.unique_optimum and len(report.minimal_sets) >= 2
            and report.n_sequences >= min_sequences)


def write_scene(data: dict, path: str | Path, header: str = "") -> Path:
    """Validate `data` as a scenario and write it as YAML to `path`, after the comment `header`."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    parse_scenario(data, str(path))  # validate before writing
    text = yaml.safe_dump(data, sort_keys=False, default_flow_style=None, width=120)
    path.write_text((header.rstrip() + "\n" if header else "") + text)
    return path


def evaluate_scene(data: dict, params, directory, workers: int = 1):
    """Fill the feasibility table of a scene mapping with the real planner and analyse its sequences."""
    from relocation_app.evaluation.feasibility_cache import fill_reachable, open_table
    from relocation_app.evaluation.sequences import analyse

    sc = parse_scenario(data, data["name"])
    table, path = open_table(sc, params, directory)
    fill_reachable(sc, params, table, workers=workers, progress=False, save_to=path)
    return analyse(table, sc), table, path
