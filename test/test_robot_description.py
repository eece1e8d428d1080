"""The one Jaco2 description: DH vs Pinocchio vs MuJoCo FK, Table 6 in the Q convention, a collision-free home."""
import math

import mujoco
import numpy as np
import pinocchio as pin
import pytest

from relocation_common import robot_description as rd
from relocation_common.paths import default_scenario
from relocation_common.scenario import load_scenario
from stpik_motion_planner.model.collision import ArmGeometry, CollisionScene, segment_distance
from stpik_motion_planner.model.kinematics import Kinematics
from stpik_motion_planner.planning.planner import PlannerParams

MJCF = f"""<mujoco><compiler angle="radian"/>\
<default><default class="arm_collision"><geom contype="1" conaffinity="1"/></default></default>
<worldbody>{rd.mjcf_arm_body()}</worldbody></mujoco>"""


def random_q(n, seed=0):
    rng = np.random.default_rng(seed)
    lo = np.maximum(rd.Q_LOWER, -2 * math.pi)
    hi = np.minimum(rd.Q_UPPER, 2 * math.pi)
    return rng.uniform(lo, hi, size=(n, rd.N_JOINTS))


def test_fk_dh_pinocchio_mujoco_agree_on_1000_configurations():
    model = pin.buildModelFromXML(rd.urdf())
    data = model.createData()
    ee = model.getFrameId(rd.EE_LINK)
    mj = mujoco.MjModel.from_xml_string(MJCF)
    md = mujoco.MjData(mj)
    site = mujoco.mj_name2id(mj, mujoco.mjtObj.mjOBJ_SITE, "end_effector")
    qadr = [mj.jnt_qposadr[mujoco.mj_name2id(mj, mujoco.mjtObj.mjOBJ_JOINT, n)] for n in rd.JOINT_NAMES]
    worst = 0.0
    for q in random_q(1000):
        t_dh = rd.dh_fk(q)[-1]
        pin.framesForwardKinematics(model, data, q)
        t_pin = data.oMf[ee]
        md.qpos[qadr] = q
        mujoco.mj_kinematics(mj, md)
        p_mj, r_mj = md.site_xpos[site], md.site_xmat[site].reshape(3, 3)
        worst = max(worst, np.linalg.norm(t_dh[:3, 3] - t_pin.translation), np.linalg.norm(t_dh[:3, 3] - p_mj),
                    np.abs(t_dh[:3, :3] - t_pin.rotation).max(), np.abs(t_dh[:3, :3] - r_mj).max())
    assert worst < 1e-6


def test_table6_limits_hold_in_the_q_convention():
    model = pin.buildModelFromXML(rd.urdf())
    np.testing.assert_allclose(model.lowerPositionLimit, rd.Q_LOWER)
    np.testing.assert_allclose(model.upperPositionLimit, rd.Q_UPPER)
    np.testing.assert_allclose(rd.Q_LOWER[[1, 3, 5]], [0.82, 0.52, 1.13])
    np.testing.assert_allclose(rd.Q_UPPER[[1, 3, 5]], [5.46, 5.76, 5.14])
    # the upright arm (Q = pi everywhere) is inside Table 6 ...
    assert np.all(rd.Q_UPRIGHT >= rd.Q_LOWER) and np.all(rd.Q_UPRIGHT <= rd.Q_UPPER)
    t = rd.dh_fk(rd.Q_UPRIGHT)[-1]
    assert t[2, 3] == pytest.approx(rd.D1 + rd.D23 + rd.D45 + rd.D67, abs=1e-9)  # straight up
    # ... but its DH angle theta2 is 0: applying [0.82, 5.46] to theta2 would forbid the upright pose
    theta = rd.dh_theta(rd.Q_UPRIGHT)
    assert theta[1] == pytest.approx(0.0) and not 0.82 <= theta[1] <= 5.46
    # the mapping of docs/robot.md, "Angle convention"
    q = random_q(1, 3)[0]
    th = rd.dh_theta(q)
    np.testing.assert_allclose(th, [-q[0], q[1] - math.pi, q[2], q[3], q[4], q[5] - math.pi, -q[6] - math.pi / 2])
    mj = mujoco.MjModel.from_xml_string(MJCF)
    for i in (1, 3, 5):
        jid = mujoco.mj_name2id(mj, mujoco.mjtObj.mjOBJ_JOINT, rd.JOINT_NAMES[i])
        np.testing.assert_allclose(mj.jnt_range[jid], [rd.Q_LOWER[i], rd.Q_UPPER[i]])


def test_velocity_limits_are_table7():
    np.testing.assert_allclose(rd.QDOT_MAX, [0.81] * 4 + [1.11] * 3)
    np.testing.assert_allclose(PlannerParams.load().stpik.qdot_max, rd.QDOT_MAX)


def test_velocity_limits_have_one_source():
    """Table 7 is the robot description's: no parameter file under config/ gives joint speed limits a second
    value (the simulator, the planner and the follower read rd.QDOT_MAX)."""
    from relocation_common.config import read_yaml
    from relocation_common.paths import config_dir

    def keys(d):
        for k, v in d.items() if isinstance(d, dict) else ():
            yield str(k)
            yield from keys(v)

    found = [(f.name, k) for f in sorted(config_dir().glob("*.yaml")) for k in keys(read_yaml(f))
             if any(w in k.lower() for w in ("qdot", "velocity_limit", "speed_limit", "max_velocity"))]
    assert found == []


def test_home_is_collision_free_self_and_scene():
    kin = Kinematics()
    arm = ArmGeometry(kin)
    kin.update(rd.Q_HOME)
    arm.pose()
    p = PlannerParams().stpik
    assert np.all(rd.Q_HOME > rd.Q_LOWER + p.joint_margin) and np.all(rd.Q_HOME < rd.Q_UPPER - p.joint_margin)
    for i, j in arm.self_pairs:  # every non-adjacent pair, no broad phase
        d, _, _ = segment_distance(arm.p0[i], arm.p1[i], arm.p0[j], arm.p1[j])
        assert d - arm.radius[i] - arm.radius[j] > p.self_clearance, (arm.specs[i].name, arm.specs[j].name)
    scene = CollisionScene(load_scenario(default_scenario())).obstacles()
    dists = arm.obstacle_distances(scene, d_act=10.0)
    assert len(dists) == len(arm.moving) * len(scene.items)
    assert min(d for _, _, d, _, _ in dists) > p.clearance


def test_self_collision_is_detected_when_folded():
    """The checker can fail: folding the elbow fully brings the wrist and palm down to the base."""
    kin = Kinematics()
    arm = ArmGeometry(kin)
    q = rd.Q_UPRIGHT.copy()
    q[[1, 3, 5]] = (1.4, 5.7, 3.43)
    kin.update(q)
    arm.pose()
    hits = {(arm.specs[i].name, arm.specs[j].name) for i, j, d, _, _ in arm.self_distances(1e-3) if d < 0}
    assert ("base", "wrist") in hits
