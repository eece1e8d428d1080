#!/usr/bin/env python3
"""Benchmark: how regularly a node receives the driver's 100 Hz joint states, per executor (docs/benchmarks.md).

Starts the sim driver (camera off) on a private domain, then for each configuration subscribes in this process for
--seconds and prints the receive gaps: rclpy's SingleThreadedExecutor, MultiThreadedExecutor with 2 and 6 threads
(the node also runs a busy callback, as the motion planner's relocation does), and relocation_common.node.SideNode
next to that busy multi-threaded node (what the motion planner does). Prints numbers; asserts nothing.
"""
import argparse
import sys
import threading
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
import rclpy
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.executors import MultiThreadedExecutor, SingleThreadedExecutor
from sensor_msgs.msg import JointState
from std_msgs.msg import Empty

from relocation_app.graph import Graph
from relocation_common.node import SideNode

TOPIC = "/j2s7s300_driver/out/joint_state"


def busy(_msg) -> None:  # a long callback holding an executor thread, as a relocation does (follower loop)
    t = time.monotonic()
    while time.monotonic() - t < 5.0:
        sum(i * i for i in range(2000))
        time.sleep(0.005)


def measure(kind: str, seconds: float) -> np.ndarray:
    arrivals = []
    node = rclpy.create_node(f"bench_{kind.replace('-', '_')}")
    side = None
    if kind == "single":
        ex = SingleThreadedExecutor()
    else:
        ex = MultiThreadedExecutor(num_threads=2 if kind == "multi-2" else 6)
        node.create_subscription(Empty, "/bench/busy", busy, 1, callback_group=ReentrantCallbackGroup())
    if kind == "side-node":
        side = SideNode("bench_side")
        side.node.create_subscription(JointState, TOPIC, lambda m: arrivals.append(time.monotonic()), 10)
    else:
        node.create_subscription(JointState, TOPIC, lambda m: arrivals.append(time.monotonic()), 10,
                                 callback_group=MutuallyExclusiveCallbackGroup())
    ex.add_node(node)
    th = threading.Thread(target=ex.spin, daemon=True)
    th.start()
    pub = node.create_publisher(Empty, "/bench/busy", 1)
    time.sleep(2.0)  # discovery
    t0 = time.monotonic()
    while time.monotonic() - t0 < seconds:
        if kind != "single":
            pub.publish(Empty())
        time.sleep(1.0)
    ex.shutdown(timeout_sec=6.0)
    th.join(timeout=6.0)
    if side is not None:
        side.close()
    node.destroy_node()
    a = np.array([x for x in arrivals if x >= t0])
    return np.diff(a) if len(a) > 1 else np.array([np.inf])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=10.0)
    a = ap.parse_args()
    import os
    with Graph(Path("out/bench_joint_states")) as g:
        g.start("jaco2_sim_driver", {"camera_rate": 0.0})
        os.environ.update(g.env)
        rclpy.init()
        print(f"{'executor':<12} {'messages':>8} {'p50 gap ms':>10} {'p99 gap ms':>10} {'max gap ms':>10} "
              f"{'gaps > 0.1 s':>12}")
        for kind in ("single", "multi-2", "multi-6", "side-node"):
            d = measure(kind, a.seconds)
            print(f"{kind:<12} {len(d) + 1:>8} {np.median(d) * 1e3:>10.1f} {np.percentile(d, 99) * 1e3:>10.1f} "
                  f"{d.max() * 1e3:>10.1f} {int((d > 0.1).sum()):>12}", flush=True)
        rclpy.try_shutdown()


if __name__ == "__main__":
    main()
