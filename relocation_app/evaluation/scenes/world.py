"""Scenes of the shelf as it is (`python -m relocation_app.evaluation.scenes world`): objects the scenario does not
list, boxes, a bottle lying from the start, 20 and 30 objects with colours repeating, two bottles of one colour, a
bottle hidden from the camera. For tests, benchmarks and the demo; written to config/scenarios/world/
(docs/scenarios.md).

Every layout is drawn by this generator from a seed: the objects of a scene's recipe (`RECIPES`: shapes and sizes)
either at uniformly drawn free spots of the top shelf within the arm's reach (placing.uniform_layout, GAP apart, the
target at the back as layout.free_scene puts it) or, for the crowded scenes, stocked in columns (placing.stocked),
weights uniform in [0.05, 0.95]; the hidden scene's unlisted bottle at spots drawn just behind a listed one as the
camera sees it (`behind`). For each scene the seeds are tried in order from its own first seed (SEED0 + 100 k; a
columns layout with 0, then 1, then 2 spare columns, SPARES, each over SEEDS_PER_SCENE seeds) until
a layout meets the scene's definition: all the objects fit; for `hidden_unlisted_10` the unlisted bottle shows no
pixel to the camera with the arm at home while every listed bottle does (admission.hidden); for the scenes of
`RETRIEVABLE_SCENES` (crowd_20, crowd_30: the demo's 20- and 30-object scenes) the target is retrievable, proven by
the exact blocker A* with the real motion planner (admission.judge). The seed kept and the rule are written in the
file's header; the seeds refused, with their reasons, are printed. Nothing is chosen by how a demo does on it.
"""
from __future__ import annotations

import copy
import math
import random
import textwrap
from pathlib import Path
from typing import Any, Callable

import yaml

from relocation_app.evaluation.scenes.admission import RETRIEVABLE, Purpose, hidden, judge
from relocation_app.evaluation.scenes.layout import SHELF, made_by, write_scene
from relocation_app.evaluation.scenes.placing import (
    BOTTLE,
    BOX_A,
    BOX_B,
    BOX_C,
    GAP,
    JAR,
    LYING,
    MARKERS,
    SLIM,
    SMALL,
    TALL,
    Spec,
    entry,
    place_uniform,
    stocked,
    uniform_layout,
)
from relocation_common.paths import resolve_scenario
from relocation_common.scenario import PALETTE, ShelfObject, parse_scenario

DIR = "world"
SEED0 = 36000  # scene k's seeds start at SEED0 + 100 k
SEEDS_PER_SCENE = 100
SPARES = (0, 1, 2)  # spare columns of a columns layout, tried in turn (each over the scene's seeds)

# name -> (obstacles, unlisted objects, description, layout: "uniform" or "columns")
RECIPES: dict[str, tuple[tuple[Spec, ...], tuple[Spec, ...], str, str]] = {
    "shapes_box_10": ((BOTTLE,) * 5 + (SLIM, BOX_A, BOX_B, BOX_C), (),
                      "Nine obstacles, three of them boxes, and a bottle target at the back.", "uniform"),
    "lying_start_8": ((BOTTLE,) * 6 + (LYING,), (), "Seven obstacles, one bottle lying on its side from the start.",
                      "uniform"),
    "crowd_20": ((BOTTLE,) * 6 + (SLIM,) * 4 + (SMALL,) * 3 + (TALL,) * 2 + (JAR,) * 2 + (BOX_A, BOX_B), (),
                 "Nineteen obstacles of mixed shapes and sizes (colours repeat after the palette's 16), stocked in "
                 "columns.", "columns"),
    "crowd_30": ((BOTTLE,) * 6 + (SLIM,) * 6 + (SMALL,) * 9 + (TALL,) * 2 + (JAR,) * 2 + (BOX_B,) * 3 + (BOX_A,), (),
                 "Twenty-nine obstacles of mixed shapes and sizes (colours repeat after the palette's 16), stocked in "
                 "columns.", "columns"),
    "same_colour_10": ((BOTTLE,) * 9, (), "Nine obstacles, two of them of one colour.", "uniform"),
    "hidden_unlisted_10": ((BOTTLE,) * 9, (SMALL,),
                           "Nine obstacles; one more bottle, unlisted, stands where the camera at home cannot see it.",
                           "uniform"),
}
ORDER = ("paper_experiment_10_unlisted", *RECIPES)
RETRIEVABLE_SCENES = {name: Purpose(f"{n} objects of mixed shapes, colours repeating; {RETRIEVABLE}", False, False)
                      for name, n in (("crowd_20", 20), ("crowd_30", 30))}


def recipe_scene(name: str, seed: int, spare: int = 0) -> dict | None:
    """The scene `name` of RECIPES drawn with `seed` (module docstring; `spare`: the columns beyond the fewest, for
    the columns layout), or None when its objects do not fit."""
    obstacles, unlisted, description, layout = RECIPES[name]
    rng = random.Random(seed)
    specs, ids = (BOTTLE,) + obstacles, ["T"] + [f"o{k + 1}" for k in range(len(obstacles))]
    got = stocked(rng, specs, ids, spare) if layout == "columns" else uniform_layout(rng, specs, ids)
    if got is None:
        return None
    target, placed = got[0], list(got)
    objects = [entry(o, spec, rng) for o, spec in zip(got[1:], obstacles)]
    objects.append({"id": "T", "xy": [target.x, target.y]})
    data: dict[str, Any] = {"name": name, "description": f"{description} Drawn with seed {seed}{spared(spare)}.",
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
        o = place_uniform(rng, spec, f"x{k + 1}", placed,
                          behind(rng, listed, spec) if name == "hidden_unlisted_10" else None)
        if o is None:
            return None
        extra.append(entry(o, spec, rng, weighed=False))
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
    o = place_uniform(rng, spec, "x1", placed, lambda: (rng.uniform(0.80, 0.90), t.y + rng.uniform(-0.12, 0.12)))
    if o is None:
        return None
    data["name"] = "paper_experiment_10_unlisted"
    data["description"] = (f"paper_experiment_10 with one bottle the scenario does not list in front of the target "
                           f"(drawn with seed {seed}): only the simulator knows it.")
    data["unlisted"] = [{**entry(o, spec, rng, weighed=False), "color": rng.choice(list(PALETTE))}]
    return data


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


def admitted(name: str, seed: int, spare: int, log: Callable[[str], None]) -> dict | None:
    """The scene `name` drawn with `seed` (and `spare`, recipe_scene) when it meets the scene's definition (module
    docstring), else None, the reason logged."""
    data = unlisted_in_the_way(seed) if name == ORDER[0] else recipe_scene(name, seed, spare)
    if data is None:
        log(f"{name} seed {seed}{spared(spare)}: refused (fit): the objects do not fit")
        return None
    if name == "hidden_unlisted_10":
        why = hidden(data)
        if why:
            log(f"{name} seed {seed}: refused (hidden): {why}")
            return None
    if name in RETRIEVABLE_SCENES:
        from relocation_app.evaluation.feasibility_cache import planner_params
        v = judge(data, RETRIEVABLE_SCENES[name], planner_params())
        said = (f"admitted, optimum {' '.join(v.sequence or ())} ({v.weight:.2f}), {v.planner_calls} planner calls"
                if v.admitted else f"refused ({v.stage}): {v.reason[:300]}")
        log(f"{name} seed {seed}{spared(spare)}: {said} ({v.seconds:.0f} s)")
        if not v.admitted:
            return None
    return data


def spared(spare: int) -> str:
    """', N spare columns' for the log and the header (nothing for none)."""
    return f", {spare} spare column{'s' * (spare > 1)}" if spare else ""


def header(name: str, seed: int, spare: int, first: int) -> str:
    """The scene file's header: who made it, the seed kept and the rule that admitted it."""
    made = f"# Test and benchmark scene (docs/scenarios.md), made by {made_by('world')}\n"
    if name in RETRIEVABLE_SCENES:
        rule = (f"(relocation_app/evaluation/scenes/world.py): seed {seed}{spared(spare)}, the first (spare columns "
                f"{', '.join(map(str, SPARES))} in turn, each over seeds {first}+{SEEDS_PER_SCENE}) whose layout fits "
                f"and meets its purpose (admission.py): {RETRIEVABLE_SCENES[name].text}. Format: docs/scenarios.md.")
        return made + "\n".join("# " + line for line in textwrap.wrap(rule, 116))
    hides = " and hides the unlisted bottle" if name == "hidden_unlisted_10" else ""
    return (made + f"# (relocation_app/evaluation/scenes/world.py): seed {seed}, the first from {first} whose "
            f"layout fits{hides}. Format: docs/scenarios.md.")


def make_world(out: Path, names: tuple[str, ...] = ORDER, log: Callable[[str], None] = print) -> list[Path]:
    """Write the scenes `names` (ORDER) into `out`: for each, the first seed from its own that gives a layout
    meeting its definition (module docstring); a columns layout tries the seeds with each of SPARES spare columns
    in turn. RuntimeError when none does."""
    written = []
    for name in names:
        first = SEED0 + 100 * ORDER.index(name)
        data = None
        for spare in SPARES if RECIPES.get(name, ((), (), "", ""))[3] == "columns" else (0,):
            for seed in range(first, first + SEEDS_PER_SCENE):
                data = admitted(name, seed, spare, log)
                if data is not None:
                    break
            if data is not None:
                break
        if data is None:
            raise RuntimeError(f"{name}: no layout in seeds {first}+{SEEDS_PER_SCENE}")
        written.append(write_scene(data, out / f"{name}.yaml", header(name, seed, spare, first)))
        log(f"{name}: seed {seed}{spared(spare)}")
    return written
