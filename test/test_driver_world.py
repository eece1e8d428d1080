"""The driver node on a scenario with an object it alone is told about (world/paper_experiment_10_unlisted): its
ground truth on /sim/objects carries the unlisted bottle (listed false, perception's weight estimate and its note),
read back through ros_conversions.msg_to_objects, and /tf has a frame for it."""
import signal

import pytest

pytest.importorskip("rclpy")
from qtree_relocation_msgs.msg import ObjectArray
from rclpy.qos import QoSDurabilityPolicy, QoSProfile
from ros_procs import REPO, RosGraph
from tf2_msgs.msg import TFMessage

from relocation_common.ros_conversions import msg_to_objects
from relocation_common.scenario import load_scenario
from relocation_common.shelf_object import estimated_weight, unlisted_density

pytestmark = pytest.mark.graph

SCENE = "world/paper_experiment_10_unlisted"
LATCHED = QoSProfile(depth=1, durability=QoSDurabilityPolicy.TRANSIENT_LOCAL)


def test_ground_truth_carries_the_unlisted_bottle_with_listed_false(tmp_path):
    sc = load_scenario(SCENE)
    g = RosGraph(tmp_path)
    try:
        node = g.start("jaco2_sim_driver.driver_node", params_file=REPO / "config" / "jaco2_sim_driver.yaml",
                       params={"scenario": SCENE, "camera_rate": 0.0})
        tf = g.probe.collect("/tf", TFMessage)
        msg = g.probe.collect("/sim/objects", ObjectArray, LATCHED).wait(timeout=60)[-1]
        objects = msg_to_objects(msg, listed_ids=sc.ids)
        assert [o.id for o in objects] == [*sc.ids, "x1"], node.log()
        x1 = objects[-1]
        weight, note = estimated_weight(sc.unlisted[0], unlisted_density())
        assert (x1.listed, x1.weight, x1.weight_note) == (False, pytest.approx(weight), note)
        assert (x1.x, x1.y, x1.support_z) == pytest.approx((sc.unlisted[0].x, sc.unlisted[0].y, sc.shelf.top_z),
                                                           abs=0.002)
        assert all(o.listed for o in objects[:-1])
        frames = tf.wait(lambda ms: any(t.child_frame_id == "bottle_x1" for m in ms for t in m.transforms),
                         timeout=20)
        assert frames
        assert node.stop(signal.SIGINT) == 0, node.log()
    finally:
        g.close()
