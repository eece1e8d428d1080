"""The perception node in its own process over real DDS: this test plays the camera driver (a frame rendered by the
MuJoCo scene, published as RealSense-named topics) and checks the ObjectArray on /scene/objects (transient local)
and the debug image, and the health on /diagnostics. A colour image with an unsupported encoding is logged, not
fatal."""
import os
import threading
import time
from dataclasses import replace

import numpy as np
import pytest

from jaco2_sim_driver.camera import render_frame
from perception_aruco.images import encode_color, encode_depth
from relocation_app.graph import Graph
from relocation_common.arm_interface import ArmInterface
from relocation_common.config import node_section
from relocation_common.paths import config_file, default_scenario
from relocation_common.robot_description import JOINT_NAMES, Q_HOME
from relocation_common.ros_conversions import msg_to_objects
from relocation_common.scenario import load_scenario

pytestmark = pytest.mark.graph


def _image(stamp, enc, h, w, step, data):
    from sensor_msgs.msg import Image
    m = Image(encoding=enc, height=h, width=w, step=step, data=data)
    m.header.stamp, m.header.frame_id = stamp, "camera_color_optical_frame"
    return m


def _matrix(m) -> np.ndarray:
    """4x4 of a geometry_msgs/TransformStamped."""
    import mujoco
    r = np.zeros(9)
    q = m.transform.rotation
    mujoco.mju_quat2Mat(r, np.array([q.w, q.x, q.y, q.z]))
    t = np.eye(4)
    t[:3, :3] = r.reshape(3, 3)
    t[:3, 3] = m.transform.translation.x, m.transform.translation.y, m.transform.translation.z
    return t


START_WAIT = 120.0  # s for the node to start (imports, the scenario): at a load of 20, more than the 30 s for a scene


def _started(g, pub) -> None:
    """Until the perception node subscribes to `pub`'s topic: the waits for its answers start from there, not from
    its process's start (at a load of 20 no scene came within 30 s of that)."""
    deadline = time.monotonic() + START_WAIT
    while pub.get_subscription_count() == 0:
        g.check_alive()
        assert time.monotonic() < deadline, f"no subscriber on {pub.topic_name} within {START_WAIT} s:\n" + \
            g.log("perception")
        time.sleep(0.1)


def test_node_publishes_perceived_scene(tmp_path):
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
    from qtree_relocation_msgs.msg import ObjectArray
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import DurabilityPolicy, QoSProfile, qos_profile_sensor_data
    from sensor_msgs.msg import CameraInfo, Image, JointState
    from std_msgs.msg import Header
    from tf2_msgs.msg import TFMessage

    scenario = load_scenario(default_scenario())
    frame = render_frame(scenario)
    with Graph(tmp_path) as g:
        g.start("perception", {"process_rate": 10.0})
        os.environ.update({k: g.env[k] for k in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE")})
        rclpy.init()
        try:
            node = rclpy.create_node("fake_camera")
            color_pub = node.create_publisher(Image, "/camera/color/image_raw", qos_profile_sensor_data)
            depth_pub = node.create_publisher(Image, "/camera/depth/image_rect_raw", qos_profile_sensor_data)
            info_pub = node.create_publisher(CameraInfo, "/camera/color/camera_info", qos_profile_sensor_data)
            # the arm's joint states on the surface of config/arm_interface.yaml (the driver's): the arm is filtered
            joints_pub = node.create_publisher(JointState, ArmInterface.load().state_topic, 10)
            scenes, debug = [], []
            node.create_subscription(ObjectArray, "/scene/objects", scenes.append,
                                     QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL))
            node.create_subscription(Image, "/perception/debug_image", debug.append, 1)
            tfs, health = [], []
            node.create_subscription(TFMessage, "/tf", tfs.append, 100)
            node.create_subscription(DiagnosticArray, "/diagnostics", health.append, 10)
            ex = SingleThreadedExecutor()
            ex.add_node(node)
            t = threading.Thread(target=ex.spin, daemon=True)
            t.start()

            info = CameraInfo(width=frame.width, height=frame.height, distortion_model="plumb_bob",
                              k=frame.K.reshape(-1).tolist(), d=[0.0] * 5)
            color = encode_color(frame.rgb)
            depth16 = encode_depth(frame.depth, "16UC1")
            bad = ("mono8", frame.height, frame.width, frame.width, bytes(frame.height * frame.width))

            def publish(color_fields, n=1):
                for _ in range(n):
                    stamp = node.get_clock().now().to_msg()
                    info.header.stamp = stamp
                    info_pub.publish(info)
                    joints_pub.publish(JointState(header=Header(stamp=stamp), name=list(JOINT_NAMES),
                                                  position=[float(x) for x in Q_HOME]))
                    color_pub.publish(_image(stamp, *color_fields))
                    depth_pub.publish(_image(stamp, *depth16))
                    time.sleep(0.25)

            # unsupported encoding first: logged, no scene, node alive
            _started(g, color_pub)
            deadline = time.monotonic() + 40
            while "not supported" not in g.log("perception"):
                g.check_alive()
                assert time.monotonic() < deadline, g.log("perception")
                publish(bad)
            assert not scenes
            # good frames (depth as 16UC1 millimetres): a scene with every bottle at its place
            deadline = time.monotonic() + 30
            while not scenes:
                g.check_alive()
                assert time.monotonic() < deadline, "no ObjectArray on /scene/objects:\n" + g.log("perception")
                publish(color)
            msg = scenes[-1]
            ids = [o.id for o in msg.objects]
            assert set(ids) <= set(scenario.ids) and scenario.target_id in ids
            assert len(ids) >= 9, ids  # at Q_HOME the arm may hide one or two bottles of this scene
            errs = []
            for o in msg_to_objects(msg, scenario.ids):
                b = scenario.object(o.id)
                errs.append(np.hypot(o.x - b.x, o.y - b.y))
                assert o.label == b.label and o.weight == pytest.approx(b.weight) and o.is_target == b.is_target
                assert o.support_z == pytest.approx(scenario.shelf.top_z)
            assert max(errs) < 0.02 and np.median(errs) <= 0.01, errs
            assert msg.header.frame_id == "j2s7s300_link_base"
            # /tf: the marker seen from the camera, the shelf frame on it; through the camera's true pose the shelf
            # frame lands on the front edge of the top board
            deadline = time.monotonic() + 5
            while not tfs and time.monotonic() < deadline:  # another topic: it may arrive after the scene
                time.sleep(0.05)
            tf = {m.child_frame_id: m for m in tfs[-1].transforms}
            assert tf["aruco_marker_7"].header.frame_id == "camera_color_optical_frame"
            assert tf["shelf"].header.frame_id == "aruco_marker_7"
            t_base_shelf = frame.T_base_camera @ _matrix(tf["aruco_marker_7"]) @ _matrix(tf["shelf"])
            sh = scenario.shelf
            assert np.allclose(t_base_shelf[:3, 3], (sh.x_front, sh.y_center, sh.top_z), atol=0.01), t_base_shelf
            assert np.allclose(t_base_shelf[:3, :3], np.eye(3), atol=0.03)
            # republished without new frames (the task planner refuses scenes older than 10 s)
            n = len(scenes)
            time.sleep(1.2)
            assert len(scenes) > n
            assert debug and debug[-1].encoding == "rgb8" and debug[-1].width == frame.width
            # health on /diagnostics: the refused frames (bad encoding) as ERROR with the reason, then the good ones
            levels = [(st.level, st.message) for a in health for st in a.status]
            assert any(lv == DiagnosticStatus.ERROR and "not supported" in m for lv, m in levels), levels
            assert levels[-1][0] in (DiagnosticStatus.OK, DiagnosticStatus.WARN), levels[-1]
            deadline = time.monotonic() + 10  # the first frames may come before the first joint state
            while all("no joint state" in st.message for a in health for st in a.status
                      if st.level != DiagnosticStatus.ERROR):
                assert time.monotonic() < deadline, levels[-1]  # it listens where the driver publishes
                publish(color)
            g.check_alive()
            ex.shutdown()
            node.destroy_node()
        finally:
            rclpy.try_shutdown()
        assert g.stop("perception") == 0


def test_node_publishes_an_unlisted_object(tmp_path):
    """The user's case over DDS: the camera sees a bottle the scenario does not list (the simulator's `unlisted`);
    the node, given the arm's joint state, publishes it as u1 (listed false, its estimated weight said in
    weight_note) beside every listed bottle, through the one message conversion."""
    import rclpy
    from perception_scenes import render_scene, with_objects
    from qtree_relocation_msgs.msg import ObjectArray
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import DurabilityPolicy, QoSProfile, qos_profile_sensor_data
    from sensor_msgs.msg import CameraInfo, Image, JointState

    from relocation_common.robot_description import JOINT_NAMES, Q_HOME
    from relocation_common.scenario import PALETTE

    scenario = load_scenario(default_scenario())
    # the case: an unlisted bottle at (0.86, 0.07) of paper_experiment_10, between o6, o7, o9 and T
    other = replace(scenario.objects[0], id="x1", label="pink", rgb=PALETTE["pink"], x=0.86, y=0.07, listed=False,
                    is_target=False)
    frame, vis = render_scene(with_objects(scenario, scenario.objects, [other]))
    assert vis["x1"] >= 300
    with Graph(tmp_path) as g:
        g.start("perception", {"process_rate": 10.0})
        os.environ.update({k: g.env[k] for k in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE")})
        rclpy.init()
        try:
            node = rclpy.create_node("fake_camera")
            pubs = [node.create_publisher(t, n, qos_profile_sensor_data) for t, n in (
                (Image, "/camera/color/image_raw"), (Image, "/camera/depth/image_rect_raw"),
                (CameraInfo, "/camera/color/camera_info"))]
            joints = node.create_publisher(JointState, "/joint_states", 10)
            scenes = []
            node.create_subscription(ObjectArray, "/scene/objects", scenes.append,
                                     QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL))
            ex = SingleThreadedExecutor()
            ex.add_node(node)
            threading.Thread(target=ex.spin, daemon=True).start()
            info = CameraInfo(width=frame.width, height=frame.height, distortion_model="plumb_bob",
                              k=frame.K.reshape(-1).tolist(), d=[0.0] * 5)
            _started(g, pubs[0])
            deadline = time.monotonic() + 30
            after_first = 0   # frames sent after the first scene: a new unlisted object is published once confirmed
            while True:
                seen = list(scenes)  # one look: a scene that arrives after it is judged at the next one
                if seen and "u1" in {o.id for o in seen[-1].objects}:
                    break
                g.check_alive()
                assert time.monotonic() < deadline, f"no ObjectArray with u1 on /scene/objects ({len(seen)} " \
                    "without):\n" + g.log("perception")
                after_first += bool(seen)
                stamp = node.get_clock().now().to_msg()
                info.header.stamp = stamp
                joints.publish(JointState(name=list(JOINT_NAMES), position=[float(v) for v in Q_HOME]))
                pubs[2].publish(info)
                pubs[0].publish(_image(stamp, *encode_color(frame.rgb)))
                pubs[1].publish(_image(stamp, *encode_depth(frame.depth, "16UC1")))
                time.sleep(0.25)
            print(f"\nu1 published {after_first} frame(s) after the first scene (confirm_frames "
                  f"{node_section(config_file('perception.yaml'), 'perception')['confirm_frames']})")
            assert after_first == 0, g.log("perception")   # no scene before confirm_frames frames: the first holds it
            objects = {o.id: o for o in msg_to_objects(scenes[-1], scenario.ids)}
            u = objects.get("u1")
            assert u is not None and not u.listed, objects
            assert np.hypot(u.x - other.x, u.y - other.y) < 0.01 and "L x 600 kg/m3" in u.weight_note
            assert "unlisted objects: u1" in g.log("perception")
            assert set(scenario.ids) <= set(objects) | {i for i in scenario.ids if vis[i] < 300}
            ex.shutdown()
            node.destroy_node()
        finally:
            rclpy.try_shutdown()
        assert g.stop("perception") == 0
