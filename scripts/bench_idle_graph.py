#!/usr/bin/env python
"""CPU of the camera loop while nothing moves: the simulated driver (its camera at camera_rate) and the perception
node (every frame) over `--seconds` of an idle scene, this checkout's code against an older checkout's (`--old`),
alternated, one after the other; the real parameters (config/jaco2_sim_driver.yaml, config/perception.yaml), the arm
at home with no command, as during the task planner's training. Prints each run's CPU (fraction of one core) and the
ratio new / old; the new code's frames rendered / reused and processed / reused from its /diagnostics. First, in
this process, the cost of one frame rendered and reused (CameraRenderer) and processed and reused (Perception).
Paste the numbers into docs/bench/sim_driver.md.

Usage: git worktree add --detach /tmp/old <commit before>; ln -s $PWD/.venv /tmp/old/.venv
       .venv/bin/python scripts/bench_idle_graph.py --old /tmp/old [--seconds 60] [--rounds 2] [--domain 96]
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "test"))  # ros_procs
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # this checkout's packages
os.environ.setdefault("MUJOCO_GL", "egl")  # headless rendering: before mujoco is imported (as jaco2_sim_driver does)

from relocation_app.graph import Graph

REPO = Path(__file__).resolve().parent.parent

NODES = ("jaco2_sim_driver", "perception")
COUNTS = ("camera frames rendered", "camera frames reused (scene unchanged)", "frames processed",
          "frames reused (inputs unchanged)")


def cpu_seconds(pid: int) -> float:
    """utime + stime of a process (s), from /proc."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def counts(msgs: list) -> dict[str, str]:
    """The newest frame counters in these /diagnostics messages (the new code's)."""
    return {kv.key: kv.value for m in msgs for st in m.status for kv in st.values if kv.key in COUNTS}


def run(tree: Path, scenario: str, seconds: float, warmup: float, domain: int) -> tuple[dict[str, float], dict]:
    """CPU fraction of one core of each node over `seconds` after its first scene (and `warmup` s), the code from
    `tree`; the frame counters of its /diagnostics at the end."""
    from diagnostic_msgs.msg import DiagnosticArray
    from qtree_relocation_msgs.msg import ObjectArray
    from rclpy.qos import DurabilityPolicy, QoSProfile
    from ros_procs import Probe

    with tempfile.TemporaryDirectory(prefix="idle_") as tmp, Graph(Path(tmp), domain_id=domain) as g:
        g.env["PYTHONPATH"] = os.pathsep.join([str(tree)] + g.env["PYTHONPATH"].split(os.pathsep)[1:])
        procs = {n: g.start(n, {"scenario": scenario}) for n in NODES}
        probe = Probe(domain)
        try:
            diagnostics = probe.collect("/diagnostics", DiagnosticArray)
            scenes = probe.collect("/scene/objects", ObjectArray,
                                   QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL))
            t_start = time.monotonic()
            scenes.wait(timeout=240.0)
            up = time.monotonic() - t_start
            time.sleep(warmup)
            c0, t0 = {n: cpu_seconds(p.pid) for n, p in procs.items()}, time.monotonic()
            time.sleep(seconds)
            g.check_alive()
            c1, t1 = {n: cpu_seconds(p.pid) for n, p in procs.items()}, time.monotonic()
            time.sleep(2.0)
            seen = counts(diagnostics.wait(timeout=1.0))
        finally:
            probe.close()
        print(f"  ({tree}: first scene {up:.0f} s after the start)", flush=True)
        return {n: (c1[n] - c0[n]) / (t1 - t0) for n in NODES}, seen


def per_frame(scenario: str, n: int = 5) -> None:
    """ms per frame of the camera (render vs reuse) and of perception (process vs reuse), this checkout, median."""
    import mujoco
    import numpy as np

    from jaco2_sim_driver.camera import CameraRenderer
    from jaco2_sim_driver.params import CameraSpec
    from jaco2_sim_driver.sim import Jaco2Sim
    from perception_aruco.pipeline import Perception, SceneMemory
    from relocation_common.robot_description import Q_HOME
    from relocation_common.scenario import load_scenario

    sc = load_scenario(scenario)
    sim = Jaco2Sim(sc, camera=CameraSpec.configured())
    sim.step(300)
    r = CameraRenderer(sim.model, sim.camera.width, sim.camera.height)
    data = mujoco.MjData(sim.model)
    data.qpos[:] = sim.data.qpos
    mujoco.mj_kinematics(sim.model, data)
    mujoco.mj_camlight(sim.model, data)
    p, memory, q = Perception(sc), SceneMemory(sc.ids, 3, 2), np.array([Q_HOME])

    def ms(f) -> float:
        out = []
        for _ in range(n):
            t = time.perf_counter()
            f()
            out.append(1e3 * (time.perf_counter() - t))
        return float(np.median(out))

    def render_anew():
        r._last = None
        return r.render(data)
    f = r.render(data)

    def process_anew():
        p._last = None
        return p.process(f.rgb, f.depth, f.K, None, memory, q)
    try:
        rendered, reused = ms(render_anew), ms(lambda: r.render(data))
    finally:
        r.close()
    processed, again = ms(process_anew), ms(lambda: p.process(f.rgb, f.depth, f.K, None, memory, q))
    print(f"per frame ({Path(scenario).name}, {sim.camera.width}x{sim.camera.height}, median of {n}): camera "
          f"render {rendered:.1f} ms, reuse {reused:.1f} ms; perception process {processed:.0f} ms, reuse "
          f"{again:.1f} ms", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--old", type=Path, required=True, help="a checkout of the code before (git worktree)")
    ap.add_argument("--scenario", default="config/scenarios/scenario3_15.yaml")
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--warmup", type=float, default=10.0, help="s after the first scene before measuring")
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--domain", type=int, default=96)
    a = ap.parse_args()
    scenario = str((REPO / a.scenario).resolve())
    per_frame(scenario)
    out: dict[str, list[dict[str, float]]] = {"old": [], "new": []}
    for r in range(a.rounds):
        for label, tree in (("old", a.old.resolve()), ("new", REPO)) if r % 2 == 0 else \
                (("new", REPO), ("old", a.old.resolve())):
            cpu, counts = run(tree, scenario, a.seconds, a.warmup, a.domain)
            out[label].append(cpu)
            print(f"pass {r + 1} {label}: " + ", ".join(f"{n} {cpu[n]:.3f} core" for n in NODES)
                  + (f"; {counts}" if counts else ""), flush=True)
    print(f"\nmean over {a.rounds} rounds of {a.seconds:g} s (fraction of one core), {Path(a.scenario).name}:")
    for n in NODES + ("both",):
        old = sum(sum(c.values()) if n == "both" else c[n] for c in out["old"]) / a.rounds
        new = sum(sum(c.values()) if n == "both" else c[n] for c in out["new"]) / a.rounds
        print(f"  {n:17s} old {old:.3f}  new {new:.3f}  new/old {new / old:.2f}")


if __name__ == "__main__":
    main()
