#!/usr/bin/env python
"""Benchmark of the MuJoCo Jaco2 driver (docs/sim_driver.md). Prints numbers; paste them into docs/bench/sim_driver.md.

1. Core speed: 15 free bottles, physics at 1 kHz, arm streaming a velocity command at 100 Hz and a JointState
   message built at 100 Hz; with MuJoCo's sleeping of resting bodies (the default) and with it off (every bottle
   awake: the worst case). Goal >= 10x real time.
2. Node speed: the node process with real_time_factor 0 (as fast as possible), camera off, publishing joint
   states every 10 ms of simulated time over DDS; speed = messages per wall second / 100.
3. Command-to-state latency over DDS: a probe publishes a joint-7 velocity of alternating sign on
   /velocity_controller/commands and times the first /joint_states message whose joint-7 velocity has the new
   sign. Goal p50 <= 5 ms. With state_on_command true (default) and false (states only at 100 Hz).

Usage: .venv/bin/python scripts/bench_sim_driver.py [--quick]
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

import mujoco
import numpy as np
import yaml

from jaco2_sim_driver.sim import Jaco2Sim
from relocation_common.paths import default_scenario
from relocation_common.scenario import parse_scenario

REPO = Path(__file__).resolve().parent.parent


def scenario_15() -> dict:
    """Fifteen bottles on the top shelf: three rows of five, placed relative to the default scenario's shelf."""
    data = yaml.safe_load(default_scenario().read_text())
    sh = data["shelf"]
    data["name"] = "bench_15"
    rows = [sh["x_front"] + f * sh["depth"] for f in (0.2, 0.5, 0.8)]
    cols = [sh.get("y_center", 0.0) + dy for dy in (-0.28, -0.14, 0.0, 0.14, 0.28)]
    objs = [{"id": f"o{k + 1}", "weight": 0.5, "xy": [x, y]}
            for k, (x, y) in enumerate((x, y) for x in rows for y in cols)]
    objs[7] = {"id": "T", "xy": objs[7]["xy"]}  # centre of the middle row
    data.pop("blocking", None)
    data["objects"], data["target"], data["slots"] = objs, "T", "auto"
    return data


def bench_core(seconds: float, sleep: bool) -> float:
    sim = Jaco2Sim(parse_scenario(scenario_15()))
    if not sleep:
        sim.model.opt.enableflags &= ~int(mujoco.mjtEnableBit.mjENBL_SLEEP)
    from sensor_msgs.msg import JointState
    n = int(seconds * 100)
    t0 = time.perf_counter()
    for k in range(n):
        sim.set_velocity(0.3 * np.sin(0.02 * k + np.arange(7)))
        sim.step(10)
        js = JointState()
        js.position, js.velocity = sim.q.tolist(), sim.qdot.tolist()
    return seconds / (time.perf_counter() - t0)


def bench_node(tmp: Path, seconds: float) -> float:
    from ros_procs import RosGraph
    from sensor_msgs.msg import JointState
    path = tmp / "bench_15.yaml"
    path.write_text(yaml.safe_dump(scenario_15()))
    with RosGraph(tmp / "node") as g:
        g.start("jaco2_sim_driver.driver_node", params={"scenario": str(path), "real_time_factor": 0.0,
                                                         "camera_rate": 0.0, "state_on_command": False,
                                                         "command_interface": "ros2_control"})
        c = g.probe.collect("/joint_states", JointState)
        c.wait(lambda m: len(m) > 50, timeout=60)
        n0, t0 = len(c.msgs), time.monotonic()
        time.sleep(seconds)
        return (len(c.msgs) - n0) / (time.monotonic() - t0) / 100.0


def bench_latency(tmp: Path, samples: int, state_on_command: bool) -> np.ndarray:
    from ros_procs import RosGraph
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64MultiArray
    with RosGraph(tmp / f"lat_{state_on_command}") as g:
        g.start("jaco2_sim_driver.driver_node", params={"camera_rate": 0.0, "state_on_command": state_on_command,
                                                         "command_interface": "ros2_control"})
        c = g.probe.collect("/joint_states", JointState)
        c.wait(lambda m: len(m) > 10, timeout=60)
        pub = g.probe.publisher(Float64MultiArray, "/velocity_controller/commands")
        g.probe.wait_for_subscribers(pub)
        for _ in range(30):  # discovery settles both ways
            pub.publish(Float64MultiArray(data=[0.0] * 7))
            time.sleep(0.01)
        lat = []
        for k in range(samples + 5):
            sign = 1.0 if k % 2 == 0 else -1.0
            for _ in range(3):  # hold the command (watchdog) and let the joint settle
                pub.publish(Float64MultiArray(data=[0.0] * 6 + [-0.5 * sign]))
                time.sleep(0.01)
            n = len(c.msgs)
            t0 = time.monotonic()
            pub.publish(Float64MultiArray(data=[0.0] * 6 + [0.5 * sign]))
            c.wait(lambda m: any(x.velocity[6] * sign > 0.25 for x in m[n:]), timeout=2)
            i = next(i for i in range(n, len(c.msgs)) if c.msgs[i].velocity[6] * sign > 0.25)
            if k >= 5:
                lat.append(c.times[i] - t0)
        return np.array(lat) * 1e3


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="short runs (for the bench test)")
    a = ap.parse_args()
    secs, samples = (1.0, 20) if a.quick else (10.0, 200)
    print(f"jaco2_sim_driver benchmark (mujoco {mujoco.__version__}, 15 free bottles, physics 1 kHz)")
    print(f"core, bottles may sleep when at rest : {bench_core(secs, True):6.1f} x real time")
    print(f"core, sleeping off (all bottles awake): {bench_core(secs, False):6.1f} x real time")
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        print(f"node over DDS, as fast as possible   : {bench_node(tmp, min(secs, 5.0)):6.1f} x real time "
              f"(joint states every 10 ms sim)")
        for soc in (True, False):
            ms = bench_latency(tmp, samples, soc)
            print(f"command->state latency, state_on_command={str(soc):5}: p50 {np.percentile(ms, 50):.2f} ms, "
                  f"p90 {np.percentile(ms, 90):.2f} ms, max {ms.max():.2f} ms ({len(ms)} samples)")


if __name__ == "__main__":
    main()
