#!/usr/bin/env python3
"""Benchmark of the perception core (perception_aruco.pipeline) on frames rendered by the MuJoCo scene.

Prints, per scenario: bottles found / in the scenario, position error (median, max) against the scenario's ground
truth, marker (camera) pose error against the simulator's camera pose, and frames per second of
Perception.process on 640x480 (marker + segmentation + fits; rendering not included). Optional: --arm-away
renders with the arm folded out of the camera view (Q_UPRIGHT) instead of Q_HOME.
Usage: .venv/bin/python scripts/bench_perception.py [--repeats 20] [--scenarios a.yaml b.yaml] [--arm-away]
"""
from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from jaco2_sim_driver.camera import render_frame
from perception_aruco.aruco import pose_error
from perception_aruco.pipeline import Perception
from relocation_common.paths import default_scenario, scenarios_dir
from relocation_common.robot_description import Q_HOME, Q_UPRIGHT
from relocation_common.scenario import load_scenario


def bench(path, repeats: int, q) -> dict:
    s = load_scenario(path)
    f = render_frame(s, q=q)
    p = Perception(s)
    r = p.process(f.rgb, f.depth, f.K)  # warm-up
    t0 = time.perf_counter()
    for _ in range(repeats):
        r = p.process(f.rgb, f.depth, f.K)
    dt = (time.perf_counter() - t0) / repeats
    err = [math.hypot(d.x - s.object(i).x, d.y - s.object(i).y) for i, d in r.detections.items()]
    et, er = pose_error(r.T_base_camera, f.T_base_camera)
    return dict(name=s.name, found=len(r.detections), total=len(s.objects), missing=sorted(r.missing),
                med=np.median(err) * 1000, max=max(err) * 1000, marker_mm=et * 1000, marker_deg=math.degrees(er),
                fps=1.0 / dt, size=f"{f.width}x{f.height}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=20)
    ap.add_argument("--scenarios", nargs="*", default=[str(default_scenario())] + [
        str(scenarios_dir() / f"blocking_{n}.yaml") for n in (5, 10, 15)])
    ap.add_argument("--arm-away", action="store_true", help="arm at Q_UPRIGHT instead of Q_HOME")
    a = ap.parse_args()
    q = Q_UPRIGHT if a.arm_away else Q_HOME
    print(f"perception bench: arm at {'Q_UPRIGHT' if a.arm_away else 'Q_HOME'}, {a.repeats} repeats per frame")
    print(f"{'scenario':22s} {'size':8s} {'found':>6s} {'err med':>8s} {'err max':>8s} {'marker':>15s} {'fps':>6s}"
          "  missing")
    for path in a.scenarios:
        b = bench(path, a.repeats, q)
        print(f"{b['name']:22s} {b['size']:8s} {b['found']:>3d}/{b['total']:<2d} {b['med']:6.2f}mm {b['max']:6.2f}mm "
              f"{b['marker_mm']:5.1f}mm {b['marker_deg']:4.2f}deg {b['fps']:6.1f}  {','.join(b['missing']) or '-'}")


if __name__ == "__main__":
    main()
