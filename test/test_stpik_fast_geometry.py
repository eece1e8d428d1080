"""The fast pieces of STPIK and the collision layer (docs/motion_planner.md, "Performance notes") against
straightforward references: the hand proxy's broad phase drops no contact, capsules posed all at once sit where each
link's placement puts them, and the hierarchy (Eq. 10) with numpy's SVD gufunc equals the textbook recursion bit for
bit."""
import fcl
import numpy as np

from relocation_common import robot_description as rd
from relocation_common.paths import resolve_scenario
from relocation_common.scenario import load_scenario
from stpik_motion_planner.model.collision import HAND_PARTS, ArmGeometry, CollisionScene, HandProxy, _key
from stpik_motion_planner.model.grasp import pose_matrix
from stpik_motion_planner.model.kinematics import Kinematics
from stpik_motion_planner.planning.stpik import hierarchy


def _brute_collides(hand: HandProxy, r, p, obs, skip) -> bool:
    """Every (shape, obstacle) pair with fcl, no broad phase."""
    p7 = p - r[:, 2] * rd.D67
    for s, o in zip(hand.specs, hand.objs):
        o.setTransform(fcl.Transform(r @ s.rot, r @ s.centre + p7))
        for ob in obs.items:
            if skip and _key(ob) in skip.get(s.name, ()) or s.name == "forearm_stub" and ob.name in hand.STUB_IGNORES:
                continue
            if fcl.collide(o, ob.obj, fcl.CollisionRequest(), fcl.CollisionResult()):
                return True
    return False


def test_hand_proxy_broad_phase_drops_no_contact():
    sc = load_scenario(resolve_scenario("scenario3_15"))
    scene = CollisionScene(sc)
    hand = HandProxy(0.012)
    rng = np.random.default_rng(0)
    s = sc.shelf
    hits = 0
    for k in range(1500):
        obs = scene.obstacles(frozenset(rng.choice(sc.obstacle_ids, size=k % 5, replace=False)))
        pose = np.array([rng.uniform(s.x_front - 0.25, s.x_back), rng.uniform(s.y_min, s.y_max),
                         rng.uniform(s.top_z - 0.05, s.ceiling_z + 0.05), rng.uniform(-0.9, 0.9)])
        skip = {n: frozenset([sc.ids[k % len(sc.ids)]]) for n in HAND_PARTS} if k % 2 else None
        r, p = pose_matrix(pose)
        got = hand.collides(r, p, obs, skip)
        assert got == _brute_collides(hand, r, p, obs, skip), (pose, skip)
        hits += got
    assert 200 < hits < 1300  # both answers exercised


def test_capsules_posed_at_once_sit_on_their_links():
    kin = Kinematics()
    arm = ArmGeometry(kin)
    rng = np.random.default_rng(1)
    for _ in range(50):
        kin.update(rng.uniform(rd.Q_LOWER, rd.Q_UPPER), jacobians=False)
        arm.pose()
        for i, s in enumerate(arm.specs):
            r, p = kin.placement(arm.fids[i])
            assert np.allclose(arm.p0[i], r @ s.p0 + p, atol=1e-12, rtol=0)
            assert np.allclose(arm.p1[i], r @ s.p1 + p, atol=1e-12, rtol=0)


def _hierarchy_reference(levels, n, damping):
    """The recursion as first written, before the fast layer (np.linalg.svd, identity products included)."""
    qdot, proj = np.zeros(n), np.eye(n)
    for jac, xd in levels:
        if jac is None:
            return qdot + proj @ (xd - qdot)
        u, s, vt = np.linalg.svd(jac @ proj, full_matrices=False)
        keep = s > 1e-6
        if not np.any(keep):
            continue
        u, s, vt = u[:, keep], s[keep], vt[keep]
        lam2 = damping ** 2 * (1.0 - (s[-1] / damping) ** 2) if s[-1] < damping else 0.0
        qdot = qdot + vt.T @ ((s / (s * s + lam2))[:, None] * u.T) @ (xd - jac @ qdot)
        proj = proj - vt.T @ vt
    return qdot


def test_hierarchy_equals_the_reference_recursion():
    rng = np.random.default_rng(2)
    for k in range(300):
        levels = []
        for _ in range(k % 4):  # set-based levels: a few rows, sometimes rank-deficient or near-singular
            rows = rng.normal(size=(1 + k % 3, 7))
            if k % 5 == 0:
                rows[-1] = rows[0] * (1.0 + 1e-9)
            levels.append((rows, rng.normal(size=len(rows))))
        jt = rng.normal(size=(6, 7)) * (1e-3 if k % 7 == 0 else 1.0)
        levels += [(jt[:3], rng.normal(size=3)), (jt[3:], rng.normal(size=3)), (None, rng.normal(size=7))]
        got, ref = hierarchy(levels, 7, 0.05), _hierarchy_reference(levels, 7, 0.05)
        assert np.array_equal(got, ref), (k, got - ref)
    assert np.array_equal(hierarchy([(np.zeros((2, 7)), np.ones(2)), (None, np.ones(7))], 7, 0.05), np.ones(7))
