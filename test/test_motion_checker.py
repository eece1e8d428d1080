"""Every planned motion of the demo sequence of every shipped scene, replayed in the project's MuJoCo model by an
independent checker (test/motion_checker.py): nothing touches anything it is not meant to touch.

The demo sequence of a scene is its exact optimum (qtree_task_planner.search.exact.solve with the real planner as the
oracle): each obstacle of it, then the target, relocated in that order with relocation.plan_relocation (pick,
carry, retreat, home planned before the arm would move). Also: a sample of feasibility answers (picks), scenes with
bottles of other sizes, and the slots and planning errors of the carried bottle
(docs/motion_planner.md, "The carried bottle", "Slots").
"""
import dataclasses
import math

import numpy as np
import pytest
from motion_checker import MotionChecker, Report, replay_relocation

from qtree_task_planner.search.exact import solve
from relocation_common import robot_description as rd
from relocation_common.feasibility import Label
from relocation_common.paths import scenarios_dir
from relocation_common.scenario import load_scenario, parse_scenario
from stpik_motion_planner.execution.relocation import plan_relocation, relocate
from stpik_motion_planner.model.grasp import WorkspaceError
from stpik_motion_planner.planning.planner import MotionPlanner, PlannerParams, PlanningError

PARAMS = PlannerParams.load()
ARM_CLEARANCE = PARAMS.stpik.clearance - 0.002  # the planner's bound less the interpolation between IK samples
CARRIED_CLEARANCE = PARAMS.carried_clearance - 0.002
SCENES = sorted(p for p in scenarios_dir().glob("*.yaml") if not p.stem.startswith("blocking_"))
RANDOM = sorted((scenarios_dir() / "random5").glob("*.yaml"))
TOTAL = Report()  # over the module, for the summary line


def planner_for(scenario):
    # answers must not depend on machine load: wall-clock safety nets (reached, the query raises) of 300 s instead of
    # config/motion_planner.yaml's 10 s (a home plan took over 30 s next to other jobs); the work budgets, which
    # decide the answers, are the planner's
    return MotionPlanner(scenario, dataclasses.replace(PARAMS, timeout=300.0, carry_timeout=300.0))


def check_sequence(scenario, planner, sequence) -> Report:
    checker = MotionChecker(scenario)
    rep = Report()
    done = []
    for oid in sequence:
        plan = plan_relocation(planner, oid, done)
        rep.merge(replay_relocation(checker, plan.pick, [plan.carry, plan.retreat], plan.home, oid))
        done.append(oid)
    return rep


def assert_clean(rep: Report, what: str) -> None:
    print(f"{what}: {rep.summary()}")
    TOTAL.merge(rep)
    assert rep.contacts == [], "\n".join(map(str, rep.contacts))
    assert rep.min_arm >= ARM_CLEARANCE, rep.min_arm_at
    assert rep.min_carried >= CARRIED_CLEARANCE, rep.min_carried_at
    assert rep.support_depth <= 0.001


# the default run: the demo scene and the smallest one; every scene with -m extended
DEMO_DEFAULT = ("paper_experiment_10", "scenario1_5")
DEMO_CASES = [p if p.stem in DEMO_DEFAULT else pytest.param(p, marks=pytest.mark.extended) for p in SCENES + RANDOM]


@pytest.mark.parametrize("path", DEMO_CASES, ids=lambda p: p.stem)
def test_demo_sequence_touches_nothing_but_the_grasped_bottle(path):
    scenario = load_scenario(path)
    planner = planner_for(scenario)
    result = solve(scenario, planner)
    assert result.found, scenario.name
    rep = check_sequence(scenario, planner, result.sequence)
    assert rep.segments == 4 * len(result.sequence)
    assert_clean(rep, f"{scenario.name} {'-'.join(result.sequence)}")


PAPER_SIZE = ("paper1_5", "paper2_10", "paper3_15")  # scenes of the paper's size (docs/evaluation.md)
PAPER_RANDOM = tuple(f"paper_random5/{p.stem}" for p in sorted((scenarios_dir() / "paper_random5").glob("*.yaml")))
# Plannings of a paper scene's optimum after the first, in the same process: a pick that fails in 5 of 12
# plannings (paper2_10's T at 0.902, before it moved 10 mm forward; here it failed at the 5th) passes 11 in a row
# 0.3 % of the time
REPLANS = 10
# (scene, plannings again): the default run has one random case planned once again; -m extended every paper-size
# scene with REPLANS and every random case twice (Table 4's random cases: six plannings in a row)
OPTIMUM_CASES = [(PAPER_RANDOM[0], 1), pytest.param(PAPER_RANDOM[0], 2, marks=pytest.mark.extended),
                 *(pytest.param(n, REPLANS, marks=pytest.mark.extended) for n in PAPER_SIZE),
                 *(pytest.param(n, 2, marks=pytest.mark.extended) for n in PAPER_RANDOM[1:])]


@pytest.mark.parametrize("name, replans", OPTIMUM_CASES, ids=lambda v: f"x{v}" if isinstance(v, int) else v)
def test_the_optimum_of_each_paper_scene_table_touches_nothing(name, replans):
    """The optimum the evaluation reports (exact.solve over the committed feasibility table, the answers of a fill
    in its own process) relocated in order: the demo-sequence test above asks a planner whose OMPL stream depends
    on the queries run before it in this process (stpik_motion_planner/planning/rrt.py), so it may solve another
    sequence."""
    from relocation_app.evaluation.__main__ import planner_params
    from relocation_app.evaluation.feasibility_cache import PlannerOracle, open_table
    from relocation_app.evaluation.scenes import screening
    from relocation_common.paths import data_dir
    scenario = load_scenario(name)
    table, path = open_table(scenario, planner_params(), data_dir() / "feasibility")
    assert len(table) > 0, f"no feasibility table {path.name}"
    oracle = PlannerOracle(scenario, planner_params(), table)
    result = solve(scenario, oracle)
    assert result.found and oracle.real_calls == 0, name  # the table is complete
    planner = planner_for(scenario)
    rep = check_sequence(scenario, planner, result.sequence)
    assert rep.segments == 4 * len(result.sequence)
    assert_clean(rep, f"{name} table optimum {'-'.join(result.sequence)}")
    # the same planner again: its OMPL stream has moved on, as a demo's planner's has
    assert screening.replans(planner, result.sequence, replans) == "", name


def test_the_blocking_scenes_are_not_relocation_scenes():
    """blocking_*.yaml are test scenes of the Q-Tree layer (BlockingOracle) on the first shelf geometry, which the
    arm does not reach: the real planner frees no target there, so no demo runs on them."""
    for path in sorted(scenarios_dir().glob("blocking_*.yaml")):
        scenario = load_scenario(path)
        assert not solve(scenario, planner_for(scenario)).found, scenario.name


@pytest.mark.parametrize("name", ["paper_experiment_10", pytest.param("scenario3_15", marks=pytest.mark.extended),
                                  pytest.param("random5/random5_04", marks=pytest.mark.extended)])
def test_a_sample_of_feasibility_answers_touches_nothing(name):
    """Every object of a scene asked with no object removed and with each prefix of the demo sequence removed;
    every feasible answer's trajectory (home -> pre-grasp -> grasp) replayed. The default run asks the demo scene;
    -m extended two more."""
    rep, answers = Report(), 0
    scenario = load_scenario(name)
    planner = planner_for(scenario)
    seq = solve(scenario, planner).sequence
    for k in range(len(seq)):
        removed = frozenset(seq[:k])
        for oid in scenario.ids:
            if oid in removed:
                continue
            ans = planner.feasibility(oid, removed)
            if ans.label == Label.UNFEASIBLE:
                continue
            answers += 1
            c = MotionChecker(scenario)
            _move_to_slots(c, scenario, seq[:k])  # the relocated ones stand in their slots
            rep.merge(c.check(ans.trajectory, f"{name}:{oid}|{','.join(sorted(removed))}", picking=oid,
                              approach_from=dict(ans.trajectory.phases)["approach"]))
    assert answers >= 5
    assert_clean(rep, f"{name}: {answers} feasibility answers")


def _move_to_slots(checker, scenario, relocated):
    import mujoco
    for k, oid in enumerate(relocated):
        a = checker._free[oid]
        x, y = scenario.slot(k)
        checker.data.qpos[a:a + 3] = (x, y, scenario.shelf.bottom_z)
    mujoco.mj_kinematics(checker.model, checker.data)


def test_the_checker_sees_a_bottle_pushed_into_its_board():
    """The checker is not blind: the hand lowered by 1 cm after the grasp (the planner without the bottle in its
    model) drives the bottle 1 cm into the top board, which the checker reports, and the true carry does not."""
    scenario = load_scenario("paper_experiment_10")
    planner = planner_for(scenario)
    (pick,) = planner.plan_pick("o2", [])
    q = pick.trajectory.positions[-1]
    planner.kin.update(q, jacobians=False)
    rot, pos = planner.kin.tool_pose()
    start = np.array([*pos, math.atan2(rot[1, 2], rot[0, 2])])
    obs = planner.scene.obstacles({"o2"})
    down = planner.stpik.track(q, [start, start - [0, 0, 0.01, 0]], obs, math.inf, speed=0.05)
    assert down.ok, down.reason
    from stpik_motion_planner.planning.trajectory import Trajectory
    checker = MotionChecker(scenario)
    checker.check(pick.trajectory, "pick", picking="o2", approach_from=dict(pick.trajectory.phases)["approach"])
    checker.grasp("o2")
    checker.support_band = 0.0  # no lift exemption: every contact with the board counts
    rep = checker.check(Trajectory.from_steps(down.q, down.qdot, down.dt, "down").resample(), "down")
    deepest = {(c.geom1, c.geom2): -c.distance for c in rep.contacts}
    assert deepest.get(("o2_geom", "shelf_top_board"), 0.0) == pytest.approx(0.01, abs=0.002), rep.contacts


# ------------------------------------------------------------------ bottle sizes
SHELF = {"x_front": 0.62, "depth": 0.36, "width": 0.8, "board_thickness": 0.02, "top_z": 0.02,
         "ceiling_z": 0.28, "bottom_z": -0.18}
MARKER = {"id": 7, "size": 0.07, "position": [0.625, -0.345, 0.09], "rpy": [1.5708, 0, -1.5708]}


def sized_scene(sizes, slots="auto"):
    """One bottle per (radius, height) in the front row, 0.14 m apart, the last one the target."""
    objects = [{"id": f"b{k}", "weight": 0.5, "xy": [0.70, -0.14 * (len(sizes) - 1) / 2 + 0.14 * k], "radius": r,
                "height": h} for k, (r, h) in enumerate(sizes)]
    return parse_scenario({"shelf": SHELF, "objects": objects, "target": objects[-1]["id"], "marker": MARKER,
                           "slots": slots})


@pytest.mark.parametrize("sizes", [[(0.025, 0.13), (0.033, 0.16), (0.030, 0.14)],
                                   pytest.param([(0.028, 0.15), (0.032, 0.13), (0.026, 0.125)],
                                                marks=pytest.mark.extended)], ids=["mixed1", "mixed2"])
def test_bottles_of_every_size_are_carried_at_their_size(sizes):
    """Sizes the hand can grasp from the side (mid-height >= 0.065 m keeps the palm 15 mm above the board, radius <=
    0.033 m fits between the open fingers) and the bottom compartment can take (<= 0.162 m here)."""
    scenario = sized_scene(sizes)
    planner = planner_for(scenario)
    rep = check_sequence(scenario, planner, scenario.ids)
    assert_clean(rep, f"sizes {sizes}")
    assert rep.min_carried < 0.02  # the real size: in the bottom compartment it passes within 2 cm of a board


def test_a_bottle_too_tall_for_the_bottom_shelf_is_not_picked():
    """0.18 m between the bottom and the top board: a 0.17 m bottle fits on the top shelf but cannot be carried
    in keeping its clearance; it is answered UNFEASIBLE (it could be grasped, not relocated)."""
    scenario = sized_scene([(0.033, 0.17), (0.033, 0.16)])
    planner = planner_for(scenario)
    ans = planner.feasibility("b0", frozenset())
    assert ans.label == Label.UNFEASIBLE and "bottom compartment" in ans.message, ans.message
    assert planner.feasibility("b1", frozenset()).label == Label.TARGET
    with pytest.raises(PlanningError, match="bottom compartment"):
        plan_relocation(planner, "b0", [])


# ------------------------------------------------------------------ slots and planning errors
@pytest.mark.parametrize("path", SCENES, ids=lambda p: p.stem)
def test_every_shipped_slot_is_within_reach(path):
    scenario = load_scenario(path)
    assert planner_for(scenario).slot_problems() == []


def test_auto_slots_follow_the_reachable_layout_and_an_unreachable_shelf_is_refused():
    s = load_scenario("scenario3_15")
    assert s.auto_slots and len(s.slots) == 12 < len(s.objects)  # the shelf holds 12 slots 0.12 m apart
    assert s.slots[:2] == ((0.76, -0.06), (0.76, 0.06))  # back row, central slots first, as paper_experiment_10
    far = dict(SHELF, x_front=0.80, depth=0.40)
    scenario = parse_scenario({"shelf": far, "objects": [{"id": "T", "xy": [0.90, 0.0]}], "target": "T",
                               "marker": MARKER, "slots": "auto"})
    with pytest.raises(WorkspaceError, match="slots 'auto' gives .* out of the arm's reach"):
        MotionPlanner(scenario)


class RecordingArm:
    """relocation.Arm that only records: at home, never moves."""

    def __init__(self):
        self.calls = []

    def measured(self):
        return rd.Q_HOME.copy()

    def follow(self, trajectory, phase):
        self.calls.append(("follow", phase))

    def gripper(self, action, phase):
        self.calls.append(("gripper", action))

    def phase(self, phase):
        self.calls.append(("phase", phase))


def test_a_relocation_that_cannot_be_planned_never_moves_the_arm():
    """An explicit slot out of reach: the carry cannot be planned, and it is known before the pick starts."""
    scenario = sized_scene([(0.033, 0.16), (0.033, 0.16)], slots=[[0.95, 0.33], [0.76, 0.06]])
    planner = MotionPlanner(scenario)  # explicit slots are checked per relocation
    assert "slot 0" in planner.slot_problems()[0]
    arm = RecordingArm()
    with pytest.raises(PlanningError, match="carry of 'b0' to slot 0"):
        relocate(planner, arm, "b0", [])
    assert arm.calls == [("phase", "plan_pick")]
    big = load_scenario("scenario3_15")
    with pytest.raises(PlanningError, match="no free slot for 'T': 12 objects relocated"):
        plan_relocation(MotionPlanner(big), "T", [f"o{k}" for k in range(1, 13)])


OUTER_SLOTS = (4, 11)  # y = -0.30 in the back row, +0.30 in the front row: a staging pose put joints on their limits


@pytest.mark.parametrize("name, oid, slots", [
    ("paper_experiment_10", "o2", OUTER_SLOTS),
    pytest.param("paper_experiment_10", "o2", None, marks=pytest.mark.extended),
    pytest.param("scenario3_15", "o3", None, marks=pytest.mark.extended)],
    ids=["paper_experiment_10-outer", "paper_experiment_10-all", "scenario3_15-all"])
def test_every_slot_takes_a_bottle(name, oid, slots):
    """A front-row bottle carried to each slot in turn (the bottom shelf otherwise empty): the outer slots too
    (a staging pose 0.30 m in front of them put two joints on their limits). The default run carries it to the
    two outer slots, -m extended to every slot (None)."""
    scenario = load_scenario(name)
    planner = planner_for(scenario)
    slots = range(len(scenario.slots)) if slots is None else slots
    (pick,) = planner.plan_pick(oid, [])  # the same pick for every slot
    rep = Report()
    for k in slots:
        carry, retreat = planner.plan_carry(oid, [], k, q_start=pick.trajectory.positions[-1], placed=[])
        home = planner.plan_home(retreat.trajectory.positions[-1], [oid], [(oid, scenario.slot(k))])
        rep.merge(replay_relocation(MotionChecker(scenario), pick.trajectory, [carry.trajectory, retreat.trajectory],
                                    home, oid))
    assert_clean(rep, f"{name}: {oid} to each of slots {list(slots)}")


def test_summary():
    """The figures of the closing note (printed with -s)."""
    print(f"motion checker, whole module: {TOTAL.summary()}")
