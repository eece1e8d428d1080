"""The camera's ~1 MB images reach a best-effort subscriber (perception's sensor-data QoS): the graph's processes use
config/fastdds.xml (relocation_app.graph.ros_env). With Fast DDS's defaults 3-6 of 40 frames arrived
(scripts/bench_image_delivery.py, docs/sim_driver.md); a demo start waited 56 s for its first colour/depth pair."""
import importlib.util
from pathlib import Path

import pytest

pytestmark = pytest.mark.graph

_spec = importlib.util.spec_from_file_location(
    "bench_image_delivery", Path(__file__).resolve().parent.parent / "scripts" / "bench_image_delivery.py")
bench = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(bench)


def test_a_best_effort_subscriber_gets_most_camera_frames(tmp_path):
    d = bench.delivery(True, 8.0, tmp_path)
    print(f"\n{d}")
    # of the frames published (on a loaded machine the camera renders fewer than camera_rate x seconds: at a load of
    # 20 the window began before the driver's first frame and counted 0 of 16) with Fast DDS's defaults: about 10 %
    assert d["published"] >= 3 and d["pairs"] >= 0.6 * d["published"], d
