#!/usr/bin/env python3
"""Benchmark: camera frames a best-effort subscriber (perception's sensor-data QoS) receives from the sim driver,
with Fast DDS's default transports and with config/fastdds.xml (16 MB shared-memory segment), side by side in one
run (docs/sim_driver.md). Each case starts the driver and a counting subscriber as processes of their own on a
private domain. Prints numbers; asserts nothing (test_image_delivery.py runs a short version).

    .venv/bin/python scripts/bench_image_delivery.py [--seconds 30] [--rounds 2]
"""
import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from relocation_app.graph import Graph

COUNTER = """
import json, sys, time
import rclpy
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import Image
rclpy.init()
node = rclpy.create_node("image_delivery_probe")
got = {"colour": set(), "depth": set()}
for key, topic in (("colour", "/camera/color/image_raw"), ("depth", "/camera/depth/image_rect_raw")):
    node.create_subscription(Image, topic, lambda m, k=key: got[k].add((m.header.stamp.sec, m.header.stamp.nanosec)),
                             qos_profile_sensor_data)
t0 = time.monotonic()
while time.monotonic() - t0 < float(sys.argv[1]):
    rclpy.spin_once(node, timeout_sec=0.05)
print(json.dumps({"colour": len(got["colour"]), "depth": len(got["depth"]),
                  "pairs": len(got["colour"] & got["depth"])}))
"""


def delivery(profile: bool, seconds: float, run_dir: Path, camera_rate: float = 2.0) -> dict:
    """Frames received in `seconds` (after the first one) by a best-effort subscriber; `expected` = camera_rate x
    seconds. profile=False: Fast DDS's defaults (FASTRTPS_DEFAULT_PROFILES_FILE unset)."""
    with Graph(run_dir) as g:
        if not profile:
            g.env.pop("FASTRTPS_DEFAULT_PROFILES_FILE", None)
        g.start("jaco2_sim_driver", {"camera_rate": camera_rate})
        time.sleep(3.0)  # the driver's first frame
        r = subprocess.run([sys.executable, "-c", COUNTER, str(seconds)], env=g.env, capture_output=True, text=True,
                           timeout=seconds + 60)
        g.check_alive()
    if r.returncode != 0:
        raise RuntimeError(r.stderr[-2000:])
    return json.loads(r.stdout.strip().splitlines()[-1]) | {"expected": round(camera_rate * seconds)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=30.0)
    ap.add_argument("--rounds", type=int, default=2)
    a = ap.parse_args()
    print("| Fast DDS transports | round | colour | depth | colour+depth pairs | frames published |")
    print("|---|---:|---:|---:|---:|---:|")
    for k in range(a.rounds):
        for profile in (False, True):
            d = delivery(profile, a.seconds, Path(f"/tmp/bench_image_delivery/{k}_{int(profile)}"))
            label = "config/fastdds.xml (16 MB SHM segment)" if profile else "defaults (512 KB SHM segment)"
            print(f"| {label} | {k + 1} | {d['colour']} | {d['depth']} | {d['pairs']} | {d['expected']} |", flush=True)


if __name__ == "__main__":
    main()
