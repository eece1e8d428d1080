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
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from relocation_app.graph import Graph

COUNTER = """
import json, sys, time
import rclpy
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import CameraInfo, Image
rclpy.init()
node = rclpy.create_node("image_delivery_probe")
got = {"colour": set(), "depth": set(), "info": set()}
stamp = lambda m: (m.header.stamp.sec, m.header.stamp.nanosec)
for key, topic in (("colour", "/camera/color/image_raw"), ("depth", "/camera/depth/image_rect_raw")):
    node.create_subscription(Image, topic, lambda m, k=key: got[k].add(stamp(m)), qos_profile_sensor_data)
# the frames published: each frame's small camera info, reliable (its stamp is the frame's)
node.create_subscription(CameraInfo, "/camera/color/camera_info", lambda m: got["info"].add(stamp(m)), 10)
start = time.monotonic()
while not got["info"]:  # the driver's first frame: its start, slow on a loaded machine, is not the window's
    rclpy.spin_once(node, timeout_sec=0.05)
    if time.monotonic() - start > float(sys.argv[2]):
        sys.exit(f"no camera frame within {sys.argv[2]} s")
for k in got:
    got[k].clear()
t0 = time.monotonic()
while time.monotonic() - t0 < float(sys.argv[1]):
    rclpy.spin_once(node, timeout_sec=0.05)
published, t1 = set(got["info"]), time.monotonic()
while time.monotonic() - t1 < 1.0:  # the images of the window's last frames, still on their way
    rclpy.spin_once(node, timeout_sec=0.05)
print(json.dumps({"colour": len(got["colour"] & published), "depth": len(got["depth"] & published),
                  "pairs": len(got["colour"] & got["depth"] & published), "published": len(published)}))
"""
START_WAIT = 120.0  # s for the driver's first frame


def delivery(profile: bool, seconds: float, run_dir: Path, camera_rate: float = 2.0) -> dict:
    """Camera frames a best-effort subscriber receives of those published in `seconds` from the first one (counted
    by their camera info, received reliably), and `expected` = camera_rate x seconds. The camera renders on the wall
    clock's pace only while rendering (about 75 ms a frame) keeps up: on a loaded machine fewer frames are published
    than expected. profile=False: Fast DDS's defaults (FASTRTPS_DEFAULT_PROFILES_FILE unset)."""
    with Graph(run_dir) as g:
        if not profile:
            g.env.pop("FASTRTPS_DEFAULT_PROFILES_FILE", None)
        g.start("jaco2_sim_driver", {"camera_rate": camera_rate})
        r = subprocess.run([sys.executable, "-c", COUNTER, str(seconds), str(START_WAIT)], env=g.env,
                           capture_output=True, text=True, timeout=START_WAIT + seconds + 60)
        g.check_alive()
    if r.returncode != 0:
        raise RuntimeError(r.stderr[-2000:])
    return json.loads(r.stdout.strip().splitlines()[-1]) | {"expected": round(camera_rate * seconds)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=30.0)
    ap.add_argument("--rounds", type=int, default=2)
    a = ap.parse_args()
    print("| Fast DDS transports | round | colour | depth | colour+depth pairs | frames published | at camera_rate |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for k in range(a.rounds):
        for profile in (False, True):
            d = delivery(profile, a.seconds, Path(f"/tmp/bench_image_delivery/{k}_{int(profile)}"))
            label = "config/fastdds.xml (16 MB SHM segment)" if profile else "defaults (512 KB SHM segment)"
            print(f"| {label} | {k + 1} | {d['colour']} | {d['depth']} | {d['pairs']} | {d['published']} | "
                  f"{d['expected']} |", flush=True)


if __name__ == "__main__":
    main()
