"""Generated "X beside T" layouts for the push (test_push.py, scripts/bench_push.py): the shipped default scene's
shelf and slots, the target T near the front, a bottle X standing beside it (along the shelf, 5-15 mm between
their surfaces: the side grasp of either needs the other gone) and a few other bottles elsewhere, all drawn from
one seed."""
from __future__ import annotations

import copy
import math
import random

import yaml

from relocation_common.paths import config_file, default_scenario
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
    data, sc = _base()
    pos, _ = _t_and_x(rng)
    return _layout(data, f"push_beside_s{seed}", _others(rng, sc, pos, OTHERS + 2))


def box_beside_layout(seed: int) -> Scenario:
    """The layout of `seed` (box_beside_data) as a scenario."""
    data = box_beside_data(seed)
    return parse_scenario(data, data["name"])


def box_beside_data(seed: int) -> dict:
    """"A box X beside T" as scenario YAML data: T drawn as in beside_data; X a box (sides 0.05-0.08 m, 0.10-0.16 m
    tall, turned by up to 45 deg) beside it on a random side, its rectangle 5-15 mm from T's circle along the line
    between them; OTHERS bottles elsewhere, at least 30 mm from every other bottle."""
    rng = random.Random(f"push-box-beside:{seed}")
    data, sc = _base()
    tx, ty = rng.uniform(0.68, 0.76), rng.uniform(-0.15, 0.15)
    side, gap = rng.choice((-1.0, 1.0)), rng.uniform(0.005, 0.015)
    sx, sy, sz = rng.uniform(0.05, 0.08), rng.uniform(0.05, 0.08), rng.uniform(0.10, 0.16)
    yaw = rng.uniform(-math.pi / 4, math.pi / 4)
    half_y = abs(math.sin(yaw)) * sx / 2 + abs(math.cos(yaw)) * sy / 2
    x = (tx + rng.uniform(-0.01, 0.01), ty + side * (RADIUS + gap + half_y))
    pos = _others(rng, sc, {"T": (tx, ty), "X": x}, OTHERS + 2)  # >= 6 mm from the box's corners
    out = _layout(data, f"push_box_beside_s{seed}", pos)
    for o in out["objects"]:
        if o["id"] == "X":
            o.update({"shape": "box", "size": [round(sx, 4), round(sy, 4), round(sz, 4)], "yaw": round(yaw, 4)})
    return out


def held_lane_layout(seed: int) -> Scenario:
    """The layout of `seed` (held_lane_data) as a scenario."""
    data = held_lane_data(seed)
    return parse_scenario(data, data["name"])


def held_lane_data(seed: int) -> dict:
    """"X beside T, B across" as scenario YAML data: T and X drawn as in beside_data, a bottle B on the far side of T
    from X (0.105-0.15 m across, 0.02 m nearer the front to 0.05 m farther back): where the widest grasp lane of T on
    that side comes in, the lane the shortest push of X opens; OTHERS - 1 bottles elsewhere, at least 30 mm from
    every other. The layouts where the shortest push of X opens a lane B still holds while a longer one may open a
    free lane."""
    rng = random.Random(f"push-held-lane:{seed}")
    data, sc = _base()
    pos, side = _t_and_x(rng)
    tx, ty = pos["T"]
    pos["B"] = (tx + rng.uniform(-0.02, 0.05), ty - side * rng.uniform(0.105, 0.15))
    return _layout(data, f"push_held_lane_s{seed}", _others(rng, sc, pos, OTHERS + 2))


def _base() -> tuple[dict, Scenario]:
    with open(default_scenario()) as f:
        data = yaml.safe_load(f)
    return data, parse_scenario(data, "base")


def _t_and_x(rng: random.Random) -> tuple[dict[str, tuple[float, float]], float]:
    """T at x 0.68-0.76, y -0.15..0.15 and X beside it on a random side (the side's sign), 5-15 mm apart."""
    tx, ty = rng.uniform(0.68, 0.76), rng.uniform(-0.15, 0.15)
    side = rng.choice((-1.0, 1.0))
    gap = rng.uniform(0.005, 0.015)
    return {"T": (tx, ty), "X": (tx + rng.uniform(-0.01, 0.01), ty + side * (2 * RADIUS + gap))}, side


def _others(rng: random.Random, sc: Scenario, pos: dict[str, tuple[float, float]], n: int
            ) -> dict[str, tuple[float, float]]:
    """`pos` filled up to `n` bottles o<k> drawn on the top shelf, at least 30 mm from every other."""
    s = sc.shelf
    while len(pos) < n:
        x, y = rng.uniform(s.x_front + 0.05, s.x_front + s.depth - 0.05), rng.uniform(-0.33, 0.33)
        if all(math.hypot(x - px, y - py) >= 2 * RADIUS + 0.03 for px, py in pos.values()):
            pos[f"o{len(pos) - 1}"] = (x, y)
    return pos


def _layout(data: dict, name: str, pos: dict[str, tuple[float, float]]) -> dict:
    out = copy.deepcopy(data)
    out["name"] = name
    out["objects"] = [{"id": i, "weight": 0.3, "xy": [round(x, 4), round(y, 4)]} if i != "T" else
                      {"id": i, "xy": [round(x, 4), round(y, 4)]} for i, (x, y) in pos.items()]
    return out


def lying_layout(seed: int) -> Scenario:
    """The layout of `seed` (lying_data) as a scenario."""
    data = lying_data(seed)
    return parse_scenario(data, data["name"])


def lying_data(seed: int) -> dict:
    """"X lying in T's lanes" as scenario YAML data, on paper_experiment_10's shelf (0.26 m of headroom: no grasp
    from above): T standing at x 0.80-0.88, y -0.12..0.12; X (a bottle of the default size) lying flat 5-15 mm from
    it, on a side drawn from the seed: across the shelf in front of T (axis yaw pi/2 +- 0.3 rad, its centre up to
    40 mm off T's line), or along it beside T (yaw +- 0.3 rad, its centre up to 60 mm nearer the front than T's);
    OTHERS bottles standing elsewhere on the top shelf, at least 30 mm from every other footprint."""
    rng = random.Random(f"push-lying:{seed}")
    with open(config_file("scenarios/paper_experiment_10.yaml")) as f:
        data = yaml.safe_load(f)
    sc = parse_scenario(data, "base")
    tx, ty = rng.uniform(0.80, 0.88), rng.uniform(-0.12, 0.12)
    gap = rng.uniform(0.005, 0.015)
    if rng.random() < 0.5:  # across, in front of T
        yaw = math.pi / 2 + rng.uniform(-0.3, 0.3)
        x = (tx - RADIUS - gap - RADIUS / abs(math.sin(yaw)) - 0.08 * abs(math.cos(yaw)), ty + rng.uniform(-0.04, 0.04))
    else:  # along, beside T
        yaw, side = rng.uniform(-0.3, 0.3), rng.choice((-1.0, 1.0))
        dx = -rng.uniform(0.0, 0.06)
        x = (tx + dx, ty + side * (RADIUS + gap + RADIUS / math.cos(yaw) + abs(dx * math.tan(yaw))))
    objs = [{"id": "T", "xy": [round(tx, 4), round(ty, 4)]},
            {"id": "X", "weight": 0.3, "xy": [round(x[0], 4), round(x[1], 4)], "lying": True,
             "yaw": round(math.remainder(yaw, math.pi), 4)}]
    _add_others(rng, sc.shelf, {"T": (tx, ty), "X": x}, objs, 0.08)
    out = copy.deepcopy(data)
    out["name"] = f"push_lying_s{seed}"
    out["objects"] = objs
    return out


def across_layout(seed: int) -> Scenario:
    """The layout of `seed` (across_data) as a scenario."""
    data = across_data(seed)
    return parse_scenario(data, data["name"])


def across_data(seed: int) -> dict:
    """"X lying across the shelf in front of T" as scenario YAML data, on paper_experiment_10's shelf (0.26 m of
    headroom: no grasp from above, and an axis this far from pointing in has no grasp along it): T standing at x
    0.82-0.90, y -0.15..0.15; X lying flat in front of it, its axis 0.85-1.55 rad from pointing into the shelf
    (either sign), its centre up to 40 mm off T's line and 5-15 mm from T; OTHERS bottles standing elsewhere, as
    lying_data (the closed-loop grid's remaining failures: a bottle tipped across every lane of T)."""
    rng = random.Random(f"push-across:{seed}")
    with open(config_file("scenarios/paper_experiment_10.yaml")) as f:
        data = yaml.safe_load(f)
    s = parse_scenario(data, "base").shelf
    tx, ty = rng.uniform(0.82, 0.90), rng.uniform(-0.15, 0.15)
    yaw = rng.choice((-1.0, 1.0)) * rng.uniform(0.85, 1.55)
    gap, dy = rng.uniform(0.005, 0.015), rng.uniform(-0.04, 0.04)
    return _lying_in_front(rng, data, s, f"push_across_s{seed}", (tx, ty), yaw, gap, dy)


def _lying_in_front(rng: random.Random, data: dict, s, name: str, t: tuple[float, float], yaw: float, gap: float,
                    dy: float) -> dict:
    """The scenario data `name`: T standing at `t`; X (a bottle of the default size) lying flat in front of it, its
    axis at `yaw`, its centre `dy` off T's line and moved towards the front until its rectangle is `gap` from T's
    circle; OTHERS bottles standing elsewhere (_add_others)."""
    tx, ty = t
    c, sn, half = math.cos(yaw), math.sin(yaw), 0.08
    d = 0.0
    while True:
        u, v = c * d - sn * dy, -sn * d - c * dy  # T's centre in X's frame (X at (tx - d, ty + dy))
        if math.hypot(max(abs(u) - half, 0.0), max(abs(v) - RADIUS, 0.0)) >= RADIUS + gap:
            break
        d += 0.001
    x = (tx - d, ty + dy)
    objs = [{"id": "T", "xy": [round(tx, 4), round(ty, 4)]},
            {"id": "X", "weight": 0.3, "xy": [round(x[0], 4), round(x[1], 4)], "lying": True,
             "yaw": round(math.remainder(yaw, math.pi), 4)}]
    _add_others(rng, s, {"T": (tx, ty), "X": x}, objs, half)
    out = copy.deepcopy(data)
    out["name"] = name
    out["objects"] = objs
    return out


def _add_others(rng: random.Random, s, pos: dict, objs: list, half: float) -> None:
    """OTHERS standing bottles drawn on the shelf `s`, each 3 cm clear of T, of every other one and of the lying X's
    reach (`half` its half length), appended to `objs` (ids o1, o2, ...)."""
    while len(pos) < OTHERS + 2:
        px, py = rng.uniform(s.x_front + 0.05, s.x_front + s.depth - 0.05), rng.uniform(-0.33, 0.33)
        near = [RADIUS if k != "X" else half + RADIUS for k in pos]
        if all(math.hypot(px - qx, py - qy) >= RADIUS + n + 0.03 for (qx, qy), n in zip(pos.values(), near)):
            pos[f"o{len(pos) - 1}"] = (px, py)
            objs.append({"id": f"o{len(pos) - 2}", "weight": 0.3, "xy": [round(px, 4), round(py, 4)]})


def diagonal_layout(seed: int) -> Scenario:
    """The layout of `seed` (diagonal_data) as a scenario."""
    data = diagonal_data(seed)
    return parse_scenario(data, data["name"])


def diagonal_data(seed: int) -> dict:
    """"X lying diagonally in front of T" as scenario YAML data, on paper_experiment_10's shelf: T standing at x
    0.82-0.88, y -0.10..0.10; X lying flat in front of it, its axis at yaw +-(0.5-1.0) rad (a side drawn from the
    seed: both a slide along its axis and a roll across it then go towards the back), its centre up to 30 mm off T's
    line and 5-15 mm from T; OTHERS bottles standing elsewhere, as lying_data."""
    rng = random.Random(f"push-diagonal:{seed}")
    with open(config_file("scenarios/paper_experiment_10.yaml")) as f:
        data = yaml.safe_load(f)
    s = parse_scenario(data, "base").shelf
    tx, ty = rng.uniform(0.82, 0.88), rng.uniform(-0.10, 0.10)
    yaw, gap, dy = rng.choice((-1.0, 1.0)) * rng.uniform(0.5, 1.0), rng.uniform(0.005, 0.015), rng.uniform(-0.03, 0.03)
    return _lying_in_front(rng, data, s, f"push_diagonal_s{seed}", (tx, ty), yaw, gap, dy)
