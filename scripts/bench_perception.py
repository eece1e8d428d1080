#!/usr/bin/env python3
"""Benchmark of the perception core (perception_aruco.pipeline) on frames rendered by the MuJoCo scene.

Prints, per scenario: bottles found / in the scenario, position error (median, max) against the scenario's ground
truth, marker (camera) pose error against the simulator's camera pose, and frames per second of
Perception.process on 640x480 (marker + segmentation + fits; rendering not included), wall clock and CPU time.
Optional: --arm-away renders with the arm folded out of the camera view (Q_UPRIGHT) instead of Q_HOME;
--objects N: generated layouts of N bottles on the default scene's shelf instead of the scenario files (seeds 0-4,
test/perception_scenes.py; colours repeat past the palette's 16);
--camera-model realsense_d435 renders through the driver's sensor model (5 frames of different noise, seeds 0-4,
processed in turn; errors: median over all of them, max the largest).
Usage: .venv/bin/python scripts/bench_perception.py [--repeats 20] [--scenarios a.yaml b.yaml] [--arm-away]
       [--camera-model ideal|realsense_d435] [--objects 30]
"""
from __future__ import annotations

import argparse
import math
import os
import sys
import time
from dataclasses import replace
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # as the perception node runs (perception_aruco/__init__.py)

import numpy as np  # noqa: E402  (after the BLAS thread setting, which must precede numpy)

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "test"))   # perception_scenes (generated layouts)
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from jaco2_sim_driver.camera import render_frame
from jaco2_sim_driver.sensor_model import CAMERA_MODELS, SensorModel
from perception_aruco.pipeline import Perception
from relocation_common.geometry import pose_error
from relocation_common.paths import default_scenario, scenarios_dir
from relocation_common.robot_description import Q_HOME, Q_UPRIGHT
from relocation_common.scenario import load_scenario


def bench(path, repeats: int, q, camera_model: str = "ideal", objects: int = 0, seed: int = 0) -> dict:
    """One scene (a scenario file, or with `objects` a generated layout of that many bottles, seeded)."""
    sensor = SensorModel.named(camera_model)
    n_frames = 1 if camera_model == "ideal" else 5
    if objects:
        from perception_scenes import generated_layout, render_scene, with_objects
        base = load_scenario(default_scenario())
        s = replace(with_objects(base, generated_layout(base, seed, objects, min_gap=0.012, radii=(0.02, 0.025, 0.03))),
                    name=f"generated_{objects}_seed{seed}")
        frames = [render_scene(s, q=q, sensor=sensor, seed=k)[0] for k in range(n_frames)]
    else:
        s = load_scenario(path)
        frames = [render_frame(s, q=q, sensor=sensor, seed=k) for k in range(n_frames)]
    p = Perception(s)
    results = [p.process(f.rgb, f.depth, f.K, q=q) for f in frames]  # also the warm-up
    t0, c0 = time.perf_counter(), time.process_time()
    for k in range(repeats):
        f = frames[k % len(frames)]
        p.process(f.rgb, f.depth, f.K, q=q)
    dt, dc = (time.perf_counter() - t0) / repeats, (time.process_time() - c0) / repeats
    err = [math.hypot(d.x - s.object(i).x, d.y - s.object(i).y) for r in results for i, d in r.detections.items()]
    pose = [pose_error(r.T_base_camera, f.T_base_camera) for r, f in zip(results, frames)]
    found = min(len(r.detections) for r in results)
    missing = sorted({i for r in results for i in r.missing})
    return dict(name=s.name, found=found, total=len(s.objects), missing=missing,
                med=np.median(err) * 1000, max=max(err) * 1000, marker_mm=max(e[0] for e in pose) * 1000,
                marker_deg=math.degrees(max(e[1] for e in pose)), fps=1.0 / dt, cpu_fps=1.0 / dc,
                size=f"{frames[0].width}x{frames[0].height}", ms=1000 * dc,
                unlisted=max(len(r.unlisted) for r in results))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=20)
    ap.add_argument("--scenarios", nargs="*", default=[str(default_scenario())] + [
        str(scenarios_dir() / f"blocking_{n}.yaml") for n in (5, 10, 15)])
    ap.add_argument("--arm-away", action="store_true", help="arm at Q_UPRIGHT instead of Q_HOME")
    ap.add_argument("--camera-model", choices=CAMERA_MODELS, default="ideal", help="the driver's sensor model")
    ap.add_argument("--objects", type=int, default=0, help="generated layouts of this many bottles (seeds 0-4)")
    a = ap.parse_args()
    q = Q_UPRIGHT if a.arm_away else Q_HOME
    print(f"perception bench: arm at {'Q_UPRIGHT' if a.arm_away else 'Q_HOME'}, camera {a.camera_model}, "
          f"{a.repeats} repeats per scene")
    print(f"{'scenario':22s} {'size':8s} {'found':>6s} {'err med':>8s} {'err max':>8s} {'camera pose':>15s} "
          f"{'fps':>6s} {'cpu fps':>7s} {'cpu ms':>6s} {'unlisted':>8s}  missing")
    runs = [(None, k) for k in range(5)] if a.objects else [(p, 0) for p in a.scenarios]
    for path, seed in runs:
        b = bench(path, a.repeats, q, a.camera_model, a.objects, seed)
        print(f"{b['name']:22s} {b['size']:8s} {b['found']:>3d}/{b['total']:<2d} {b['med']:6.2f}mm {b['max']:6.2f}mm "
              f"{b['marker_mm']:5.1f}mm {b['marker_deg']:4.2f}deg {b['fps']:6.1f} {b['cpu_fps']:7.1f} {b['ms']:6.0f} "
              f"{b['unlisted']:8d}  "
              f"{','.join(b['missing']) or '-'}")


if __name__ == "__main__":
    main()
