#!/usr/bin/env python3
"""Robustness benchmark of the perception core (perception_aruco.pipeline) on frames rendered by the MuJoCo scene,
perturbed as a real RGB-D camera and a real shelf perturb them (docs/perception.md, "Robustness").

Per scene (rendered once per resolution, arm at Q_HOME unless --arm-away) and per category x level (seeded):
marker pose in the scenario wrong by L cm and L deg; intrinsics (fx, fy off by L %, principal point by 2L px);
depth noise (L=1/3/5 mm at 0.75 m, growing with distance squared); depth holes; colour noise; white balance warm
and cool; exposure; blur; marker occlusion (a small object on the marker, a corner covered, a third covered); bottle
occlusion (a quarter / half / three quarters of one bottle covered by an object in front); resolution; and the
simulator's realistic sensor (camera_model realsense_d435, jaco2_sim_driver/sensor_model.py; level = seed); motion
blur (the arm arriving at its pose with joint speeds of 0.3 / 0.6 / 1.1 rad/s in a random direction, seen through a
20 ms colour exposure: CameraRenderer.motion_blurred).

Each case is scored against the scenario's ground truth as the node would publish it (a scene is published when
`process` raises no PerceptionError and the target is among the detections):
- ok: published, every required bottle (>= 300 pixels in view at 640x480, minus the covered one) within 10 mm,
  nothing wrong;
- incomplete: published, nothing wrong, some required bottle reported missing;
- refused: nothing published, with the reason;
- WRONG (silently wrong): published with a bottle > 10 mm off its true position or with another bottle's identity,
  or a required bottle neither found nor inside any published object (occupied space published as free).
Objects the scenario does not list (u1, ...) are counted (`unlisted`): here every such object is a bottle perception
could not name, or an occluder the case painted in front of the camera (bottle_occl, marker_occl).
Also printed: processing frames per second at 640x480 (clean frames; rendering not included).
Usage: .venv/bin/python scripts/bench_perception_robustness.py [--scenes a b] [--reps 1] [--cases-out FILE]
"""
from __future__ import annotations

import argparse
import math
import os
import sys
import time
from collections import defaultdict
from dataclasses import replace
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # as the perception node runs (perception_aruco/__init__.py)

import cv2  # noqa: E402  (after the BLAS thread setting, which must precede numpy)
import numpy as np  # noqa: E402  (after the BLAS thread setting, which must precede numpy)

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from jaco2_sim_driver import sensor_model as sm  # noqa: E402  (after the sys.path insert of the checkout)
from jaco2_sim_driver.camera import CameraRenderer, Frame, render_frame, visible_pixels  # noqa: E402  (after the sys.path insert of the checkout)
from jaco2_sim_driver.params import CameraSpec
from jaco2_sim_driver.scene import build_model  # noqa: E402  (after the sys.path insert of the checkout)
from perception_aruco.aruco import PerceptionError, marker_corners_3d, marker_in_base  # noqa: E402  (after the sys.path insert of the checkout)
from perception_aruco.pipeline import Perception  # noqa: E402  (after the sys.path insert of the checkout)
from relocation_common.geometry import matrix_rpy, rotvec_matrix, rpy_matrix  # noqa: E402  (after the sys.path insert of the checkout)
from relocation_common.paths import scenarios_dir  # noqa: E402  (after the sys.path insert of the checkout)
from relocation_common.robot_description import JOINT_NAMES, Q_HOME, Q_UPRIGHT  # noqa: E402  (after the sys.path insert of the checkout)
from relocation_common.scenario import Scenario, load_scenario  # noqa: E402  (after the sys.path insert of the checkout)

SCENES = ["paper_experiment_10", "blocking_5", "blocking_10", "blocking_15", "scenario2_10"]
TOL = 0.010  # m: a published bottle farther than this from its true position is wrong
VISIBLE_PIXELS = 300  # a bottle showing this many pixels at 640x480 (test_perception.py's bound) must be found
RESOLUTIONS = {1: (480, 360), 2: (424, 240), 3: (320, 240)}
OCCLUDER_RGB = (185, 150, 130)   # a hand / a tool: matches no bottle colour of the palette


def random_unit(rng: np.random.Generator) -> np.ndarray:
    v = rng.standard_normal(3)
    return v / np.linalg.norm(v)


def wrong_marker(s: Scenario, level: int, rng: np.random.Generator) -> Scenario:
    """The scenario with its marker pose L cm and L deg off (random directions): a hand-measured marker."""
    m = s.marker
    x, y, z = (float(v) for v in np.asarray(m.position) + 0.01 * level * random_unit(rng))
    rot = rotvec_matrix(math.radians(level) * random_unit(rng)) @ rpy_matrix(m.rpy)
    return replace(s, marker=replace(m, position=(x, y, z), rpy=matrix_rpy(rot)))


def project(K: np.ndarray, T_base_camera: np.ndarray, pts_base: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pixel (N x 2) and depth (N,) of base-frame points."""
    T = np.linalg.inv(T_base_camera)
    cam = pts_base @ T[:3, :3].T + T[:3, 3]
    return np.c_[K[0, 0] * cam[:, 0] / cam[:, 2] + K[0, 2], K[1, 1] * cam[:, 1] / cam[:, 2] + K[1, 2]], cam[:, 2]


def paint_occluder(f: Frame, poly_px: np.ndarray, gap: float = 0.03) -> Frame:
    """An object in front: the polygon gets the occluder's colour and a depth `gap` nearer than what it covers."""
    mask = np.zeros(f.depth.shape, np.uint8)
    cv2.fillPoly(mask, [np.round(poly_px).astype(np.int32)], 1)
    m = mask > 0
    rgb, depth = f.rgb.copy(), f.depth.copy()
    covered = depth[m & (depth > 0)]
    z = (float(covered.min()) if covered.size else 0.6) - gap
    rgb[m] = OCCLUDER_RGB
    depth[m] = z
    return replace(f, rgb=rgb, depth=depth)


def cover_marker(s: Scenario, f: Frame, level: int, rng: np.random.Generator) -> Frame:
    """Level 1: a 7 mm object on the marker (about 1 % of it); 2: one corner covered (6 % of its area); 3: the
    left third covered (two corners)."""
    h = s.marker.size / 2
    T = marker_in_base(s.marker)
    if level == 1:
        c = rng.uniform(-0.5, 0.5, 2) * h
        a = np.linspace(0, 2 * math.pi, 16, endpoint=False)
        local = np.c_[c[0] + 0.0035 * np.cos(a), c[1] + 0.0035 * np.sin(a), np.zeros_like(a)]
    else:
        corner = marker_corners_3d(s.marker.size)[int(rng.integers(4))] if level == 2 else np.array([-h, 0, 0])
        sx, sy = np.sign(corner[0]) or -1.0, np.sign(corner[1]) or 1.0
        w = 0.5 * h if level == 2 else 0.6 * h               # 0.25 or 0.3 of the side
        y_in = -sy * h * 1.6 if level == 3 else sy * (h - w)  # level 3: a bar over the full height
        x_in, x_out, y_out = sx * (h - w), sx * h * 1.6, sy * h * 1.6
        local = np.array([[x_in, y_in, 0], [x_out, y_in, 0], [x_out, y_out, 0], [x_in, y_out, 0]], float)
    px, _ = project(f.K, f.T_base_camera, local @ T[:3, :3].T + T[:3, 3])
    return paint_occluder(f, px)


def bottle_box(s: Scenario, f: Frame, bid: str) -> np.ndarray:
    """Pixel bounding box (u0, v0, u1, v1) of a bottle's cylinder (ground truth)."""
    b = s.object(bid)
    a = np.linspace(0, 2 * math.pi, 24, endpoint=False)
    zs = [s.shelf.top_z, s.shelf.top_z + b.height]  # scenario bottles stand on the top board
    pts = np.array([[b.x + b.radius * math.cos(t), b.y + b.radius * math.sin(t), z] for t in a for z in zs])
    px, _ = project(f.K, f.T_base_camera, pts)
    return np.r_[px.min(0), px.max(0)]


def cover_bottle(s: Scenario, f: Frame, level: int, bid: str) -> Frame:
    """The left quarter / half / three quarters (level 1/2/3) of bottle `bid` covered by an object in front."""
    u0, v0, u1, v1 = bottle_box(s, f, bid)
    ue = u0 + (u1 - u0) * 0.25 * level
    return paint_occluder(f, np.array([[u0 - 2, v0 - 2], [ue, v0 - 2], [ue, v1 + 2], [u0 - 2, v1 + 2]]), gap=0.04)


def perturb(cat: str, level: int, s: Scenario, f: Frame, rng: np.random.Generator, cover: str | None):
    """(scenario given to perception, K given to it, rgb, depth) of one case."""
    rgb, depth, K = f.rgb, f.depth, f.K.copy()
    if cat == "marker_pose":
        s = wrong_marker(s, level, rng)
    elif cat == "intrinsics":
        K[0, 0] *= 1 + 0.01 * level * rng.choice([-1, 1])
        K[1, 1] *= 1 + 0.01 * level * rng.choice([-1, 1])
        K[:2, 2] += 2 * level * random_unit(rng)[:2] / np.linalg.norm(random_unit(rng)[:2])
    elif cat == "depth_noise":
        depth = sm.depth_noise(depth, {1: 0.001, 2: 0.003, 3: 0.005}[level], rng)
    elif cat == "depth_holes":
        depth = sm.depth_holes(depth, {1: 0.02, 2: 0.05, 3: 0.10}[level], rng)
    elif cat == "colour_noise":
        rgb = sm.colour_noise(rgb, {1: 5.0, 2: 10.0, 3: 20.0}[level], rng)
    elif cat in ("wb_warm", "wb_cool"):
        rgb = sm.white_balance(rgb, sm.warm((1 if cat == "wb_warm" else -1) * 0.08 * level))
    elif cat == "exposure":
        rgb = sm.exposure(rgb, {1: 0.6, 2: 1.4, 3: 1.7}[level])
    elif cat == "blur":
        rgb = sm.blur(rgb, {1: 0.7, 2: 1.2, 3: 2.0}[level])
    elif cat == "marker_occl":
        g = cover_marker(s, f, level, rng)
        rgb, depth = g.rgb, g.depth
    elif cat == "bottle_occl":
        g = cover_bottle(s, f, level, cover or s.target_id)
        rgb, depth = g.rgb, g.depth
    elif cat not in ("resolution", "realsense_d435", "motion_blur"):
        raise ValueError(cat)
    return s, K, rgb, depth


CATEGORIES = ["marker_pose", "intrinsics", "depth_noise", "depth_holes", "colour_noise", "wb_warm", "wb_cool",
              "exposure", "blur", "marker_occl", "bottle_occl", "resolution", "realsense_d435", "motion_blur"]
ARM_SPEEDS = {1: 0.3, 2: 0.6, 3: 1.1}   # rad/s, the largest joint speed of a motion_blur case (Table 7: 0.81-1.11)


def render_moving(s: Scenario, q, qdot, exposure: float = 0.02) -> Frame:
    """The frame of the arm arriving at q with joint speeds qdot, through a camera exposing its colour image for
    `exposure` s (the sensor model's motion blur only)."""
    import mujoco
    model = build_model(s, CameraSpec.configured())
    data = mujoco.MjData(model)
    adr = [model.joint(j).qposadr[0] for j in JOINT_NAMES]
    r = CameraRenderer(model, 640, 480, sensor=sm.SensorModel(exposure_s=exposure))
    try:
        for t in (0.0, 0.1):   # the previous frame 0.1 s earlier gives the renderer the speeds
            data.qpos[adr], data.time = np.asarray(q) - (0.1 - t) * np.asarray(qdot), t
            mujoco.mj_forward(model, data)
            f = r.render(data)
        return f
    finally:
        r.close()


def score(truth: Scenario, given: Scenario, K, rgb, depth, required: set[str], prior=None, q=None) -> dict:
    """One case: outcome (ok / incomplete / refused / WRONG), errors of the required bottles, swaps, false ones.
    `prior`: the camera pose of earlier frames, as the node's frame fusion gives it (None: a first frame); q: the
    arm's joint angles (its body left out of the depth)."""
    try:
        r = Perception(given).process(rgb, depth, K, prior=prior, q=q)
    except PerceptionError as exc:
        return dict(outcome="refused", reason=str(exc), errors=[], swaps=0, false=0)
    if truth.target_id not in r.detections:
        return dict(outcome="refused", reason=f"target {truth.target_id} not seen: "
                    f"{r.missing.get(truth.target_id, '')}", errors=[], swaps=0, false=0)
    errors, swaps, false, wrong = [], 0, 0, []
    for i, d in r.detections.items():
        e = math.hypot(d.x - truth.object(i).x, d.y - truth.object(i).y)
        if e <= TOL:
            if i in required:
                errors.append(e)
            continue
        near = [b.id for b in truth.objects if b.id != i and math.hypot(d.x - b.x, d.y - b.y) <= TOL]
        swaps += bool(near)
        false += not near
        wrong.append(f"{i} {e * 1000:.0f}mm off" + (f" (at {near[0]})" if near else ""))
    missing = sorted(required - {i for i, d in r.detections.items()
                                 if math.hypot(d.x - truth.object(i).x, d.y - truth.object(i).y) <= TOL})
    dropped = [i for i in missing if not any(math.hypot(o.x - truth.object(i).x, o.y - truth.object(i).y)
                                             <= o.reach + 0.005 for o in r.objects.values())]
    wrong += [f"{i} dropped (no published object there)" for i in dropped]
    outcome = "WRONG" if wrong else "incomplete" if missing else "ok"
    reason = ", ".join(wrong) if wrong else ("missing " + ", ".join(f"{i}: {r.missing.get(i, '?')}"
                                                                      for i in missing) if missing else "")
    return dict(outcome=outcome, reason=reason, errors=errors, swaps=swaps, false=false, unlisted=len(r.unlisted))



def fps(scenes: list[tuple[Scenario, Frame]], q, repeats: int = 5) -> tuple[float, float]:
    """Frames per second of Perception.process: (wall clock, CPU time of this process). On a shared machine the
    CPU-time figure is what one free core gives."""
    n, t, c = 0, 0.0, 0.0
    for s, f in scenes:
        p = Perception(s)
        p.process(f.rgb, f.depth, f.K, q=q)
        t0, c0 = time.perf_counter(), time.process_time()
        for _ in range(repeats):
            p.process(f.rgb, f.depth, f.K, q=q)
        t += time.perf_counter() - t0
        c += time.process_time() - c0
        n += repeats
    return n / t, n / c


def run(scene_names, reps: int, q, seed: int, out, categories=tuple(CATEGORIES), prior: bool = False) \
        -> tuple[list[dict], list[tuple[Scenario, Frame]]]:
    """All cases of the scenes x categories x levels x reps (module docstring)."""
    cases = []
    rendered = []
    for name in scene_names:
        s = load_scenario(scenarios_dir() / f"{name}.yaml")
        f = render_frame(s, q=q)
        rendered.append((s, f))
        required = {i for i, n in visible_pixels(s, q).items() if n >= VISIBLE_PIXELS}
        fused = Perception(s).process(f.rgb, f.depth, f.K, q=q).T_base_camera if prior else None
        low = {lv: render_frame(s, q=q, camera=replace(CameraSpec.configured(), width=w, height=h))
               for lv, (w, h) in RESOLUTIONS.items()}
        for ci, cat in enumerate(CATEGORIES):
            if cat not in categories:
                continue
            for level in (1, 2, 3):
                for rep in range(reps):
                    rng = np.random.default_rng([seed, SCENES.index(name) if name in SCENES else 99, ci, level, rep])
                    cover = sorted(required)[int(rng.integers(len(required)))] if required else None
                    g = low[level] if cat == "resolution" else f
                    if cat == "realsense_d435":  # the simulator's realistic sensor, seeded by the level
                        g = render_frame(s, q=q, sensor=sm.SensorModel.named(cat), seed=level + 100 * rep)
                    if cat == "motion_blur":
                        d = rng.normal(size=len(JOINT_NAMES))
                        g = render_moving(s, q, ARM_SPEEDS[level] * d / np.max(np.abs(d)))
                    given, K, rgb, depth = perturb(cat, level, s, g, rng, cover)
                    req = required - {cover} if cat == "bottle_occl" else required
                    c = score(s, given, K, rgb, depth, req, fused if cat != "resolution" else None, q)
                    c.update(scene=name, cat=cat, level=level, rep=rep)
                    cases.append(c)
                    if out:
                        out.write(f"{name} {cat} L{level} r{rep}: {c['outcome']} {c['reason']}\n")
    return cases, rendered


def table(cases: list[dict]) -> list[str]:
    """Markdown rows per category x level and the totals."""
    rows = ["| category | level | cases | ok | incomplete | refused | WRONG | err med mm | err max mm | swaps | "
            "false | unlisted |",
            "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    groups: dict = defaultdict(list)
    for c in cases:
        groups[(c["cat"], c["level"])].append(c)
    for cat in CATEGORIES:
        for level in (1, 2, 3):
            if groups[(cat, level)]:
                rows.append(_row(f"{cat}", str(level), groups[(cat, level)]))
    rows.append(_row("**all**", "", cases))
    return rows


def category_summary(cases: list[dict]) -> str:
    """One line: ok / cases and silently wrong per category."""
    out = []
    for cat in CATEGORIES:
        cs = [c for c in cases if c["cat"] == cat]
        if cs:
            ok = sum(c["outcome"] == "ok" for c in cs)
            out.append(f"{cat} {ok}/{len(cs)} ok, {sum(c['outcome'] == 'WRONG' for c in cs)} wrong")
    return "; ".join(out)


def _row(cat: str, level: str, cs: list[dict]) -> str:
    n = len(cs)
    k = {o: sum(c["outcome"] == o for c in cs) for o in ("ok", "incomplete", "refused", "WRONG")}
    err = [e * 1000 for c in cs for e in c["errors"]]
    med = f"{np.median(err):.1f}" if err else "-"
    mx = f"{max(err):.1f}" if err else "-"
    return (f"| {cat} | {level} | {n} | {k['ok']} ({100 * k['ok'] / max(n, 1):.0f} %) | {k['incomplete']} | "
            f"{k['refused']} | {k['WRONG']} | {med} | {mx} | {sum(c['swaps'] for c in cs)} | "
            f"{sum(c['false'] for c in cs)} | {sum(c.get('unlisted', 0) for c in cs)} |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", nargs="*", default=SCENES)
    ap.add_argument("--reps", type=int, default=1, help="seeded repetitions of each category x level")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--arm-away", action="store_true", help="arm at Q_UPRIGHT instead of Q_HOME")
    ap.add_argument("--cases-out", help="write one line per case (outcome and reason) to this file")
    ap.add_argument("--categories", nargs="*", default=CATEGORIES, choices=CATEGORIES)
    ap.add_argument("--prior", action="store_true", help="give each case the camera pose of the clean frame, as the "
                    "node's frame fusion does after its first frames")
    a = ap.parse_args()
    out = open(a.cases_out, "w") if a.cases_out else None
    t0 = time.time()
    q = Q_UPRIGHT if a.arm_away else Q_HOME
    cases, rendered = run(a.scenes, a.reps, q, a.seed, out, tuple(a.categories), a.prior)
    if out:
        out.close()
    print(f"perception robustness: {len(a.scenes)} scenes ({', '.join(a.scenes)}), arm at "
          f"{'Q_UPRIGHT' if a.arm_away else 'Q_HOME'}, seed {a.seed}, {a.reps} rep(s), {len(cases)} cases, "
          f"{'with the fused pose of earlier frames, ' if a.prior else ''}"
          f"{time.time() - t0:.0f} s")
    print("\n".join(table(cases)))
    ok = sum(c["outcome"] == "ok" for c in cases)
    wrong = [c for c in cases if c["outcome"] == "WRONG"]
    print(f"\nok {ok}/{len(cases)} ({100 * ok / len(cases):.1f} %), silently wrong {len(wrong)}, refused "
          f"{sum(c['outcome'] == 'refused' for c in cases)}")
    print("per category: " + category_summary(cases))
    for c in wrong:
        print(f"  WRONG {c['scene']} {c['cat']} L{c['level']}: {c['reason']}")
    wall, cpu = fps(rendered, q)
    print(f"processing at 640x480: {wall:.1f} frames/s wall clock, {cpu:.1f} frames/s of CPU time (clean frames, "
          f"rendering not included; load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores)")


if __name__ == "__main__":
    main()
