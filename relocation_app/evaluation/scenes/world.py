"""Scenes of the shelf as it is (`python -m relocation_app.evaluation.scenes world`): objects the scenario does not
list, boxes, a bottle lying from the start, 20 and 30 objects with colours repeating, two bottles of one colour, a
bottle hidden from the camera. For tests and benchmarks; written to config/scenarios/world/ (docs/scenarios.md).

Every layout is drawn by this generator from a seed: the objects of a scene's recipe (`RECIPES`: shapes and sizes)
at uniformly drawn free spots of the top shelf within the arm's reach (layout.X_FREE, Y_FREE, MAX_REACH), GAP apart,
the target at the back (as layout.free_scene puts it), weights uniform in [0.05, 0.95]; the hidden scene's unlisted
bottle at spots drawn just behind a listed one as the camera sees it (`behind`). For each scene the seeds are tried
in order from its own first seed (SEED0 + 100 k) until a layout meets the scene's definition (all the
objects fit; for `hidden_unlisted_10` the unlisted bottle shows no pixel to the camera with the arm at home while
every listed bottle does); the seed used is written in the file's header. Nothing is chosen by how a planner or
perception does on it.
"""
from __future__ import annotations

import copy
import math
import random
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import yaml

from relocation_app.evaluation.scenes.layout import MAX_REACH, SHELF, X_FREE, Y_FREE, made_by, write_scene
from relocation_common.paths import resolve_scenario
from relocation_common.scenario import PALETTE, ShelfObject, parse_scenario

DIR = "world"
SEED0 = 36000  # scene k's seeds start at SEED0 + 100 k
SEEDS_PER_SCENE = 100
GAP = 0.004  # m between two objects' footprints
DRAWS = 4000  # spots drawn per object before the layout is given up
MARKERS = {"marker": {"id": 7, "dictionary": "DICT_4X4_50", "size": 0.07, "position": [0.625, -0.345, 0.09],
                      "rpy": [1.5707963, 0.0, -1.5707963]},
           "markers": [{"id": 8, "dictionary": "DICT_4X4_50", "size": 0.07, "position": [0.625, 0.345, 0.09],
                        "rpy": [1.5707963, 0.0, -1.5707963]}]}  # paper_experiment_10's two markers
HIDDEN_MIN_PIXELS = 250  # a listed bottle this many pixels or more is visible (test_sim_core's bound)


@dataclass(frozen=True)
class Spec:
    """One object of a recipe: a cylinder (radius, height; lying or standing) or a box (size)."""

    shape: str = "cylinder"
    radius: float = 0.033
    height: float = 0.16
    size: tuple[float, float, float] = (0.0, 0.0, 0.0)
    lying: bool = False

    def entry(self) -> dict[str, Any]:
        """The keys of a scenario entry that give this shape (none for the default bottle)."""
        if self.shape == "box":
            return {"shape": "box", "size": list(self.size)}
        out: dict[str, Any] = {}
        if self.radius != 0.033:
            out["radius"] = self.radius
        if self.height != 0.16:
            out["height"] = self.height
        if self.lying:
            out["lying"] = True
        return out


BOTTLE = Spec()
SLIM = Spec(radius=0.028)
SMALL = Spec(radius=0.025, height=0.12)
TALL = Spec(radius=0.03, height=0.2)
JAR = Spec(radius=0.04, height=0.09)
LYING = Spec(lying=True)
BOX_A, BOX_B, BOX_C = Spec("box", size=(0.06, 0.09, 0.14)), Spec("box", size=(0.05, 0.05, 0.1)), \
    Spec("box", size=(0.08, 0.06, 0.18))
# name -> (obstacles, unlisted objects, description)
RECIPES: dict[str, tuple[tuple[Spec, ...], tuple[Spec, ...], str]] = {
    "shapes_box_10": ((BOTTLE,) * 5 + (SLIM, BOX_A, BOX_B, BOX_C), (),
                      "Nine obstacles, three of them boxes, and a bottle target at the back."),
    "lying_start_8": ((BOTTLE,) * 6 + (LYING,), (), "Seven obstacles, one bottle lying on its side from the start."),
    "crowd_20": ((BOTTLE,) * 6 + (SLIM,) * 4 + (SMALL,) * 3 + (TALL,) * 2 + (JAR,) * 2 + (BOX_A, BOX_B), (),
                 "Nineteen obstacles of mixed shapes and sizes (colours repeat after the palette's 16)."),
    "crowd_30": ((BOTTLE,) * 6 + (SLIM,) * 6 + (SMALL,) * 9 + (TALL,) * 2 + (JAR,) * 2 + (BOX_B,) * 3 + (BOX_A,), (),
                 "Twenty-nine obstacles of mixed shapes and sizes (colours repeat after the palette's 16)."),
    "same_colour_10": ((BOTTLE,) * 9, (), "Nine obstacles, two of them of one colour."),
    "hidden_unlisted_10": ((BOTTLE,) * 9, (SMALL,),
                           "Nine obstacles; one more bottle, unlisted, stands where the camera at home cannot see it."),
}
ORDER = ("paper_experiment_10_unlisted", *RECIPES)


def _object(spec: Spec, oid: str, x: float, y: float, yaw: float, top_z: float) -> ShelfObject:
    return ShelfObject(oid, "", (0.5, 0.5, 0.5), 0.5, x, y, 0.0 if spec.shape == "box" else spec.radius,
                       spec.height, False, spec.shape, spec.size, yaw if spec.shape == "box" or spec.lying else 0.0,
                       spec.lying, support_z=top_z)


def _fits(o: ShelfObject, placed: list[ShelfObject]) -> bool:
    """On the top shelf within the arm's reach, GAP from every placed object."""
    s = SHELF
    if abs(o.y) > Y_FREE or math.hypot(o.x, o.y) > MAX_REACH:
        return False
    if not o.footprint().inside(s["x_front"], s["x_front"] + s["depth"], -s["width"] / 2 + GAP, s["width"] / 2 - GAP):
        return False
    grown = o.footprint(GAP)
    return not any(grown.overlaps(p.footprint()) for p in placed)


def _place(rng: random.Random, spec: Spec, oid: str, placed: list[ShelfObject],
           draw: Callable[[], tuple[float, float]] | None = None) -> ShelfObject | None:
    """`spec` at the first of DRAWS uniformly drawn spots (x in X_FREE, |y| <= Y_FREE, any yaw) that fits."""
    for _ in range(DRAWS):
        x, y = draw() if draw is not None else (rng.uniform(*X_FREE), rng.uniform(-Y_FREE, Y_FREE))
        o = _object(spec, oid, round(x, 3), round(y, 3), round(rng.uniform(-math.pi / 2, math.pi / 2), 3),
                    SHELF["top_z"])
        if _fits(o, placed):
            placed.append(o)
            return o
    return None


def _entry(o: ShelfObject, spec: Spec, rng: random.Random, weighed: bool = True) -> dict[str, Any]:
    e: dict[str, Any] = {"id": o.id}
    if weighed:
        e["weight"] = round(rng.uniform(0.05, 0.95), 2)
    e["xy"] = [o.x, o.y]
    e.update(spec.entry())
    if spec.shape == "box" or spec.lying:
        e["yaw"] = o.yaw
    return e


def recipe_scene(name: str, seed: int) -> dict | None:
    """The scene `name` of RECIPES drawn with `seed` (module docstring), or None when its objects do not fit."""
    obstacles, unlisted, description = RECIPES[name]
    rng = random.Random(seed)
    target = _object(BOTTLE, "T", round(rng.uniform(0.87, 0.91), 3), round(rng.uniform(-0.1, 0.1), 3), 0.0,
                     SHELF["top_z"])
    placed = [target]
    order = sorted(range(len(obstacles)), key=lambda k: -max(obstacles[k].size[:2] + (2 * obstacles[k].radius,)))
    found: dict[int, ShelfObject] = {}
    for k in order:  # the widest first: a crowded shelf fills up with the small ones
        o = _place(rng, obstacles[k], f"o{k + 1}", placed)
        if o is None:
            return None
        found[k] = o
    objects = [_entry(found[k], obstacles[k], rng) for k in range(len(obstacles))]
    objects.append({"id": "T", "xy": [target.x, target.y]})
    data: dict[str, Any] = {"name": name, "description": f"{description} Drawn with seed {seed}.",
                            "shelf": dict(SHELF), "defaults": {"radius": 0.033, "height": 0.16},
                            **copy.deepcopy(MARKERS), "target": "T", "objects": objects, "slots": "auto"}
    if name == "same_colour_10":
        names = [c for c in PALETTE]
        twice = rng.choice(names)
        rest = iter(c for c in names if c != twice)
        pair = set(rng.sample(range(len(objects) - 1), 2))
        for k, e in enumerate(objects[:-1]):
            e["color"] = twice if k in pair else next(rest)
    extra = []
    listed = list(placed)
    for k, spec in enumerate(unlisted):
        o = _place(rng, spec, f"x{k + 1}", placed, behind(rng, listed, spec) if name == "hidden_unlisted_10" else None)
        if o is None:
            return None
        extra.append(_entry(o, spec, rng, weighed=False))
    if extra:
        data["unlisted"] = extra
    return data


def unlisted_in_the_way(seed: int) -> dict | None:
    """paper_experiment_10 and one unlisted bottle (radius 0.025-0.033, height 0.12 or 0.16) at a spot drawn
    uniformly in front of the target, within its approach lanes: x in [0.80, 0.90], |y - y_T| <= 0.12."""
    rng = random.Random(seed)
    data = yaml.safe_load(resolve_scenario("paper_experiment_10").read_text())
    sc = parse_scenario(data, "paper_experiment_10")
    t = sc.object(sc.target_id)
    spec = Spec(radius=rng.choice((0.025, 0.03, 0.033)), height=rng.choice((0.12, 0.16)))
    placed = list(sc.objects)
    o = _place(rng, spec, "x1", placed, lambda: (rng.uniform(0.80, 0.90), t.y + rng.uniform(-0.12, 0.12)))
    if o is None:
        return None
    data["name"] = "paper_experiment_10_unlisted"
    data["description"] = (f"paper_experiment_10 with one bottle the scenario does not list in front of the target "
                           f"(drawn with seed {seed}): only the simulator knows it.")
    data["unlisted"] = [{**_entry(o, spec, rng, weighed=False), "color": rng.choice(list(PALETTE))}]
    return data


def hidden(data: dict) -> bool:
    """The unlisted objects show no pixel to the driver's camera with the arm at home, and every listed one shows
    at least HIDDEN_MIN_PIXELS (jaco2_sim_driver.camera.visible_pixels)."""
    from jaco2_sim_driver.camera import visible_pixels
    sc = parse_scenario(data, data["name"])
    pixels = visible_pixels(sc)
    return all(pixels[o.id] == 0 for o in sc.unlisted) and all(pixels[o.id] >= HIDDEN_MIN_PIXELS
                                                                for o in sc.objects)


def behind(rng: random.Random, listed: list[ShelfObject], spec: Spec) -> Callable[[], tuple[float, float]]:
    """Spots drawn just behind a listed obstacle as the driver's camera sees it: along the horizontal direction from
    the camera to the obstacle, the two footprints GAP to GAP + 20 mm apart (where a hidden object would stand)."""
    from jaco2_sim_driver.params import CameraSpec
    from relocation_common.scenario import Shelf
    cam, _ = CameraSpec.configured().placed(Shelf(**SHELF))

    def draw() -> tuple[float, float]:
        o = rng.choice([p for p in listed if p.id != "T"])
        d = (o.x - cam[0], o.y - cam[1])
        n = math.hypot(*d)
        r = o.radius + spec.radius + GAP + rng.uniform(0.0, 0.02)
        return float(o.x + d[0] / n * r), float(o.y + d[1] / n * r)
    return draw


def make_world(out: Path, names: tuple[str, ...] = ORDER, log: Callable[[str], None] = print) -> list[Path]:
    """Write the scenes `names` (ORDER) into `out`: for each, the first seed from its own that gives a layout
    meeting its definition (module docstring). RuntimeError when none of SEEDS_PER_SCENE does."""
    written = []
    for name in names:
        k = ORDER.index(name)
        for seed in range(SEED0 + 100 * k, SEED0 + 100 * k + SEEDS_PER_SCENE):
            data = unlisted_in_the_way(seed) if k == 0 else recipe_scene(name, seed)
            if data is not None and (name != "hidden_unlisted_10" or hidden(data)):
                break
        else:
            raise RuntimeError(f"{name}: no layout in seeds {SEED0 + 100 * k}+{SEEDS_PER_SCENE}")
        header = (f"# Test and benchmark scene (docs/scenarios.md), made by {made_by('world')}\n"
                  f"# (relocation_app/evaluation/scenes/world.py): seed {seed}, the first from {SEED0 + 100 * k} whose "
                  f"layout fits{' and hides the unlisted bottle' if k == 6 else ''}. Format: docs/scenarios.md.")
        written.append(write_scene(data, out / f"{name}.yaml", header))
        log(f"{name}: seed {seed}")
    return written
