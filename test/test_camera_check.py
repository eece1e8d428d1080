"""Perception refuses a camera_info or an image it cannot use, with the reason, and keeps running
(perception_aruco.camera_check; the node's callbacks driven in this process, no DDS traffic needed)."""
import math
import os

import pytest

from perception_aruco.camera_check import camera_info_problem, image_problem

K = [600.0, 0.0, 320.0, 0.0, 600.0, 240.0, 0.0, 0.0, 1.0]


def test_a_usable_camera_info_passes():
    assert camera_info_problem(K, (640, 480), (640, 480)) is None
    assert image_problem(1920, 1080, 1920 * 1080) is None


@pytest.mark.parametrize("k, size, words", [
    ([math.nan] * 9, (640, 480), "not 9 finite numbers"),
    ([0.0] * 9, (640, 480), "focal lengths fx=0, fy=0"),
    ([-600.0, 0, 320, 0, 600, 240, 0, 0, 1], (640, 480), "must be > 0"),
    ([600.0, 0, 320, 0, 600, 240, 0, 0, 0], (640, 480), "last row must be 0 0 1"),
    ([600.0, 0, 900, 0, 600, 240, 0, 0, 1], (640, 480), "principal point (900, 240) is outside the 640x480"),
    (K, (1280, 720), "camera_info is for 1280x720, the images are 640x480"),
    (K[:4], (640, 480), "not 9 finite numbers"),
])
def test_an_unusable_camera_info_is_refused_with_the_reason(k, size, words):
    assert words in camera_info_problem(k, size, (640, 480))


def test_an_image_over_the_maximum_is_refused_with_the_reason():
    why = image_problem(3840, 2160, 1920 * 1080, "colour image")
    assert why.startswith("colour image is 3840x2160 = 8294400 pixels > max_image_pixels (2073600)"), why
    assert "empty" in image_problem(0, 480, 100)


@pytest.fixture(scope="module")
def node(tmp_path_factory):
    """The perception node in this process (its own domain, loopback) with a rendered frame of the scene."""
    rclpy = pytest.importorskip("rclpy")
    from ros_procs import reserve_domain_id

    from jaco2_sim_driver.camera import render_frame
    from perception_aruco.perception_node import PerceptionNode
    from relocation_common.paths import default_scenario
    from relocation_common.scenario import load_scenario

    domain, lock = reserve_domain_id()
    saved = os.environ.get("ROS_AUTOMATIC_DISCOVERY_RANGE")
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    rclpy.init(domain_id=domain)
    n = PerceptionNode()
    n.frame = render_frame(load_scenario(default_scenario()))
    yield n
    n.destroy_node()
    rclpy.try_shutdown()
    lock.unlink(missing_ok=True)
    if saved is None:
        os.environ.pop("ROS_AUTOMATIC_DISCOVERY_RANGE", None)
    else:
        os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = saved


def _feed(node, k, width=None, height=None, stamp=1):
    from sensor_msgs.msg import CameraInfo, Image

    from perception_aruco.images import encode_color, encode_depth
    f = node.frame
    node._on_info(CameraInfo(width=width or f.width, height=height or f.height, k=[float(v) for v in k]))
    for fields, handler in ((encode_color(f.rgb), node._on_color), (encode_depth(f.depth, "16UC1"), node._on_depth)):
        enc, h, w, step, data = fields
        msg = Image(encoding=enc, height=h, width=w, step=step, data=data)
        msg.header.stamp.sec = stamp
        handler(msg)
    node._process()


def test_the_node_drops_frames_with_a_bad_camera_info_and_goes_on(node):
    """Old code: a NaN or all-zero K raised LinAlgError ('Eigenvalues did not converge') out of the timer callback:
    the node exited (status 2) and real frames afterwards got no scene."""
    for stamp, k in enumerate(([math.nan] * 9, [0.0] * 9), start=1):
        _feed(node, k, stamp=stamp)
        assert node._scene is None
    for stamp in range(3, 3 + node.memory.confirm_frames):  # the real calibration: a scene once the node's first
        _feed(node, node.frame.K.reshape(-1).tolist(), stamp=stamp)  # `confirm_frames` frames are in
    assert node._scene is not None and len(node._scene.objects) >= 9


def test_the_node_refuses_a_4k_image_before_keeping_it(node):
    from sensor_msgs.msg import Image
    kept = len(node._colors)
    node._on_color(Image(encoding="rgb8", width=3840, height=2160, step=3840 * 3))
    assert len(node._colors) == kept
