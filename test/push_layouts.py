"""Generated "X beside T" layouts for the push (test_push.py, scripts/bench_push.py): the shipped default scene's
shelf and slots, the target T near the front, a bottle X standing beside it (along the shelf, 5-15 mm between
their surfaces: the side grasp of either needs the other gone) and a few other bottles elsewhere, all drawn from
one seed."""
from __future__ import annotations

import copy
import math
import random

import yaml

from relocation_common.paths import default_scenario
from relocation_common.scenario import Scenario, parse_scenario

RADIUS = 0.033  # the default scene's bottles
OTHERS = 3  # bottles besides X and T


def beside_layout(seed: int) -> Scenario:
    """The layout of `seed` (beside_data) as a scenario."""
    data = beside_data(seed)
    return parse_scenario(data, data["name"])


def beside_data(seed: int) -> dict:
    """The layout of `seed` as scenario YAML data: T at x 0.68-0.76, y -0.15..0.15; X beside it on a random side,
    5-15 mm apart; OTHERS bottles elsewhere on the top shelf, at least 30 mm from every other (never in contact)."""
    rng = random.Random(f"push-beside:{seed}")
    with open(default_scenario()) as f:
        data = yaml.safe_load(f)
    sc = parse_scenario(data, "base")
    s = sc.shelf
    tx, ty = rng.uniform(0.68, 0.76), rng.uniform(-0.15, 0.15)
    side = rng.choice((-1.0, 1.0))
    gap = rng.uniform(0.005, 0.015)
    pos = {"T": (tx, ty), "X": (tx + rng.uniform(-0.01, 0.01), ty + side * (2 * RADIUS + gap))}
    while len(pos) < OTHERS + 2:
        x, y = rng.uniform(s.x_front + 0.05, s.x_front + s.depth - 0.05), rng.uniform(-0.33, 0.33)
        if all(math.hypot(x - px, y - py) >= 2 * RADIUS + 0.03 for px, py in pos.values()):
            pos[f"o{len(pos) - 1}"] = (x, y)
    out = copy.deepcopy(data)
    out["name"] = f"push_beside_s{seed}"
    out["objects"] = [{"id": i, "weight": 0.3, "xy": [round(x, 4), round(y, 4)]} if i != "T" else
                      {"id": i, "xy": [round(x, 4), round(y, 4)]} for i, (x, y) in pos.items()]
    return out
