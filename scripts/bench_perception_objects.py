#!/usr/bin/env python3
"""Generated benchmark of the geometry-first perception (docs/perception.md, "Objects"): shelves with N bottles (three
sizes; radius 2-3 cm above 20 bottles, 2.5-4 cm else; colours repeated past the palette), 0-3 objects the scenario
does not list (a bottle, a short wide jar, a box, a lying bottle), some listed bottles lying; rendered by the
project's simulated camera (ideal or realsense_d435, arm at Q_HOME, its joint state given); every frame scored
against the simulator's ground truth.

Per object with >= 300 pixels in view: found (listed: its id within 10 mm standing, 15 mm lying or box; unlisted:
an unlisted object there), covered (some published object's footprint holds its centre), or DROPPED (occupied
space published as free: silently wrong). Also: listed ids published > tolerance off (WRONG), frames refused,
frames/s and CPU time per frame of Perception.process. Seeds are fixed before any result (seed k = layout k).
Usage: .venv/bin/python scripts/bench_perception_objects.py [--sizes 5 10 15 20 30] [--seeds 5]
       [--camera-model ideal realsense_d435] [--frames K: score what the node publishes after K frames]
"""
from __future__ import annotations

import argparse
import math
import os
import sys
import time
from dataclasses import dataclass, replace
from pathlib import Path
from types import SimpleNamespace

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # as the perception node runs (perception_aruco/__init__.py)

import numpy as np  # noqa: E402  (after the BLAS thread setting, which must precede numpy)

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "test"))   # perception_scenes (generated layouts)
sys.path.insert(0, str(ROOT))

from perception_scenes import extra, generated_layout, reach, render_scene, with_objects  # noqa: E402  (the test helpers: after the sys.path insert)

from jaco2_sim_driver.sensor_model import SensorModel  # noqa: E402  (after the sys.path insert of the checkout)
from perception_aruco.aruco import PerceptionError  # noqa: E402 (after sys.path)
from perception_aruco.objects.model import BOX, CYLINDER  # noqa: E402 (after sys.path)
from perception_aruco.pipeline import Perception, SceneMemory  # noqa: E402 (after sys.path)
from relocation_common.config import node_section  # noqa: E402 (after sys.path)
from relocation_common.paths import config_file, default_scenario  # noqa: E402 (after sys.path)
from relocation_common.robot_description import Q_HOME  # noqa: E402 (after sys.path)
from relocation_common.scenario import PALETTE, Scenario, ShelfObject, load_scenario  # noqa: E402 (after sys.path)

VISIBLE = 300            # pixels in view at 640x480: the object must be found (test_perception.py's bound)
TOL, TOL_LYING = 0.010, 0.015


@dataclass(frozen=True)
class Case:
    """One generated frame: the scenario perception is given, the simulator's (its `unlisted`: the objects
    perception is not told about; a tipped listed bottle lying in `objects`), the truth of every object (id -> (x,
    y, lying or box)) and the ids of the unlisted ones."""

    given: Scenario
    sim: Scenario
    truth: dict[str, tuple[float, float, bool]]
    unlisted: frozenset[str]


def make_case(seed: int, n: int, n_unlisted: int, n_lying: int) -> Case:
    """A seeded layout (module docstring); the unlisted objects are x1, x2, ... in the simulator."""
    base = load_scenario(default_scenario())
    rng = np.random.default_rng([seed, n, 7])
    extras: list[ShelfObject] = []
    kinds = ["bottle", "jar", "box", "lying"]
    s = base.shelf
    colours = list(PALETTE)
    for k in range(n_unlisted + n_lying):
        kind = kinds[int(rng.integers(4))] if k < n_unlisted else "lying"
        c = colours[int(rng.integers(len(colours)))]
        size = {"bottle": (0.066, 0.066, 0.16), "jar": (0.09, 0.09, 0.09), "box": (0.06, 0.10, 0.14),
                "lying": (0.066, 0.066, 0.16)}[kind]
        for _ in range(500):
            x = float(rng.uniform(s.x_front + 0.1, s.x_back - 0.1))
            y = float(rng.uniform(s.y_min + 0.1, s.y_max - 0.1))
            e = extra(base, f"x{k + 1}" if k < n_unlisted else f"lie{k}", BOX if kind == "box" else CYLINDER, x, y,
                      size, float(rng.uniform(-math.pi, math.pi)), kind == "lying", PALETTE[c])
            if all(math.hypot(x - f.x, y - f.y) > reach(e) + reach(f) + 0.02 for f in extras):
                extras.append(e)
                break
    dense = n > 20  # 30 bottles of 3-4 cm radius do not fit the 0.8 x 0.36 m board: smaller ones, closer
    bottles = generated_layout(base, seed, n, min_gap=0.012 if dense else 0.015,
                               radii=(0.02, 0.025, 0.03) if dense else (0.025, 0.033, 0.04),
                               taken=[(e.x, e.y, reach(e) + 0.005) for e in extras])
    lying = [e for e in extras if e.lying]
    # a listed bottle lying: the scenario lists it standing where it fell from (its base at one end of the lying
    # one), the simulator has it on its side
    tipped = {b.id: replace(b, x=e.x, y=e.y, yaw=e.yaw, lying=True) for b, e in zip(bottles[1:], lying)}
    given = with_objects(base, [replace(b, x=t.x - b.height / 2 * math.cos(t.yaw), y=t.y - b.height / 2 *
                                        math.sin(t.yaw)) if (t := tipped.get(b.id)) else b for b in bottles])
    unlisted = [e for e in extras if not e.lying]
    sim = with_objects(base, [tipped.get(b.id, b) for b in bottles], unlisted)
    truth = {o.id: (o.x, o.y, o.lying or o.shape == BOX) for o in sim.world}
    return Case(given, sim, truth, frozenset(e.id for e in unlisted))


def score(case: Case, result, visible: dict[str, int]) -> dict:
    """Per visible object: found / covered / dropped; listed ids off (WRONG); the unlisted found."""
    out: dict = dict(found=0, covered=0, dropped=[], wrong=[], visible=0, unlisted_found=0, unlisted_visible=0)
    objs = list(result.objects.values())
    for i, o in result.objects.items():
        if o.listed and i in case.truth:
            tx, ty, lying = case.truth[i]
            if math.hypot(o.x - tx, o.y - ty) > (TOL_LYING if lying else TOL):
                out["wrong"].append(f"{i} {1000 * math.hypot(o.x - tx, o.y - ty):.0f} mm off")
    for i, (tx, ty, lying) in case.truth.items():
        if visible.get(i, 0) < VISIBLE:
            continue
        out["visible"] += 1
        tol = TOL_LYING if lying else TOL
        unl = i in case.unlisted
        out["unlisted_visible"] += unl
        if unl:
            ok = any(not o.listed and math.hypot(o.x - tx, o.y - ty) <= tol for o in objs)
            out["unlisted_found"] += ok
        else:
            o = result.objects.get(i)
            ok = o is not None and math.hypot(o.x - tx, o.y - ty) <= tol
        if ok:
            out["found"] += 1
        elif any(math.hypot(o.x - tx, o.y - ty) <= o.reach + 0.005 for o in objs):
            out["covered"] += 1
        else:
            out["dropped"].append(i)
    return out


def run_case(case: Case, sensor: str, seed: int, frames: int = 0) -> tuple[dict, float, float]:
    """(score, wall s, CPU s) of one frame: what Perception.process finds in it (frames 0), or what the node would
    publish after `frames` frames of the scene (sensor seeds seed, seed + 1000, ...) through its SceneMemory
    (config/perception.yaml's hold_frames, confirm_frames: a new unlisted object is published once confirmed)."""
    p = Perception(case.given)
    cfg = node_section(config_file("perception.yaml"), "perception")
    memory = SceneMemory(case.given.ids, int(cfg["hold_frames"]), int(cfg["confirm_frames"]))
    for k in range(max(frames, 1)):
        f, visible = render_scene(case.sim, sensor=SensorModel.named(sensor), seed=seed + 1000 * k)
        t0, c0 = time.perf_counter(), time.process_time()
        try:
            r = p.process(f.rgb, f.depth, f.K, memory=memory, q=Q_HOME)
        except PerceptionError as e:
            return dict(refused=str(e)), 0.0, 0.0
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        published = memory.update(r.objects, r.uncounted)[0]
    return score(case, r if not frames else SimpleNamespace(objects={o.id: o for o in published}), visible), wall, cpu


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", nargs="*", type=int, default=[5, 10, 15, 20, 30])
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--camera-model", nargs="*", default=["ideal", "realsense_d435"])
    ap.add_argument("--frames", type=int, default=0, help="score what the node publishes after this many frames of "
                    "each scene (its SceneMemory: unlisted objects confirmed over confirm_frames); 0: one frame's "
                    "objects as found")
    a = ap.parse_args()
    print("| camera | objects | frames | visible | found | covered | DROPPED | WRONG ids | unlisted found | refused | "
          "wall ms | CPU ms |\n|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    notes = []
    for cam in a.camera_model:
        for n in a.sizes:
            tot = dict(visible=0, found=0, covered=0, dropped=0, wrong=0, uf=0, uv=0, refused=0)
            wall, cpu = [], []
            for seed in range(a.seeds):
                case = make_case(seed, n, seed % 4, 1 if seed % 2 else 0)
                sc, w, c = run_case(case, cam, seed, a.frames)
                if "refused" in sc:
                    tot["refused"] += 1
                    notes.append(f"{cam} n={n} seed {seed}: refused: {sc['refused']}")
                    continue
                wall.append(w)
                cpu.append(c)
                for k, v in (("visible", sc["visible"]), ("found", sc["found"]), ("covered", sc["covered"]),
                             ("dropped", len(sc["dropped"])), ("wrong", len(sc["wrong"])),
                             ("uf", sc["unlisted_found"]), ("uv", sc["unlisted_visible"])):
                    tot[k] += v
                if sc["dropped"] or sc["wrong"]:
                    notes.append(f"{cam} n={n} seed {seed}: dropped {sc['dropped']}, wrong {sc['wrong']}")
            print(f"| {cam} | {n} | {a.seeds} | {tot['visible']} | {tot['found']} | {tot['covered']} | "
                  f"{tot['dropped']} | {tot['wrong']} | {tot['uf']}/{tot['uv']} | {tot['refused']} | "
                  f"{1000 * np.mean(wall) if wall else 0:.0f} | {1000 * np.mean(cpu) if cpu else 0:.0f} |")
    print("\n".join(notes))


if __name__ == "__main__":
    main()
