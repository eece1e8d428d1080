"""jaco2_sim_driver node as a real process over DDS (loopback, private ROS_DOMAIN_ID): topics, services, safety.

Every test runs against each surface (command_interface kinova, the default, then ros2_control; one driver process
at a time) or is skipped where it is one surface's: the kinova topic's units and HomeArm, the ros2_control command's
length checks. The fingers action, Stop and Start, TF and the robot description: test_kinova_surface.py."""
import math
import signal
import time

import cv2
import numpy as np
import pytest
from ros_procs import REPO, RosGraph

pytest.importorskip("rclpy")
from kinova_msgs.msg import JointVelocity
from kinova_msgs.srv import HomeArm
from qtree_relocation_msgs.msg import ObjectArray
from rclpy.qos import QoSDurabilityPolicy, QoSProfile
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import CameraInfo, Image, JointState
from std_msgs.msg import Float64MultiArray
from std_srvs.srv import Trigger

from jaco2_sim_driver.driver import MAX_LAG
from relocation_common.paths import default_scenario
from relocation_common.robot_description import FINGER_JOINT_NAMES, JOINT_NAMES, Q_HOME, Q_UPPER, QDOT_MAX
from relocation_common.ros_conversions import msg_to_objects
from relocation_common.scenario import load_scenario

pytestmark = pytest.mark.graph

PARAMS = REPO / "config" / "jaco2_sim_driver.yaml"
MODULE = "jaco2_sim_driver.driver_node"
PRE = "/j2s7s300_driver"
LATCHED = QoSProfile(depth=1, durability=QoSDurabilityPolicy.TRANSIENT_LOCAL)


@pytest.fixture(scope="module", params=["kinova", "ros2_control"])
def graph(request, tmp_path_factory):
    """One driver process per surface (one at a time: two simulators at once slowed each other on 2 cores)."""
    kinova = request.param == "kinova"
    g = RosGraph(tmp_path_factory.mktemp(f"driver_{request.param}"))
    try:
        node = g.start(MODULE, params_file=PARAMS, params={"camera_rate": 2.0 if kinova else 0.0,
                                                           "command_interface": request.param,
                                                           "sim_time_stamps": True})  # stamps in simulated time
        g.node, g.surface = node, request.param
        g.states = g.probe.collect(f"{PRE}/out/joint_state" if kinova else "/joint_states", JointState)
        g.states.wait(lambda m: len(m) >= 3, timeout=60)
        if kinova:
            g.pub = g.probe.publisher(JointVelocity, f"{PRE}/in/joint_velocity")
        else:
            g.pub = g.probe.publisher(Float64MultiArray, "/velocity_controller/commands")
        g.probe.wait_for_subscribers(g.pub)
        # discovery is not symmetric: stream zeros until the node surely matched the publisher
        _stream(g.pub, _cmd(g, np.zeros(7)), 0.5)
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


def _only(g, surface: str) -> None:
    if g.surface != surface:
        pytest.skip(f"{surface} surface only")


def _cmd(g, v):
    """The surface's velocity command for joint velocities v (rad/s)."""
    if g.surface == "kinova":
        return _deg(v)
    return Float64MultiArray(data=[float(x) for x in v])


def _deg(v) -> JointVelocity:
    """kinova_msgs/JointVelocity (deg/s) of joint velocities in rad/s."""
    d = np.degrees(np.asarray(v, float))
    return JointVelocity(**{f"joint{i + 1}": float(d[i]) for i in range(7)})


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
    tips = [f"j2s7s300_joint_finger_tip_{i}" for i in (1, 2, 3)]  # kinova-ros lists them, always 0
    assert list(msg.name) == list(JOINT_NAMES) + list(FINGER_JOINT_NAMES) + (tips if g.surface == "kinova" else [])
    assert np.allclose(_q(msg), Q_HOME, atol=1e-3)


def _stamp(m) -> float:
    return m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec


def _speed_run(msgs, v) -> tuple[float, np.ndarray]:
    """(simulated seconds, displacement) over consecutive joint states both moving at about v, by their stamps
    (simulated time: the driver runs with sim_time_stamps). A command stream that falls more than 50 ms behind on a
    loaded machine lets the watchdog stop the arm in between: those pauses do not count."""
    msgs, on = sorted(msgs, key=_stamp), np.asarray(v) != 0  # joints commanded to move
    moving = [bool(np.all(np.abs(np.array(m.velocity[:7]))[on] > 0.9 * np.abs(v)[on])) for m in msgs]
    duration, moved = 0.0, np.zeros(7)
    for k in range(len(msgs) - 1):
        if moving[k] and moving[k + 1]:
            duration += _stamp(msgs[k + 1]) - _stamp(msgs[k])
            moved += _q(msgs[k + 1]) - _q(msgs[k])
    return duration, moved


def _motion(g, n: int) -> tuple[float, float, float]:
    """The arm's one motion after state n, by the driver's stamps: (simulated s from the last state at rest before it
    to the first at rest after it, simulated s from its first moving state to that one, the test's receive time of
    that state at rest)."""
    timed = sorted(g.states.timed()[n:], key=lambda tm: _stamp(tm[1]))
    moving = [k for k, (_, m) in enumerate(timed) if np.max(np.abs(m.velocity[:7])) > 1e-3]
    rest = next(k for k in range(moving[-1] + 1, len(timed)) if np.max(np.abs(timed[k][1].velocity[:7])) <= 1e-3)
    before, first, stop = timed[moving[0] - 1][1], timed[moving[0]][1], timed[rest][1]
    return _stamp(stop) - _stamp(before), _stamp(stop) - _stamp(first), timed[rest][0]


def test_constant_velocity_for_one_second_moves_each_joint_by_v_t(g):
    for attempt in range(3):  # a machine so loaded that the simulation ran < 0.3 s of the window: another window
        v = (-1) ** attempt * 0.4 * QDOT_MAX * np.array([1, 1, -1, -1, 1, 1, -1])  # joint 4 away from its upper limit
        q0 = _settled_q(g)
        n = len(g.states.msgs) - 5  # from a few states at rest
        t0, t1 = _stream(g.pub, _cmd(g, v), 1.0)
        q1 = _settled_q(g, 0.3)
        duration, moved = _speed_run(g.states.wait()[n:], v)
        if duration > 0.3:
            break
    assert duration > 0.3, duration  # simulated seconds at speed, of the 1 s wall-time command window
    # tolerance: the rise time of the velocity loop (a few ms of motion)
    assert np.allclose(moved, v * duration, atol=0.005 + 0.02 * np.abs(v * duration)), (moved, v * duration)
    # all of it, by the driver's stamps: no joint outran its command between the states at rest either side
    span, moving, stopped_seen = _motion(g, n)
    assert np.all(np.abs(q1 - q0) <= np.abs(v) * span + 0.01), (q1 - q0, v * span)
    # and the simulation did not run ahead of the wall: the motion began after the first publish, its stop was
    # published before the test received it, and the pacing catches up at most MAX_LAG. Bounded by these causal
    # times, not by the publisher's window plus the watchdog: a last command delivered late or a simulation behind
    # the wall at the stream's end moves the arm longer (0.353 rad against 0.347 allowed at a load of 4-5). The
    # watchdog's own bound, from the stamps: test_kinova_surface's test_the_arm_stops_within_50_ms_when_commands_stop.
    assert moving <= stopped_seen - t0 + MAX_LAG, (moving, stopped_seen - t0)


def test_kinova_topic_is_in_degrees_per_second(g):
    _only(g, "kinova")
    q0 = _settled_q(g)
    n = len(g.states.msgs) - 5
    _stream(g.pub, JointVelocity(joint7=30.0), 0.5)
    q1 = _settled_q(g, 0.3)
    v = np.array([0.0] * 6 + [math.radians(30.0)])
    duration, moved = _speed_run(g.states.wait()[n:], v)
    assert duration > 0.1 and moved[6] == pytest.approx(v[6] * duration, rel=0.03)  # 30 deg/s = 0.52 rad/s
    assert np.allclose(q1[:6], q0[:6], atol=0.005)


def test_clock_is_the_simulated_time_of_the_stamps(g):
    clock = g.probe.collect("/clock", Clock, 100).wait(lambda m: len(m) > 5, timeout=5)[-1]
    assert abs(clock.clock.sec + 1e-9 * clock.clock.nanosec - _stamp(g.states.latest())) < 0.5


def test_watchdog_stops_the_arm_when_commands_stop(g):
    g.pub.publish(_cmd(g, [0.5] * 7))
    time.sleep(0.4)
    n = len(g.states.msgs)
    msgs = g.states.wait(lambda m: len(m) > n + 20, timeout=5)[n:]
    assert max(abs(v) for m in msgs for v in m.velocity[:7]) < 0.01
    assert np.allclose(_q(msgs[0]), _q(msgs[-1]), atol=1e-4)
    assert not np.allclose(_q(msgs[-1]), Q_HOME, atol=0.01)  # it did move before the watchdog stopped it


@pytest.mark.parametrize("bad", [[math.nan] + [0.3] * 6, [0.3] * 6 + [math.inf], [0.3] * 6, [0.3] * 8])
def test_bad_command_changes_nothing_and_node_keeps_running(g, bad):
    _only(g, "ros2_control")  # a kinova_msgs/JointVelocity always has 7 values: test_nan_on_the_kinova_topic
    q0 = _settled_q(g)
    _stream(g.pub, Float64MultiArray(data=bad), 0.3)
    q1 = _settled_q(g, 0.1)
    assert np.allclose(q1, q0, atol=1e-4)
    assert g.node.alive() and "rejected" in g.node.log()
    for _ in range(10):  # still obeys good commands (0.1 rad a window when the simulation keeps the wall's pace)
        _stream(g.pub, Float64MultiArray(data=[0.0] * 6 + [0.5]), 0.2)
        if _settled_q(g)[6] - q1[6] > 0.05:
            break
    assert _settled_q(g)[6] - q1[6] > 0.05


def _rss_mib(pid: int) -> float:
    for line in open(f"/proc/{pid}/status"):
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return math.nan


def _state_rates(reports: list) -> list[tuple[float, float]]:
    """(sim time, joint state rate per simulated s) of each of the driver's /diagnostics reports, in order."""
    out = []
    for msg in reports:
        for st in msg.status:
            if st.name == "jaco2_sim_driver: arm":
                v = {kv.key: kv.value for kv in st.values}
                out.append((float(v["sim time (s)"]), float(v["joint state rate (per simulated s)"])))
    return out


def _rates_while(reports, stream) -> list[float]:
    """The driver's joint state rates of the report periods that began after `stream()` started (`_state_rates`)."""
    start = _state_rates(reports.wait())[-1][0]
    stream()
    return [r for t, r in _state_rates(reports.wait()) if t > start + 1.0]


def test_8_mb_commands_are_refused_unread(g):
    """150 commands of 1M values (8 MB) in 3 s (before the size check the driver went from 245 to 351 MiB and its
    joint-state rate halved): refused before deserialization, the arm holds still, memory and the state rate stay.
    The rate is the driver's own (its /diagnostics, per simulated second over each report's period): counted from
    the states this process received, it fell with this process's own starvation while it serialised 400 MB/s (25 of
    100 a second received at a load of 1-2, 51 at 6). It is held against the rate while this process serialises the
    same stream to a topic the driver does not read: against the rate before the stream, a fresh clone at a load of 8
    failed with 65 of 94 a second, this process's own 400 MB/s on the 2 cores. The two streams alternate three times
    and the medians of their reports are compared: one 3 s window of each, one after the other, compared by their
    slowest second at a load of 10-12, failed with [78, 63, 67] against [92, 94] a second, while the driver's own
    threads spent 0.1-0.2 CPU-s more in 3 s on the refused stream (its shared-memory transport and the raw take):
    windows of the control stream alone ranged 56-88 a second there."""
    from diagnostic_msgs.msg import DiagnosticArray

    _only(g, "ros2_control")
    reports = g.probe.collect("/diagnostics", DiagnosticArray, 50)
    q0 = _settled_q(g)
    rss0 = _rss_mib(g.node.pid)
    reports.wait(lambda m: len(_state_rates(m)) >= 3, timeout=30)  # two full periods after the reset's
    huge = Float64MultiArray(data=np.full(1_000_000, 0.3))
    unread = g.probe.publisher(Float64MultiArray, "/unread_by_the_driver")
    control: list[float] = []
    during: list[float] = []
    for _ in range(3):
        control += _rates_while(reports, lambda: _stream(unread, huge, 3.0, rate=50.0))
        during += _rates_while(reports, lambda: _stream(g.pub, huge, 3.0, rate=50.0))
    rss1 = _rss_mib(g.node.pid)
    print(f"\njoint states per simulated s {[round(r) for r in control]} while the same stream went to a topic the "
          f"driver does not read, {[round(r) for r in during]} to its commands (the driver's reports); driver RSS "
          f"{rss0:.0f} -> {rss1:.0f} MiB")
    assert np.allclose(_settled_q(g, 0.1), q0, atol=1e-4)
    assert "bytes serialized" in g.node.log() and g.node.alive()
    assert control and during and np.median(during) > 0.7 * np.median(control), (control, during)
    assert rss1 - rss0 < 55, (rss0, rss1)  # old: +84 MiB; new: +31 (DDS)


def test_nan_on_the_kinova_topic_is_rejected(g):
    _only(g, "kinova")
    q0 = _settled_q(g)
    _stream(g.pub, JointVelocity(joint1=float("nan"), joint2=10.0), 0.3)
    assert np.allclose(_settled_q(g, 0.1), q0, atol=1e-4)


def test_joint_limit_holds(g):
    v = np.zeros(7)
    v[3] = QDOT_MAX[3]  # joint 4: 0.25 rad from its upper limit at home
    _stream(g.pub, _cmd(g, v), 1.5)  # 0.3 s would do; late commands on a loaded machine pause the arm
    q = _settled_q(g, 0.1)
    assert Q_UPPER[3] - 0.03 < q[3] <= Q_UPPER[3] + 1e-3


def test_home_arm_moves_the_arm_home(g):
    """Kinova's HomeArm moves the arm (it was a teleport: no joint state between the pose and home) at most at
    HOME_SPEED of Table 7, answers once home, then the fingers are open."""
    from jaco2_sim_driver.driver import HOME_SPEED

    _only(g, "kinova")
    for _ in range(10):  # 0.09 rad a window when the commands come on time; late ones pause the arm (watchdog)
        _stream(g.pub, _deg([0.3] * 7), 0.3)
        q0 = _settled_q(g, 0.1)
        e0 = np.max(np.abs(q0 - Q_HOME))
        if e0 > 0.05:
            break
    assert e0 > 0.05
    n = len(g.states.msgs)
    assert g.probe.call(HomeArm, f"{PRE}/in/home_arm", timeout=40).homearm_result == \
        "KINOVA ARM HAS BEEN RETURNED HOME"
    assert np.allclose(_settled_q(g, 0.1), Q_HOME, atol=1e-3)
    assert max(g.states.latest().position[7:10]) < 0.05  # fingers open
    msgs = sorted(g.states.msgs[n:], key=_stamp)
    between = [m for m in msgs if 0.1 * e0 < np.max(np.abs(_q(m) - Q_HOME)) < 0.9 * e0]
    assert len(between) >= 10, len(between)  # a motion through the poses in between
    speed = max(np.max(np.abs(np.array(m.velocity[:7])) / QDOT_MAX) for m in msgs)
    assert speed <= HOME_SPEED * 1.1, speed


def test_ground_truth_objects_match_the_scenario(g):
    sc = load_scenario(default_scenario())
    objs = msg_to_objects(g.probe.collect("/sim/objects", ObjectArray, LATCHED).wait(timeout=10)[-1], sc.ids)
    assert [o.id for o in objs] == list(sc.ids)
    for o in objs:
        b = sc.object(o.id)
        assert (o.label, o.rgb, o.weight, o.is_target, o.radius, o.height, o.shape, o.listed, o.lying) == \
            (b.label, b.rgb, b.weight, b.is_target, b.radius, b.height, b.shape, b.listed, b.lying)
        assert np.allclose([o.x, o.y, o.support_z], [b.x, b.y, sc.shelf.top_z], atol=2e-3)


def test_camera_frame_arrives_with_the_marker_visible(g):
    _only(g, "kinova")  # the camera runs in the kinova process only (camera_rate 0 in the other)
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
        g2.probe.collect(f"{PRE}/out/joint_state", JointState).wait(timeout=60)
        assert node.stop(signal.SIGTERM) == 0, node.log()
