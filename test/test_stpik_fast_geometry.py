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


def test_hand_proxy_near_clear_poses_drop_no_contact():
    """Poses 1 cm apart (turning too), as RRT-Connect's motion checks visit them: a pose answered by the clear poses
    kept (HandProxy._near_clear) has no pair in the broad phase, every answer is that of every pair checked with fcl,
    and the clear poses kept answer many poses."""
    sc = load_scenario(resolve_scenario("scenario3_15"))
    scene = CollisionScene(sc)
    hand = HandProxy(0.012)
    near = hand._near_clear
    answered = []

    def checked_near(r, p):  # a pose answered so: no shape's box overlaps an obstacle's (the broad phase's pairs)
        answered.append(near(r, p))
        assert not (answered[-1] and _box_pairs(hand, r, p, hand._clear_obs))
        return answered[-1]

    hand._near_clear = checked_near
    rng = np.random.default_rng(3)
    s = sc.shelf
    hits = poses = 0
    for k in range(60):
        obs = scene.obstacles(frozenset(rng.choice(sc.obstacle_ids, size=k % 4, replace=False)))
        a, b = ([rng.uniform(s.x_front - 0.25, s.x_back), rng.uniform(s.y_min, s.y_max),
                 rng.uniform(s.top_z - 0.05, s.ceiling_z + 0.05), rng.uniform(-0.9, 0.9)] for _ in range(2))
        n = int(np.ceil(max(np.linalg.norm(np.subtract(b[:3], a[:3])), 0.25 * abs(b[3] - a[3])) / 0.01))
        for t in np.linspace(0.0, 1.0, n + 1):
            r, p = pose_matrix(np.add(a, t * np.subtract(b, a)))
            got = hand.collides(r, p, obs)
            assert got == _brute_collides(hand, r, p, obs, None), (k, t)
            hits += got
            poses += 1
    print(f"{poses} poses, {hits} in contact, {sum(answered)} answered by a clear pose kept")
    assert 0.1 * poses < hits < 0.9 * poses  # both answers exercised
    assert sum(answered) > 0.3 * (poses - hits)  # many clear poses answered without the broad phase


def _box_pairs(hand: HandProxy, r, p, obs) -> bool:
    """Whether some shape's box (inflated by its reach) overlaps some obstacle's box: the broad phase has a pair."""
    a, b = (e @ r.T + (p - r[:, 2] * rd.D67) for e in (hand.p0, hand.p1))
    lo, hi = np.minimum(a, b) - hand.reach[:, None], np.maximum(a, b) + hand.reach[:, None]
    return bool(((obs.lo[None] <= hi[:, None]) & (lo[:, None] <= obs.hi[None])).all(axis=2).any())


def test_hand_proxy_near_clear_bound_holds_at_its_edge():
    """Poses turned (about any axis, by up to 0.3 rad) or moved (along an axis, by about the smallest gap of its
    boxes) from a clear pose, near the edge of what HandProxy._near_clear accepts: every pose it accepts has no pair
    in the broad phase."""
    from scipy.spatial.transform import Rotation

    sc = load_scenario(resolve_scenario("scenario3_15"))
    obs = CollisionScene(sc).obstacles()
    hand = HandProxy(0.012)
    rng = np.random.default_rng(4)
    s = sc.shelf
    accepted = with_pairs = 0
    while accepted < 2000:
        r, p = pose_matrix([rng.uniform(s.x_front - 0.25, s.x_back), rng.uniform(s.y_min, s.y_max),
                            rng.uniform(s.top_z - 0.05, s.ceiling_z + 0.05), rng.uniform(-0.9, 0.9)])
        hand._clear_obs = None
        if hand.collides(r, p, obs) or hand._clear_obs is not obs:
            continue  # not a clear pose (a pair in the broad phase)
        smallest = hand._clear[0][3]  # the smallest gap of its shapes' boxes
        for k in range(20):
            if k % 2:  # turned about any axis
                r2, p2 = Rotation.from_rotvec(rng.normal(size=3) * rng.uniform(0.0, 0.3) / 3).as_matrix() @ r, p
            else:  # moved along an axis by about the smallest gap
                r2, p2 = r, p + np.eye(3)[k % 3] * rng.choice([-1.0, 1.0]) * smallest * rng.uniform(0.9, 1.1)
            pairs = _box_pairs(hand, r2, p2, obs)
            with_pairs += pairs
            if hand._near_clear(r2, p2):
                accepted += 1
                assert not pairs, (r2, p2)
    assert with_pairs > 50  # poses tried reach beyond the gaps


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
