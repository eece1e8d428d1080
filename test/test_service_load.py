"""PlanFeasibility under a burst (docs/reliability.md, section 9): every request of a burst of concurrent requests is
answered.

Old code: the service kept rclpy's default depth of 10; of 50 (200) concurrent requests from one client, 11 were
answered and the rest dropped silently, their client waiting forever. A client's own history (depth 10 by default)
also drops what the client cannot take in time: requests of a burst before they leave the process, responses before
its executor reads them (a fresh-clone CI run on a loaded machine lost 1 response of 50 this way). So every client
here declares a deep queue, as RelocationClient does; what is tested is the server's side."""
import threading
import time

import pytest
from ros_procs import REPO, RosGraph

pytest.importorskip("rclpy")
from qtree_relocation_msgs.srv import PlanFeasibility

pytestmark = pytest.mark.graph

SRV = "/motion_planner/plan_feasibility"


@pytest.mark.parametrize("burst", [50, pytest.param(200, marks=pytest.mark.extended)])
def test_a_burst_of_concurrent_requests_is_answered_in_full(tmp_path, burst):
    with RosGraph(tmp_path) as g:
        planner = g.start("stpik_motion_planner.motion_planner_node",
                          params_file=REPO / "config" / "motion_planner.yaml", params={"scene_topic": "/none"})
        from rclpy.qos import QoSProfile
        cli = g.probe.node.create_client(PlanFeasibility, SRV, qos_profile=QoSProfile(depth=1000))
        assert cli.wait_for_service(timeout_sec=60)
        ids = ["o1", "o4", "o7", "T"]  # a mix of quick unfeasible and slower feasible answers
        answered, done = [], threading.Event()
        lock = threading.Lock()

        def on_done(fut):
            with lock:
                answered.append(fut.result())
                if len(answered) == burst:
                    done.set()

        t0 = time.monotonic()
        for k in range(burst):
            cli.call_async(PlanFeasibility.Request(object_id=ids[k % len(ids)], timeout=0.5)).add_done_callback(on_done)
        done.wait(120)
        took = time.monotonic() - t0
        print(f"\n{burst} concurrent requests: {len(answered)} answered in {took:.1f} s "
              f"({sum(r.ok for r in answered)} ok)")
        assert len(answered) == burst and all(r.ok for r in answered)
        assert planner.alive()
