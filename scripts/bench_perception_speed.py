#!/usr/bin/env python3
"""Perception.process of two checkouts side by side: the same rendered frames of the generated benchmark
(scripts/bench_perception_objects.py's cases: sizes, cameras, seeds), each processed by both in one run, the two
alternating frame by frame in two worker processes (these 2-core machines are shared: a ratio measured together,
never a timed test). Prints the CPU time per frame of each (median and mean over `--rounds` passes of the
`--time-sizes` frames) and every difference between their outputs (ids, shapes, poses beyond `--tol`, reasons).
Usage: .venv/bin/python scripts/bench_perception_speed.py --old /tmp/old-checkout [--new .] [--sizes 5 10 15 20 30]
       [--seeds 5] [--camera-model ideal realsense_d435] [--time-sizes 30] [--time-camera realsense_d435] [--rounds 3]
"""
from __future__ import annotations

import argparse
import dataclasses
import math
import os
import pickle
import subprocess
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # as the perception node runs (perception_aruco/__init__.py)

import numpy as np  # noqa: E402  (after the BLAS thread setting, which must precede numpy)

ROOT = Path(__file__).resolve().parent.parent


def summary(result) -> dict:
    """What a frame's result says, as plain values: objects (id -> fields), missing (id -> reason), uncounted."""
    objs = {i: dataclasses.asdict(o) for i, o in result.objects.items()}
    return dict(objects=objs, missing=dict(result.missing), uncounted=sorted(result.uncounted))


def worker(root: str, frames_file: str) -> None:
    """Serve frame indices from stdin: process that frame with the checkout at `root`, answer (CPU s, summary)."""
    sys.path.insert(0, root)
    from perception_aruco.aruco import PerceptionError
    from perception_aruco.pipeline import Perception, SceneMemory
    from relocation_common.config import node_section
    from relocation_common.paths import config_file
    from relocation_common.robot_description import Q_HOME
    assert Path(str(sys.modules["perception_aruco"].__file__)).resolve().is_relative_to(Path(root).resolve())
    with open(frames_file, "rb") as fh:
        frames = pickle.load(fh)
    cfg = node_section(config_file("perception.yaml"), "perception")
    perceptions: dict[int, Perception] = {}
    for line in sys.stdin:
        k = int(line)
        given, rgb, depth, K = frames[k]
        if k not in perceptions:
            perceptions[k] = Perception(given)
        p = perceptions[k]
        memory = SceneMemory(given.ids, int(cfg["hold_frames"]), int(cfg["confirm_frames"]))
        c0 = time.process_time()
        try:
            out: object = summary(p.process(rgb, depth, K, memory=memory, q=Q_HOME))
        except PerceptionError as e:
            out = dict(refused=str(e))
        cpu = time.process_time() - c0
        data = pickle.dumps((cpu, out))
        sys.stdout.buffer.write(len(data).to_bytes(8, "little") + data)
        sys.stdout.buffer.flush()


def differences(a: dict, b: dict, tol: float) -> list[str]:
    """Where summary b differs from a: other ids, fields, reasons; floats beyond tol."""
    if "refused" in a or "refused" in b:
        return [] if a == b else [f"refused: {a.get('refused')!r} vs {b.get('refused')!r}"]
    out = []
    if a["objects"].keys() != b["objects"].keys():
        out.append(f"ids {sorted(a['objects'])} vs {sorted(b['objects'])}")
    for i in a["objects"].keys() & b["objects"].keys():
        for k, va in a["objects"][i].items():
            vb = b["objects"][i][k]
            if isinstance(va, (float, tuple)):
                if not np.allclose(np.asarray(va, float), np.asarray(vb, float), rtol=0, atol=tol):
                    out.append(f"{i}.{k}: {va} vs {vb}")
            elif va != vb:
                out.append(f"{i}.{k}: {va!r} vs {vb!r}")
    if a["missing"] != b["missing"]:
        out.append(f"missing {a['missing']} vs {b['missing']}")
    if a["uncounted"] != b["uncounted"]:
        out.append(f"uncounted {a['uncounted']} vs {b['uncounted']}")
    return out


class Worker:
    """A worker process of one checkout."""

    def __init__(self, root: str, frames_file: str):
        self.proc = subprocess.Popen([sys.executable, __file__, "--worker", root, "--frames-file", frames_file],
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE, cwd=root)

    def run(self, k: int) -> tuple[float, dict]:
        assert self.proc.stdin is not None and self.proc.stdout is not None
        self.proc.stdin.write(f"{k}\n".encode())
        self.proc.stdin.flush()
        n = int.from_bytes(self.proc.stdout.read(8), "little")
        return pickle.loads(self.proc.stdout.read(n))

    def close(self) -> None:
        assert self.proc.stdin is not None
        self.proc.stdin.close()
        self.proc.wait(timeout=60)


def render(sizes: list[int], seeds: int, cameras: list[str]) -> tuple[list, list[tuple[str, int, int]]]:
    """The generated benchmark's frames (bench_perception_objects.make_case, its seeds and sensor seeds)."""
    sys.path.insert(0, str(ROOT / "test"))
    sys.path.insert(0, str(ROOT / "scripts"))
    sys.path.insert(0, str(ROOT))
    from bench_perception_objects import make_case
    from perception_scenes import render_scene

    from jaco2_sim_driver.sensor_model import SensorModel
    frames, names = [], []
    for cam in cameras:
        for n in sizes:
            for seed in range(seeds):
                case = make_case(seed, n, seed % 4, 1 if seed % 2 else 0)
                f, _ = render_scene(case.sim, sensor=SensorModel.named(cam), seed=seed)
                frames.append((case.given, f.rgb, f.depth, f.K))
                names.append((cam, n, seed))
    return frames, names


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--old", help="the checkout to compare against (e.g. git worktree add /tmp/old main)")
    ap.add_argument("--new", default=str(ROOT))
    ap.add_argument("--sizes", nargs="*", type=int, default=[5, 10, 15, 20, 30])
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--camera-model", nargs="*", default=["ideal", "realsense_d435"])
    ap.add_argument("--time-sizes", nargs="*", type=int, default=[30])
    ap.add_argument("--time-camera", nargs="*", default=["realsense_d435"])
    ap.add_argument("--rounds", type=int, default=3, help="timed passes over the timed frames")
    ap.add_argument("--tol", type=float, default=1e-4, help="m (or rad): float outputs equal within this")
    ap.add_argument("--worker", help=argparse.SUPPRESS)
    ap.add_argument("--frames-file", help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.worker:
        return worker(a.worker, a.frames_file)
    if not a.old:
        ap.error("--old is required")
    frames, names = render(a.sizes, a.seeds, a.camera_model)
    with tempfile.TemporaryDirectory() as tmp:
        path = str(Path(tmp) / "frames.pkl")
        with open(path, "wb") as fh:
            pickle.dump(frames, fh)
        old, new = Worker(str(Path(a.old).resolve()), path), Worker(str(Path(a.new).resolve()), path)
        try:
            diffs = same = 0
            for k, name in enumerate(names):   # every frame once: the outputs compared
                before, after = old.run(k)[1], new.run(k)[1]
                d = differences(before, after, a.tol)
                diffs += bool(d)
                same += before == after
                for line in d:
                    print(f"DIFF {name}: {line}")
            print(f"{len(names)} frames compared: {diffs} differ (floats beyond {a.tol * 1000:g} mm), {same} identical "
                  "to the last bit")
            timed = [k for k, (cam, n, _) in enumerate(names) if n in a.time_sizes and cam in a.time_camera]
            cpu: dict[str, list[float]] = {"old": [], "new": []}
            for r in range(a.rounds):
                for k in timed:   # alternating, the order swapped every round
                    for label, w in (("old", old), ("new", new)) if (r + k) % 2 == 0 else (("new", new),
                                                                                            ("old", old)):
                        cpu[label].append(w.run(k)[0])
        finally:
            old.close()
            new.close()
    o, n = np.array(cpu["old"]), np.array(cpu["new"])
    print(f"CPU ms per frame ({len(timed)} frames x {a.rounds} rounds, sizes {a.time_sizes}, {a.time_camera}): "
          f"old median {1000 * np.median(o):.0f} mean {1000 * o.mean():.0f}; new median {1000 * np.median(n):.0f} "
          f"mean {1000 * n.mean():.0f}; new/old {np.median(n / o):.2f} (median of per-frame ratios); new "
          f"{1 / np.median(n):.1f} frames/s of CPU time")
    if not math.isfinite(float(np.median(n))):
        sys.exit(1)


if __name__ == "__main__":
    main()
