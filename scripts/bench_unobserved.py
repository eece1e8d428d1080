#!/usr/bin/env python3
"""Benchmark: how much of the planned motion passes through shelf space the camera never observed
(docs/perception.md, "Unobserved space"). Not a timed test.

Per layout (shipped scenes, and perturbed copies: `scenes jitter`, 12 mm, seeds fixed before any result): the
project's simulated camera renders the shelf with the arm at home (`--frames`, default confirm_frames); perception
(Perception.process through the node's SceneMemory, its own camera pose and shelf-corrected intrinsics) takes each
frame; `ObservedSpace` integrates it into a voxel map of the top compartment. The retrieval is solved by the blocker
A* with the real motion planner in-process (the scenario's listed objects plus the unlisted ones the node would have
published: what the planner would hold), and each relocation is planned (relocation.plan_relocation: pick, carry,
retreat, home), in order. Before each relocation new frames are rendered with the objects relocated so far gone
from the top shelf and integrated (the closed loop's view after each one).

Per motion: the voxels of the compartment swept by the arm's collision capsules (robot_description.CAPSULES, the
planner's envelope of the open hand) and, during the carry, the carried object (its primitive attached to the hand
as at the end of the pick), sampled every `--step` rad of the largest joint's motion. Of those, the NEVER OBSERVED
ones outside every object the planner holds on the top shelf (those are obstacles it already avoids): space the
planner took as free without anyone having seen it. Also counted: swept voxels inside an object the simulator
builds but the planner does not hold (a hidden, unlisted object: a contact the assumption hides).

    .venv/bin/python scripts/bench_unobserved.py                              # the default set below
    .venv/bin/python scripts/bench_unobserved.py --scenes paper_experiment_10 --jitter-seeds ""  # one scene
    .venv/bin/python scripts/bench_unobserved.py --out rows.jsonl             # resumable; --table rows.jsonl
    .venv/bin/python scripts/bench_unobserved.py --camera-model realsense_d435   # noisy depth, holes
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # as the perception node runs (perception_aruco/__init__.py)

import numpy as np  # noqa: E402  (after the BLAS thread setting)

ROOT = Path(__file__).resolve().parent.parent
sys.path[:0] = [str(ROOT), str(ROOT / "test")]   # this checkout first; perception_scenes (the tests' renderer)

SCENES = ("paper_experiment_10", "scenario1_5", "scenario2_10", "scenario3_15", "paper1_5", "paper2_10",
          "paper3_15", "world/hidden_unlisted_10", "world/paper_experiment_10_unlisted")
JITTERED = ("paper_experiment_10", "scenario2_10", "scenario3_15", "paper2_10")
PHASES = ("pick", "carry", "retreat", "home")
SAFETY_NET = 300.0  # s: the planner's wall-clock safety nets, far above its work budgets on a loaded machine


def samples(positions: np.ndarray, step: float) -> np.ndarray:
    """The rows of a joint path at which the largest joint has moved `step` rad since the last one (and the ends)."""
    q = np.asarray(positions, float)
    cum = np.concatenate([[0.0], np.cumsum(np.abs(np.diff(q, axis=0)).max(axis=1))])
    idx = np.searchsorted(cum, np.arange(0.0, cum[-1], step))
    return q[np.unique(np.r_[idx, len(q) - 1])]


def swept(space, positions: np.ndarray, step: float, carried=None) -> np.ndarray:
    """Bool over the map: the voxels the arm's capsules (and `carried`: (shape, dims, pose in the hand's frame))
    cover along the path."""
    from perception_aruco.objects.self_filter import arm_segments, link_frames
    from relocation_common.robot_description import LINK_NAMES
    out = np.zeros(space.shape, bool)
    for q in samples(positions, step):
        space.mark_capsules(out, arm_segments(q))
        if carried is not None:
            shape, dims, rel = carried
            space.mark_primitive(out, link_frames(q)[LINK_NAMES[-1]] @ rel, shape, dims)
    return out


def pose(o) -> np.ndarray:
    """4x4 pose of an object's primitive centre (base frame)."""
    t = np.eye(4)
    t[:3, :3], t[:3, 3] = o.rotation(), o.centre()
    return t


def objects_mask(space, objects) -> np.ndarray:
    """Bool over the map: inside any of these objects' primitives."""
    out = np.zeros(space.shape, bool)
    for o in objects:
        space.mark_primitive(out, pose(o), o.shape, o.size)
    return out


def look(perception, memory, space, scenario, gone: set[str], notes: list[str], sensor: str, frames: int,
         seed: int) -> dict:
    """Render the shelf without the `gone` objects (arm at home) `frames` times with the camera model `sensor` (seeds
    seed, seed + 1, ...), perceive each frame through the node's SceneMemory `memory` (an unlisted object is
    published once confirmed in confirm_frames frames) and integrate it; what the node would publish after the last
    one, by id (nothing new when every frame is refused, said in `notes`)."""
    from perception_scenes import render_scene

    from jaco2_sim_driver.sensor_model import SensorModel
    from perception_aruco.aruco import PerceptionError
    from perception_aruco.shelf import corrected_K
    from relocation_common.robot_description import Q_HOME
    shown = scenario.with_objects([o for o in scenario.objects if o.id not in gone])
    published: dict = {}
    for k in range(frames):
        frame, _ = render_scene(shown, sensor=SensorModel.named(sensor), seed=seed + k)
        try:
            r = perception.process(frame.rgb, frame.depth, frame.K, memory=memory, q=Q_HOME)
        except PerceptionError as e:
            notes.append(f"frame refused ({type(e).__name__}: {e}): not integrated")
            continue
        space.integrate(frame.depth, corrected_K(frame.K, r.shelf.intrinsics), r.T_base_camera)
        published = {o.id: o for o in memory.update(r.objects, r.uncounted)[0]}
    return published


def shelf_shadow(sim, voxel: float) -> np.ndarray:
    """Bool over the map: never observed even with the shelf empty (rendered without objects, the simulator's camera
    pose): under the ceiling board's edge, behind the marker plates, out of view. The rest of the never-observed
    space is behind objects."""
    from perception_scenes import render_scene

    from perception_aruco.observed_space import ObservedSpace
    space = ObservedSpace.top_compartment(sim.shelf, voxel)
    frame, _ = render_scene(dataclasses.replace(sim, objects=(), unlisted=(), _by_id={}))
    space.integrate(frame.depth, frame.K, frame.T_base_camera)
    return space.unobserved


def figure(space, scenario, path: str) -> None:
    """The never-observed share of each column seen from above (objects outlined) and of each row seen from the
    side, as a PNG."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    hi = space.lo + np.asarray(space.shape) * space.voxel
    fig, ax = plt.subplots(1, 2, figsize=(10, 4.2), gridspec_kw={"width_ratios": [1, 1.3]})
    u = space.unobserved
    im = ax[0].imshow(u.mean(axis=2).T, origin="lower", extent=(space.lo[0], hi[0], space.lo[1], hi[1]),
                      vmin=0, vmax=1, cmap="magma")
    for o in scenario.objects:
        ax[0].add_patch(plt.Circle((o.x, o.y), max(o.radius, 0.02), fill=False, color="c"))
    ax[0].set(title="from above (share of each column)", xlabel="x (m)", ylabel="y (m)")
    ax[1].imshow(u.mean(axis=1).T, origin="lower", extent=(space.lo[0], hi[0], space.lo[2], hi[2]), vmin=0, vmax=1,
                 cmap="magma", aspect="auto")
    ax[1].set(title="from the side (share of each row)", xlabel="x (m)", ylabel="z (m)")
    fig.colorbar(im, ax=ax, shrink=0.8)
    fig.suptitle(f"{scenario.name}, top compartment: never observed from the camera at home ({100 * u.mean():.0f} %)")
    fig.savefig(path, dpi=80)
    plt.close(fig)


def one(path: str, voxel: float, step: float, sensor: str, frames: int, picture: str | None = None) -> dict:
    """Solve, plan and measure one layout (module docstring); `picture`: the first frame's map drawn there."""
    from perception_aruco.objects.model import to_shelf_object
    from perception_aruco.objects.self_filter import link_frames
    from perception_aruco.observed_space import ObservedSpace
    from perception_aruco.pipeline import Perception, SceneMemory
    from qtree_task_planner.oracles import CachedOracle
    from qtree_task_planner.problem import RelocationProblem
    from qtree_task_planner.search import astar
    from relocation_common.config import node_section
    from relocation_common.paths import config_file
    from relocation_common.robot_description import LINK_NAMES
    from relocation_common.scenario import load_scenario
    from stpik_motion_planner.execution.relocation import plan_relocation
    from stpik_motion_planner.planning.params import PlannerParams
    from stpik_motion_planner.planning.planner import MotionPlanner
    from stpik_motion_planner.planning.results import PlanningError

    sim = load_scenario(path)
    space = ObservedSpace.top_compartment(sim.shelf, voxel)
    perception = Perception(sim)
    cfg = node_section(config_file("perception.yaml"), "perception")
    memory = SceneMemory(sim.ids, int(cfg["hold_frames"]), int(cfg["confirm_frames"]))
    frames = frames or int(cfg["confirm_frames"])
    notes: list[str] = []
    t0 = time.perf_counter()
    seen = look(perception, memory, space, sim, set(), notes, sensor, frames, 0)
    first_unobserved = float(space.unobserved.mean())
    if picture:
        figure(space, sim, picture)
    unlisted = [dataclasses.replace(to_shelf_object(o), weight=min(1.0, max(o.weight, 0.01)))
                for o in seen.values() if not o.listed]
    plan_scene = sim.with_objects(list(sim.objects) + unlisted)
    unseen_unlisted = [o for o in sim.unlisted if not any(np.hypot(o.x - u.x, o.y - u.y) < 0.05 for u in unlisted)]
    hidden = objects_mask(space, unseen_unlisted)
    shadow = shelf_shadow(sim, voxel)
    params = dataclasses.replace(PlannerParams.load(), timeout=SAFETY_NET, carry_timeout=SAFETY_NET)
    planner = MotionPlanner(plan_scene, params)
    result = astar.solve(RelocationProblem.from_scenario(plan_scene), CachedOracle(planner))
    row: dict[str, Any] = {"layout": sim.name, "camera": f"{sensor} x {frames}", "objects": len(plan_scene.objects),
           "unlisted_seen": len(unlisted), "hidden": len(unseen_unlisted), "found": bool(result.found),
           "sequence": list(result.sequence or ()), "first_unobserved": round(first_unobserved, 3), "motions": [],
           "notes": notes}
    if not result.found:
        row["notes"].append("no retrieval: " + (getattr(result, "reason", "") or "no sequence"))
        return row
    done: list[str] = []
    by_id = {o.id: o for o in plan_scene.objects}
    for oid in result.sequence or ():
        if done:
            look(perception, memory, space, sim, set(done), notes, sensor, frames, 100 * len(done))
        try:
            plan = plan_relocation(planner, oid, done)
        except PlanningError as e:
            row["notes"].append(f"{oid} not planned: {e}")
            break
        known = objects_mask(space, [o for o in plan_scene.objects if o.id not in done])
        unseen = space.unobserved & ~known
        o = by_id[oid]
        rel = np.linalg.inv(link_frames(plan.pick.positions[-1])[LINK_NAMES[-1]]) @ pose(o)
        for phase, traj in zip(PHASES, (plan.pick, plan.carry, plan.retreat, plan.home)):
            s = swept(space, traj.positions, step, (o.shape, o.size, rel) if phase == "carry" else None)
            row["motions"].append({"object": oid, "phase": phase, "swept": int(s.sum()),
                                   "unobserved": int((s & unseen).sum()),
                                   "behind_objects": int((s & unseen & ~shadow).sum()),
                                   "hidden": int((s & hidden).sum())})
        done.append(oid)
    row["last_unobserved"] = round(float(space.unobserved.mean()), 3)
    row["wall"] = round(time.perf_counter() - t0, 1)
    return row


def _rates(ms: list[dict]) -> str:
    """Motions through never-observed space, and through the part behind objects; their shares of the swept
    volume."""
    swept = max(1, sum(m["swept"] for m in ms))
    n, b = sum(bool(m["unobserved"]) for m in ms), sum(bool(m.get("behind_objects")) for m in ms)
    return (f"{n} ({100 * n / max(1, len(ms)):.0f} %) | {b} ({100 * b / max(1, len(ms)):.0f} %) | "
            f"{100 * sum(m['unobserved'] for m in ms) / swept:.1f} % | "
            f"{100 * sum(m.get('behind_objects', 0) for m in ms) / swept:.1f} %")


HEAD = ("motions in the compartment | through never-observed space | of them behind objects | never-observed share of "
        "the swept volume | behind objects")


def table(rows: list[dict], voxel: float) -> str:
    """One markdown row per layout, one per phase over them all, and the notes."""
    cm3 = voxel ** 3 * 1e6
    lines = [f"| layout | objects (unlisted seen / hidden) | relocations | compartment never observed (first / last "
             f"frame) | {HEAD} | largest in one motion (cm3) | through a hidden object |", "|---" * 11 + "|"]
    for r in rows:
        ms = [m for m in r["motions"] if m["swept"]]
        lines.append(f"| {r['layout']} | {r['objects']} ({r['unlisted_seen']} / {r['hidden']}) | "
                     f"{len(r['sequence']) if r['found'] else 'none'} | {100 * r['first_unobserved']:.0f} % / "
                     f"{100 * r.get('last_unobserved', r['first_unobserved']):.0f} % | {len(ms)} | {_rates(ms)} | "
                     f"{max((m['unobserved'] for m in ms), default=0) * cm3:.0f} | "
                     f"{sum(bool(m['hidden']) for m in ms)} |")
    lines += ["", f"| phase | {HEAD} |", "|---" * 6 + "|"]
    every = [m for r in rows for m in r["motions"] if m["swept"]]
    for phase in PHASES + ("all",):
        ms = [m for m in every if phase in (m["phase"], "all")]
        lines.append(f"| {phase} | {len(ms)} | {_rates(ms)} |")
    notes = [f"- {r['layout']}: {n}" for r in rows for n in r["notes"]]
    return "\n".join(lines + (["", "Notes:"] + notes if notes else []))


def layouts(scenes, jittered, seeds, amplitude: float, tmp: str) -> list[str]:
    """The scenario files: the shipped scenes, then the perturbed copies."""
    from relocation_app.evaluation.scenes.jitter import make_jitter
    from relocation_common.paths import resolve_scenario
    out = [str(resolve_scenario(s)) for s in scenes]
    for s in jittered:
        out += [str(p) for p in make_jitter(s, amplitude, seeds, tmp)]
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", nargs="*", default=list(SCENES))
    ap.add_argument("--jittered", nargs="*", default=list(JITTERED), help="scenes whose perturbed copies are run")
    ap.add_argument("--jitter-seeds", default="0,1", help="comma-separated (fixed before any result); '' = none")
    ap.add_argument("--amplitude", type=float, default=0.012, help="m: the jitter's largest move of a bottle")
    ap.add_argument("--voxel", type=float, default=0.01, help="m: the observed-space map's voxel side")
    ap.add_argument("--step", type=float, default=0.01, help="rad: the largest joint's motion between samples")
    ap.add_argument("--out", default=None, help="JSON lines, appended per layout; layouts in it are not run again")
    ap.add_argument("--camera-model", default="ideal", help="ideal or realsense_d435 (jaco2_sim_driver.sensor_model)")
    ap.add_argument("--frames", type=int, default=0, help="frames integrated per look (seeded 100 k + 0, 1, ...); "
                    "0: config/perception.yaml's confirm_frames (a new unlisted object is published after as many)")
    ap.add_argument("--figure", default=None, help="PNG: the first layout's map after its first frame")
    ap.add_argument("--table", default=None, help="print the table of an --out file and stop")
    a = ap.parse_args()
    if a.table:
        print(table([json.loads(x) for x in Path(a.table).read_text().splitlines() if x.strip()], a.voxel))
        return 0
    out = Path(a.out) if a.out else None
    rows = [json.loads(x) for x in out.read_text().splitlines() if x.strip()] if out and out.exists() else []
    seeds = [int(s) for s in a.jitter_seeds.split(",") if s.strip()]
    with tempfile.TemporaryDirectory() as tmp:
        for path in layouts(a.scenes, a.jittered if seeds else [], seeds, a.amplitude, tmp):
            if any(r.get("path") == Path(path).stem for r in rows):
                continue
            try:
                row = one(path, a.voxel, a.step, a.camera_model, a.frames, a.figure if not rows else None)
            except Exception as e:  # one layout's failure is a row with its reason, the others still run
                row = {"layout": Path(path).stem, "objects": 0, "unlisted_seen": 0, "hidden": 0, "found": False,
                       "sequence": [], "first_unobserved": 0.0, "motions": [], "notes": [f"crashed: {e!r}"]}
            row["path"] = Path(path).stem
            rows.append(row)
            print(json.dumps(row), flush=True)
            if out:
                with out.open("a") as f:
                    f.write(json.dumps(row) + "\n")
    print(table(rows, a.voxel))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
