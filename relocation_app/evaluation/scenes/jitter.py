"""Perturbed copies of a shipped scene (`python -m relocation_app.evaluation.scenes jitter SCENE [--amplitude 0.012]
[--seeds 0-3]`): every bottle moved by a seeded random amount of at most `amplitude` (hand-placed bottles on a real
shelf), kept JITTER_GAP apart and on the top shelf (docs/benchmarks.md, "Perturbed layouts"); written to out/jitter/.
"""
from __future__ import annotations

import copy
import math
import random
from pathlib import Path

import yaml

from relocation_app.evaluation.scenes.layout import made_by, write_scene
from relocation_common.scenario import parse_scenario

JITTER_GAP = 0.005  # m between bottle surfaces after a jitter (the scene's own gap if it was smaller)
JITTER_TRIES = 200  # draws per bottle before the whole layout is drawn again


def jitter_scene(data: dict, amplitude: float, seed: int) -> dict:
    """A copy of the scene `data` (as read from YAML) with every bottle moved by an offset drawn uniformly in the
    disc of radius `amplitude` (m), seeded by (scene name, amplitude in mm, seed) only; bottles stay on the top
    shelf and at least JITTER_GAP (or their original gap, if smaller) apart. Named `<name>_j<mm>_s<seed>`."""
    if not (isinstance(amplitude, (int, float)) and 0 < amplitude <= 0.05):
        raise ValueError(f"jitter amplitude must be in (0, 0.05] m, got {amplitude!r}")
    sc = parse_scenario(data, str(data.get("name", "scene")))
    mm = int(round(amplitude * 1000))
    name = f"{sc.name}_j{mm}_s{seed}"
    rng = random.Random(f"{sc.name}:{mm}:{seed}")
    s, objs = sc.shelf, sc.objects
    gap = {(a.id, b.id): min(JITTER_GAP, math.hypot(a.x - b.x, a.y - b.y) - a.radius - b.radius)
           for a in objs for b in objs if a.id < b.id}
    for _ in range(JITTER_TRIES):
        pos: dict[str, tuple[float, float]] = {}
        for b in objs:
            for _ in range(JITTER_TRIES):
                rho, th = amplitude * math.sqrt(rng.random()), rng.uniform(-math.pi, math.pi)
                x, y = b.x + rho * math.cos(th), b.y + rho * math.sin(th)
                on_shelf = (s.x_front + b.radius <= x <= s.x_back - b.radius
                            and s.y_min + b.radius <= y <= s.y_max - b.radius)
                if on_shelf and all(math.hypot(x - px, y - py) >= b.radius + sc.object(o).radius
                                    + gap[(min(b.id, o), max(b.id, o))] for o, (px, py) in pos.items()):
                    pos[b.id] = (round(x, 4), round(y, 4))
                    break
            else:
                break
        if len(pos) == len(objs):
            break
    else:
        raise RuntimeError(f"{sc.name}: no layout within {amplitude} m keeps the bottles apart")
    out = copy.deepcopy(data)
    for o in out["objects"]:
        o["xy"] = list(pos[o["id"]])
    out["name"] = name
    out["description"] = f"{sc.name} with every bottle moved by at most {mm} mm (scenes jitter, seed {seed})."
    return out


def make_jitter(scene: str, amplitude: float, seeds, out_dir: str | Path | None = None) -> list[Path]:
    """One perturbed copy of the shipped scene per seed (jitter_scene), as YAML files in `out_dir` (default
    out/jitter)."""
    from relocation_common.paths import resolve_scenario, share_dir
    path = resolve_scenario(scene)
    data = yaml.safe_load(Path(path).read_text())
    out = Path(out_dir) if out_dir else share_dir() / "out" / "jitter"
    header = (f"# Perturbed copy of {Path(path).name} ({made_by('jitter')}, {amplitude * 1000:.0f} mm). "
              "Format: docs/scenarios.md.")
    written = []
    for seed in seeds:
        d = jitter_scene(data, amplitude, seed)
        written.append(write_scene(d, out / f"{d['name']}.yaml", header))
    return written
