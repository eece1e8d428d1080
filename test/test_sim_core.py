"""Core of the simulated Jaco2 (no ROS): scene, velocity control, watchdog, limits, grasp/carry/release, camera."""
import math

import cv2
import mujoco
import numpy as np
import pinocchio as pin
import pytest

from jaco2_sim_driver.camera import intrinsics, render_frame
from jaco2_sim_driver.params import CameraSpec, DriverParams
from jaco2_sim_driver.scene import CAMERA_NAME
from jaco2_sim_driver.sim import BadCommandError, Jaco2Sim
from relocation_common.geometry import rpy_matrix
from relocation_common.paths import default_scenario
from relocation_common.robot_description import EE_LINK, Q_HOME, Q_LOWER, Q_UPPER, QDOT_MAX, urdf
from relocation_common.scenario import load_scenario

SCENARIO = load_scenario(default_scenario())
# hand horizontal, approach +x (towards the shelf), fingers closing along y, finger spread vertical (as Q_HOME)
R_GRASP = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])


@pytest.fixture(scope="module")
def sim():
    return Jaco2Sim(SCENARIO)


@pytest.fixture
def fresh(sim):
    sim.reset()
    return sim


def test_bottles_stand_still_on_the_top_shelf(fresh):
    fresh.step(2000)
    for pose, b in zip(fresh.object_poses(), SCENARIO.objects):
        assert pose.id == b.id
        assert np.allclose(pose.position, (b.x, b.y, SCENARIO.shelf.top_z), atol=1e-3), pose
        assert abs(pose.quat_wxyz[0]) > 0.9999


def test_bottle_mass_is_its_weight(sim):
    for b in SCENARIO.objects:
        assert sim.model.body_mass[sim.model.body(b.id).id] == pytest.approx(b.weight, rel=1e-6)


def test_constant_velocity_moves_each_joint_by_v_t(fresh):
    v = 0.6 * QDOT_MAX * np.array([1, -1, 1, -1, 1, 1, -1])
    q0 = fresh.q
    for _ in range(100):  # 100 Hz for 1 s, as the planner streams
        fresh.set_velocity(v)
        fresh.step(10)
    fresh.stop()
    fresh.step(50)
    # tolerance: the velocity loop's rise time (tau = I / kv, a few ms) costs at most a few mrad
    assert np.allclose(fresh.q - q0, v * 1.0, atol=0.01), fresh.q - q0


def test_commands_are_clamped_to_table_7(fresh):
    for _ in range(20):
        applied = fresh.set_velocity(10 * np.ones(7))
        fresh.step(10)
    assert np.allclose(applied, QDOT_MAX)
    assert np.all(np.abs(fresh.qdot) <= QDOT_MAX + 0.005)  # tracking error of the velocity loop


def test_watchdog_zeroes_velocity_after_50_ms(fresh):
    fresh.set_velocity(0.5 * np.ones(7))
    fresh.step(40)
    assert not fresh.watchdog_tripped and np.allclose(fresh.command, 0.5)
    fresh.step(30)
    assert fresh.watchdog_tripped and np.allclose(fresh.command, 0.0)
    fresh.step(100)
    q = fresh.q
    fresh.step(200)
    assert np.allclose(fresh.q, q, atol=1e-4)


@pytest.mark.parametrize("bad", [[0.1] * 6, [0.1] * 8, [0.1] * 6 + [math.nan], [math.inf] + [0] * 6, "abc"])
def test_bad_command_is_rejected_and_changes_nothing(fresh, bad):
    fresh.set_velocity([0.2] * 7)
    with pytest.raises(BadCommandError):
        fresh.set_velocity(bad)
    assert np.allclose(fresh.command, 0.2)


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_huge_commands_never_leave_tables_6_and_7(fresh, sign):
    """+-1e30 on every joint for 3 s (before the firmware-like limits, joint 3 reached 1.14x Table 7 and
    joint 4 went past Table 6): at every 1 ms step each joint within its velocity and position limits."""
    from relocation_common.robot_description import CONTINUOUS
    limited = ~np.asarray(CONTINUOUS)
    worst_v, worst_p = 0.0, 0.0
    for k in range(3000):
        if k % 10 == 0:
            fresh.set_velocity(sign * 1e30 * np.ones(7))
        fresh.step(1)
        worst_v = max(worst_v, float(np.max(np.abs(fresh.qdot) / QDOT_MAX)))
        q = fresh.q
        worst_p = max(worst_p, float(np.max(np.where(limited, np.maximum(q - Q_UPPER, Q_LOWER - q), 0.0))))
    assert worst_v <= 1.0 + 1e-9 and worst_p <= 1e-9, (worst_v, worst_p)


def test_joint_limit_stop_holds(fresh):
    v = np.zeros(7)
    v[3] = QDOT_MAX[3]  # joint 4 towards its upper limit (0.25 rad away from home)
    for _ in range(100):
        fresh.set_velocity(v)
        fresh.step(10)
    assert Q_UPPER[3] - 0.02 < fresh.q[3] <= Q_UPPER[3] + 1e-3
    assert abs(fresh.qdot[3]) < 0.05


# ----------------------------------------------------------------------------------------------- grasp
_MID_PULL = np.array([0, 1, 0, 1, 0, 1, 0], float)


class _IK:
    """Damped least-squares IK of the tool frame on the description's URDF (Pinocchio)."""

    def __init__(self):
        self.model = pin.buildModelFromXML(urdf())
        self.data = self.model.createData()
        self.frame = self.model.getFrameId(EE_LINK)

    def solve(self, target: pin.SE3, q0: np.ndarray) -> np.ndarray:
        q = q0.copy()
        for _ in range(300):
            pin.framesForwardKinematics(self.model, self.data, q)
            err = pin.log6(self.data.oMf[self.frame].actInv(target)).vector
            if np.linalg.norm(err) < 1e-5:
                return q
            j = pin.computeFrameJacobian(self.model, self.data, q, self.frame, pin.LOCAL)
            j_pinv = j.T @ np.linalg.inv(j @ j.T + 1e-6 * np.eye(6))
            # task step, plus a null-space pull of the limited joints (2, 4, 6) to the middle of their ranges
            q = q + j_pinv @ err + (np.eye(7) - j_pinv @ j) @ (0.05 * _MID_PULL * ((Q_LOWER + Q_UPPER) / 2 - q))
            q = np.clip(q, Q_LOWER + 0.05, Q_UPPER - 0.05)  # stay off the joint limits of Table 6
        raise AssertionError(f"IK did not converge for {target.translation}")

    def path(self, points, q0):
        """Joint waypoints along straight lines through the points (1 cm apart), warm started."""
        qs, q = [], q0
        for a, b in zip(points[:-1], points[1:]):
            n = max(1, int(np.linalg.norm(np.subtract(b, a)) / 0.01))
            for k in range(1, n + 1):
                q = self.solve(pin.SE3(R_GRASP, np.add(a, np.subtract(b, a) * k / n)), q)
                qs.append(q)
        return qs


def _follow(sim: Jaco2Sim, qs, speed=0.5):
    """Track joint waypoints with a saturated P law streamed at 100 Hz (as the planner would)."""
    vmax = speed * QDOT_MAX
    for i, qw in enumerate(qs):
        tol = 0.002 if i == len(qs) - 1 else 0.02
        for _ in range(1000):
            e = qw - sim.q
            if np.max(np.abs(e)) < tol:
                break
            v = 8.0 * e
            v /= max(1.0, float(np.max(np.abs(v) / vmax)))
            sim.set_velocity(v)
            sim.step(10)
        else:
            raise AssertionError(f"waypoint {i} not reached")
    sim.stop()
    sim.step(100)


def test_grasp_carry_release_moves_a_bottle_to_the_bottom_shelf(fresh):
    sim, sh, ik = fresh, SCENARIO.shelf, _IK()
    b = SCENARIO.object("o1")  # front row
    zc = sh.top_z + b.height / 2  # grasp centre half way up the bottle
    place = (SCENARIO.slots[0][0], SCENARIO.slots[0][1], sh.bottom_z + b.height / 2 + 0.005)
    out = sh.x_front - 0.06  # in front of the shelf: the carried bottle clears the top board's front edge
    home, pre = tuple(sim.ee_pose()[:3, 3]), b.x - 0.12
    # to the height of the ceiling board's top, in front of the bottle, down, then straight in
    up = max(home[2], sh.ceiling_z + sh.board_thickness + 0.06)
    q = ik.path([home, (pre, b.y, up), (pre, b.y, zc), (b.x, b.y, zc)], Q_HOME)
    _follow(sim, q)
    assert np.linalg.norm(sim.ee_pose()[:3, 3] - (b.x, b.y, zc)) < 0.005
    assert sim.gripper_close() == "o1"
    sim.step(300)
    carry = [(b.x, b.y, zc), (b.x, b.y, zc + 0.02), (out, b.y, zc + 0.02), (out, place[1], place[2]), place]
    q = ik.path(carry, q[-1])
    _follow(sim, q)
    pose = {p.id: p for p in sim.object_poses()}["o1"]
    assert pose.position[2] > sh.bottom_z and pose.position[0] > sh.x_front  # came along in the hand
    assert sim.gripper_open() == "o1"
    sim.step(400)
    _follow(sim, ik.path([place, (out, place[1], place[2])], q[-1]))
    sim.step(1000)
    pose = {p.id: p for p in sim.object_poses()}["o1"]
    assert np.allclose(pose.position, (place[0], place[1], sh.bottom_z), atol=0.01), pose
    up = np.zeros(9)
    mujoco.mju_quat2Mat(up, np.array(pose.quat_wxyz))
    assert up[8] > 0.995, "the released bottle must stand upright"
    others = {p.id: p.position for p in sim.object_poses() if p.id != "o1"}
    for o in SCENARIO.objects:  # nothing else was disturbed
        if o.id != "o1":
            assert np.allclose(others[o.id], (o.x, o.y, sh.top_z), atol=0.005), o.id


def test_close_on_nothing_grasps_nothing(fresh):
    assert fresh.gripper_close() is None
    fresh.step(500)
    assert fresh.finger_q.min() > 0.3
    assert fresh.gripper_open() is None


def test_reset_restores_the_scenario(fresh):
    fresh.set_velocity(0.5 * np.ones(7))
    fresh.step(40)
    fresh.reset()
    assert np.allclose(fresh.q, Q_HOME) and fresh.time == 0.0 and fresh.grasped is None


# ----------------------------------------------------------------------------------------------- camera
def test_intrinsics_follow_fovy():
    k = intrinsics(90.0, 640, 480)
    assert k[1, 1] == pytest.approx(240.0) and k[0, 0] == k[1, 1] and k[0, 2] == pytest.approx(319.5)


def test_camera_frame_shows_the_marker_where_the_scenario_puts_it():
    frame = render_frame(SCENARIO)
    assert frame.rgb.shape == (480, 640, 3) and frame.depth.shape == (480, 640)
    m = SCENARIO.marker
    det = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, m.dictionary)),
                                  cv2.aruco.DetectorParameters())
    corners, ids, _ = det.detectMarkers(cv2.cvtColor(frame.rgb, cv2.COLOR_RGB2GRAY))
    assert ids is not None and sorted(ids.ravel()) == sorted(mk.id for mk in SCENARIO.markers)
    corners = [corners[list(ids.ravel()).index(m.id)]]  # the main marker (scenario `marker`)
    h = m.size / 2
    obj = np.array([[-h, h, 0], [h, h, 0], [h, -h, 0], [-h, -h, 0]], np.float32)
    ok, rvec, tvec = cv2.solvePnP(obj, corners[0][0], frame.K, None, flags=cv2.SOLVEPNP_IPPE_SQUARE)
    assert ok
    t = frame.T_base_camera
    assert np.linalg.norm(t[:3, :3] @ tvec.ravel() + t[:3, 3] - m.position) < 0.01
    r = t[:3, :3] @ cv2.Rodrigues(rvec)[0]
    assert np.degrees(np.arccos(np.clip((np.trace(r.T @ rpy_matrix(m.rpy)) - 1) / 2, -1, 1))) < 5
    # depth in metres: the depth at the marker centre is the marker's z in the optical frame
    u, v = corners[0][0].mean(axis=0).round().astype(int)
    assert frame.depth[v, u] == pytest.approx(float(tvec[2, 0]), abs=0.01)


@pytest.mark.parametrize("cam,min_pixels", [(CameraSpec.configured(), 250),
                                             (DriverParams.load().replace(camera_relative_to_shelf=True).camera(),
                                              1000)])
def test_every_bottle_is_visible_from_the_camera_with_the_arm_at_home(cam, min_pixels):
    sim = Jaco2Sim(SCENARIO, camera=cam)
    r = mujoco.Renderer(sim.model, cam.height, cam.width)
    try:
        r.enable_segmentation_rendering()
        r.update_scene(sim.data, camera=CAMERA_NAME)
        seg = r.render()
    finally:
        r.close()
    geoms = np.where(seg[:, :, 1] == int(mujoco.mjtObj.mjOBJ_GEOM), seg[:, :, 0], -1)
    for b in SCENARIO.objects:
        assert (geoms == sim.model.geom(f"{b.id}_geom").id).sum() >= min_pixels, b.id


@pytest.mark.parametrize("finger_q", [(0.0, 0.0, 0.0), (0.1, 0.3, 0.45), (0.5, 0.5, 0.5)])
def test_the_published_urdf_fingers_are_the_simulated_ones(fresh, finger_q):
    """urdf(hand=True) is what /robot_description publishes; frames.finger_transforms is the driver's
    robot_state_publisher for it. The finger links sit on MuJoCo's finger bodies, their tips at the ends of MuJoCo's
    finger capsules, and Pinocchio reading that URDF at the joint states' finger angles (Kinova's, 1.396 rad
    closed; the mimic gear joints at their multiplier) puts them there too (away from home, open to closed)."""
    from jaco2_sim_driver import frames, kinova
    from relocation_common.kinova import turns_to_joint
    from relocation_common.robot_description import (
        FINGER_DRIVE_LINK_NAMES,
        FINGER_GEAR,
        FINGER_GEAR_JOINT_NAMES,
        FINGER_JOINT_NAMES,
        FINGER_LINK_NAMES,
        FINGER_TIP_LINK_NAMES,
        JOINT_NAMES,
        LINK_NAMES,
    )

    m, d = fresh.model, fresh.data
    q = Q_HOME + np.array([0.3, -0.2, 0.4, -0.3, 0.5, 0.2, -0.6])
    for name, v in zip(JOINT_NAMES + FINGER_JOINT_NAMES, tuple(q) + finger_q):
        d.qpos[m.joint(name).qposadr[0]] = v
    mujoco.mj_kinematics(m, d)
    hand = frames.chain(q)[LINK_NAMES[-1]]
    published = {child: t for _, child, t in frames.finger_transforms(finger_q)}
    model = pin.buildModelFromXML(urdf(hand=True))
    data = model.createData()
    cfg = pin.neutral(model)
    joint_states = turns_to_joint(kinova.sim_to_turns(finger_q))  # what the driver publishes for the fingers
    assert np.allclose(joint_states * FINGER_GEAR, finger_q)
    gears = tuple((FINGER_GEAR - 1) * joint_states)  # the URDF's mimic joints, as robot_state_publisher sets them
    names = JOINT_NAMES + FINGER_JOINT_NAMES + FINGER_GEAR_JOINT_NAMES
    for name, v in zip(names, tuple(q) + tuple(joint_states) + gears):
        cfg[model.joints[model.getJointId(name)].idx_q] = v
    pin.framesForwardKinematics(model, data, cfg)
    for k, link in enumerate(FINGER_LINK_NAMES):
        body = m.body(link).id
        finger = hand @ published[FINGER_DRIVE_LINK_NAMES[k]] @ published[link]
        assert np.allclose(finger[:3, 3], d.xpos[body], atol=1e-9)
        assert np.allclose(finger[:3, :3], d.xmat[body].reshape(3, 3), atol=1e-9)
        geom = m.geom(f"finger_sim_{k + 1}").id  # capsule from the hinge to the tip: centre halfway
        tip = (finger @ published[FINGER_TIP_LINK_NAMES[k]])[:3, 3]
        assert np.allclose(tip, 2 * d.geom_xpos[geom] - d.xpos[body], atol=1e-9)
        assert np.allclose(data.oMf[model.getFrameId(link)].homogeneous, finger, atol=1e-9)
        assert np.allclose(data.oMf[model.getFrameId(FINGER_TIP_LINK_NAMES[k])].translation, tip, atol=1e-9)
