"""jaco2_sim_driver node as a real process over DDS (loopback, private ROS_DOMAIN_ID): topics, services, safety."""
import math
import signal
import time

import cv2
import numpy as np
import pytest

from ros_procs import REPO, RosGraph

pytestmark = pytest.mark.graph

rclpy = pytest.importorskip("rclpy")
from qtree_relocation_msgs.msg import JointVelocity, ObjectArray  # noqa: E402
from rclpy.qos import QoSDurabilityPolicy, QoSProfile  # noqa: E402
from rosgraph_msgs.msg import Clock  # noqa: E402
from sensor_msgs.msg import CameraInfo, Image, JointState  # noqa: E402
from std_msgs.msg import Float64MultiArray  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402

from stpik_motion_planner.robot_description import FINGER_JOINT_NAMES, JOINT_NAMES, Q_HOME, Q_UPPER, QDOT_MAX  # noqa
from relocation_common.paths import default_scenario
from relocation_common.scenario import load_scenario  # noqa: E402

PARAMS = REPO / "config" / "jaco2_sim_driver.yaml"
MODULE = "jaco2_sim_driver.driver_node"
PRE = "/j2s7s300_driver"
LATCHED = QoSProfile(depth=1, durability=QoSDurabilityPolicy.TRANSIENT_LOCAL)


@pytest.fixture(scope="module")
def graph(tmp_path_factory):
    g = RosGraph(tmp_path_factory.mktemp("driver"))
    try:
        node = g.start(MODULE, params_file=PARAMS, params={"camera_rate": 2.0})
        g.node = node
        g.states = g.probe.collect(f"{PRE}/out/joint_state", JointState)
        g.states.wait(lambda m: len(m) >= 3, timeout=60)
        g.vel = g.probe.publisher(Float64MultiArray, "/velocity_controller/commands")
        g.kin = g.probe.publisher(JointVelocity, f"{PRE}/in/joint_velocity")
        g.probe.wait_for_subscribers(g.vel)
        g.probe.wait_for_subscribers(g.kin)
        # discovery is not symmetric: stream zeros until the node surely matched both publishers
        _stream(g.vel, Float64MultiArray(data=[0.0] * 7), 0.5)
        _stream(g.kin, JointVelocity(), 0.5)
        yield g
        assert node.stop(signal.SIGINT) == 0, node.log()
    finally:
        g.close()


@pytest.fixture
def g(graph):
    res = graph.probe.call(Trigger, f"{PRE}/in/reset_scene")
    assert res.success
    time.sleep(0.1)
    return graph


def _q(msg: JointState) -> np.ndarray:
    return np.array(msg.position[:7])


def _settled_q(g, wait=0.25) -> np.ndarray:
    time.sleep(wait)
    n = len(g.states.msgs)
    return _q(g.states.wait(lambda m: len(m) > n + 1, timeout=5)[-1])


def _stream(pub, msg, duration: float, rate: float = 100.0) -> tuple[float, float]:
    """Publish msg at `rate` for `duration` seconds; returns the wall times of the first and last publish."""
    t0 = time.monotonic()
    k, last = 0, t0
    while True:
        now = time.monotonic()
        if now - t0 > duration:
            return t0, last
        pub.publish(msg)
        last = now
        k += 1
        time.sleep(max(0.0, t0 + k / rate - time.monotonic()))


def test_joint_states_carry_kinova_names_at_home(g):
    msg = g.states.wait(lambda m: len(m) > 0)[-1]
    assert list(msg.name) == list(JOINT_NAMES) + list(FINGER_JOINT_NAMES)
    assert np.allclose(_q(msg), Q_HOME, atol=1e-3)
    js = g.probe.collect("/joint_states", JointState)
    assert list(js.wait(timeout=5)[-1].name)[:7] == list(JOINT_NAMES)


def test_constant_velocity_for_one_second_moves_each_joint_by_v_t(g):
    v = 0.4 * QDOT_MAX * np.array([1, 1, -1, -1, 1, 1, -1])  # joint 4 away from its upper limit
    clock = []  # (wall time received, simulated time): under load the simulator runs slower than the wall
    g.probe.node.create_subscription(Clock, "/clock", lambda m: clock.append(
        (time.monotonic(), m.clock.sec + m.clock.nanosec * 1e-9)), 100)
    q0 = _settled_q(g)
    t0, t1 = _stream(g.vel, Float64MultiArray(data=v.tolist()), 1.0)
    q1 = _settled_q(g, 0.3)
    wall, sim = np.array(clock).T
    assert len(wall) > 50 and np.all(np.diff(sim) >= 0)
    duration = float(np.interp(t1, wall, sim) - np.interp(t0, wall, sim))
    assert 0.3 < duration <= 1.05  # simulated seconds of the 1 s wall-time command window
    moved = v * (duration + 0.05)  # the last command runs until the 50 ms watchdog stops it
    # tolerance: 100 Hz publishing jitter and DDS latency (about 10 ms of motion) plus the loop's rise time
    assert np.allclose(q1 - q0, moved, atol=0.02 + 0.03 * np.abs(moved)), (q1 - q0, moved)


def test_kinova_topic_is_in_degrees_per_second(g):
    q0 = _settled_q(g)
    t0, t1 = _stream(g.kin, JointVelocity(joint7=30.0), 0.5)
    q1 = _settled_q(g, 0.3)
    expected = math.radians(30.0) * (t1 - t0 + 0.05)
    assert q1[6] - q0[6] == pytest.approx(expected, abs=0.02)
    assert np.allclose(q1[:6], q0[:6], atol=0.005)


def test_watchdog_stops_the_arm_when_commands_stop(g):
    g.vel.publish(Float64MultiArray(data=[0.5] * 7))
    time.sleep(0.4)
    n = len(g.states.msgs)
    msgs = g.states.wait(lambda m: len(m) > n + 20, timeout=5)[n:]
    assert max(abs(v) for m in msgs for v in m.velocity[:7]) < 0.01
    assert np.allclose(_q(msgs[0]), _q(msgs[-1]), atol=1e-4)
    assert not np.allclose(_q(msgs[-1]), Q_HOME, atol=0.01)  # it did move before the watchdog stopped it


@pytest.mark.parametrize("bad", [[math.nan] + [0.3] * 6, [0.3] * 6 + [math.inf], [0.3] * 6, [0.3] * 8])
def test_bad_command_changes_nothing_and_node_keeps_running(g, bad):
    q0 = _settled_q(g)
    _stream(g.vel, Float64MultiArray(data=bad), 0.3)
    q1 = _settled_q(g, 0.1)
    assert np.allclose(q1, q0, atol=1e-4)
    assert g.node.alive() and "rejected" in g.node.log()
    _stream(g.vel, Float64MultiArray(data=[0.0] * 6 + [0.5]), 0.2)  # still obeys good commands
    assert _settled_q(g)[6] - q1[6] > 0.05


def test_nan_on_the_kinova_topic_is_rejected(g):
    q0 = _settled_q(g)
    _stream(g.kin, JointVelocity(joint1=float("nan"), joint2=10.0), 0.3)
    assert np.allclose(_settled_q(g, 0.1), q0, atol=1e-4)


def test_joint_limit_holds(g):
    v = np.zeros(7)
    v[3] = QDOT_MAX[3]  # joint 4: 0.25 rad from its upper limit at home
    _stream(g.vel, Float64MultiArray(data=v.tolist()), 0.8)
    q = _settled_q(g, 0.1)
    assert Q_UPPER[3] - 0.03 < q[3] <= Q_UPPER[3] + 1e-3


def test_services(g):
    _stream(g.vel, Float64MultiArray(data=[0.3] * 7), 0.2)
    assert g.probe.call(Trigger, f"{PRE}/in/home").success
    assert np.allclose(_settled_q(g, 0.1), Q_HOME, atol=1e-3)
    res = g.probe.call(Trigger, f"{PRE}/in/gripper_close")
    assert not res.success and "nothing" in res.message
    time.sleep(0.5)
    n = len(g.states.msgs)
    assert min(g.states.wait(lambda m: len(m) > n)[-1].position[7:]) > 0.3  # fingers closed
    assert g.probe.call(Trigger, f"{PRE}/in/gripper_open").success


def test_ground_truth_objects_match_the_scenario(g):
    sc = load_scenario(default_scenario())
    objs = g.probe.collect("/sim/objects", ObjectArray, LATCHED).wait(timeout=10)[-1].objects
    assert [o.id for o in objs] == list(sc.ids)
    for o in objs:
        b = sc.object(o.id)
        assert (o.label, o.weight, o.is_target, o.radius, o.height) == (b.label, b.weight, b.is_target, b.radius,
                                                                         b.height)
        assert np.allclose([o.pose.position.x, o.pose.position.y, o.pose.position.z], [b.x, b.y, sc.shelf.top_z],
                           atol=2e-3)


def test_camera_frame_arrives_with_the_marker_visible(g):
    info = g.probe.collect("/camera/color/camera_info", CameraInfo)
    depth = g.probe.collect("/camera/depth/image_rect_raw", Image)
    rgb = g.probe.collect("/camera/color/image_raw", Image).wait(timeout=15)[-1]
    assert (rgb.encoding, rgb.width, rgb.height) == ("rgb8", 640, 480)
    img = np.frombuffer(bytes(rgb.data), np.uint8).reshape(480, 640, 3)
    det = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50),
                                  cv2.aruco.DetectorParameters())
    _, ids, _ = det.detectMarkers(cv2.cvtColor(img, cv2.COLOR_RGB2GRAY))
    assert ids is not None and 7 in ids.ravel()
    k = np.array(info.wait(timeout=10)[-1].k).reshape(3, 3)
    assert k[0, 0] == pytest.approx(240 / math.tan(math.radians(29)), rel=1e-6)
    d = depth.wait(timeout=10)[-1]
    assert d.encoding == "32FC1"
    dm = np.frombuffer(bytes(d.data), np.float32).reshape(480, 640)
    assert np.all(np.isfinite(dm)) and 0.2 < np.median(dm) < 3.0


def test_sigterm_exits_cleanly(tmp_path):
    with RosGraph(tmp_path) as g2:
        node = g2.start(MODULE, params_file=PARAMS, params={"camera_rate": 0.0})
        g2.probe.collect("/joint_states", JointState).wait(timeout=60)
        assert node.stop(signal.SIGTERM) == 0, node.log()
