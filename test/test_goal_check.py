"""RelocateObject goals against the scene, the destination slot from the scene's occupancy, the outcome after the
motion (stpik_motion_planner.execution.goal_check), and scene updates against the scenario
(relocation_common.scene_check)."""
import math
import threading
import time
from dataclasses import replace

import pytest

from relocation_common.paths import default_scenario
from relocation_common.ros_conversions import msg_to_objects, objects_to_msg
from relocation_common.scenario import ScenarioError, load_scenario
from relocation_common.scene_check import check_scene, foreign_ids
from relocation_common.shelf_object import Footprint
from stpik_motion_planner.execution import goal_check as gc
from stpik_motion_planner.execution.relocation import plan_relocation

SC = load_scenario(default_scenario())
SHELF, SLOTS = SC.shelf, SC.slots
RADIUS = SC.slot_radius


def _stream(watch: gc.SceneWatch, objects, period: float = 0.05, duration: float = 3.0) -> threading.Event:
    """A camera's stream of one scene: `objects` given to `watch` every `period` s for `duration` s from now, or until
    the returned event is set. The outcome check takes the first scene received OUTCOME_SETTLE (0.3 s) after its
    call; one scene given 0.4 s after the test started raced the test's own thread to that call (under load it came
    first, and the outcome said "no scene")."""
    stop = threading.Event()

    def run() -> None:
        end = time.monotonic() + duration
        while not stop.is_set() and time.monotonic() < end:
            watch.update(objects)
            stop.wait(period)

    threading.Thread(target=run, daemon=True).start()
    return stop


def _standing(**moved):
    """Every bottle standing where the scenario has it; `moved`: id -> (x, y, z of its base)."""
    at = {i: dict(x=x, y=y, support_z=z) for i, (x, y, z) in moved.items()}
    return [replace(b, **at.get(b.id, dict(support_z=SHELF.top_z))) for b in SC.objects]


def _scene(**moved):
    """The motion planner's scene of `_standing(**moved)`: id -> SeenBottle."""
    return {o.id: gc.seen_bottle(o) for o in _standing(**moved)}


def _points(scene):
    """`before` of the outcome check: id -> base centre."""
    return {i: b.point for i, b in scene.items()}


def test_removed_bottles_still_standing_refuse_the_goal_with_their_names():
    why = gc.refusal(SHELF, "o6", ["o2", "o3"], _scene(), {})
    assert why is not None and "o2, o3" in why and "standing on the top shelf" in why, why
    slot0 = (*SLOTS[0], SHELF.bottom_z)
    assert gc.refusal(SHELF, "o6", ["o2", "o3"], _scene(o2=slot0, o3=(*SLOTS[1], SHELF.bottom_z)), {}) is None
    assert "o3" in gc.refusal(SHELF, "o6", ["o2", "o3"], _scene(o2=slot0), {})


def test_an_object_already_on_the_bottom_shelf_is_refused():
    why = gc.refusal(SHELF, "o2", [], _scene(o2=(*SLOTS[0], SHELF.bottom_z)), {})
    assert why is not None and "already relocated" in why
    assert "already relocated" in gc.refusal(SHELF, "o2", [], {}, {"o2": 0})  # no scene: what this node placed
    assert gc.refusal(SHELF, "o2", [], _scene(), {"o2": 0}) is None  # seen back on the top shelf (a reset scene)


def test_the_destination_is_a_free_slot_of_the_scene_not_the_count_of_removed():
    """o2 then o3 both sent with removed=[]: the old node put o3 into slot 0 where o2 stood (shoved 69 mm)."""
    scene = _scene(o2=(*SLOTS[0], SHELF.bottom_z))
    placed = gc.placed_bottles(SHELF, SLOTS, scene, {}, RADIUS)
    assert [(i, f.centre) for i, f in placed] == [("o2", SLOTS[0])]
    assert SC.free_slots(f for _, f in placed)[0] == 1
    # this node placed o5 in slot 1 and the scene (perception: top shelf only) does not show it
    placed = gc.placed_bottles(SHELF, SLOTS, {k: v for k, v in scene.items() if k != "o5"}, {"o5": 1}, RADIUS)
    assert SC.free_slots(f for _, f in placed)[0] == 2
    full = [Footprint(xy, RADIUS, ()) for xy in SLOTS]
    assert SC.free_slots(full) == ()
    with pytest.raises(ValueError, match="no free slot"):  # every slot taken by bottles this node placed
        gc.destination(SC, {}, {f"b{k}": k for k in range(len(SLOTS))}, 0)


def test_the_destination_is_the_certified_slot_when_it_is_free():
    """A certified feasible answer for (o6, removed) planned the carry to slot len(removed) (planning.certify).
    o2 in slot 0 and o3 dropped to the floor, o6 sent with both removed: slot 2 is free, so o6 goes there, as
    certified (before: the first free slot, 1, a carry nobody certified); with slot 2 taken, the first free one."""
    floor = (0.3, 0.0, SHELF.bottom_z - 0.3)
    scene = _scene(o2=(*SLOTS[0], SHELF.bottom_z), o3=floor)
    slot, placed = gc.destination(SC, scene, {}, 2)
    assert slot == 2 and placed == [("o2", SLOTS[0])]
    scene = _scene(o2=(*SLOTS[0], SHELF.bottom_z), o3=floor, o4=(*SLOTS[2], SHELF.bottom_z))
    assert gc.destination(SC, scene, {}, 2)[0] == 1
    assert gc.goal_refusal(SC, "o6", ["o2", "o3"], scene, {}) is None


def test_plan_relocation_goes_to_the_slot_given_with_the_bottles_placed():
    from stpik_motion_planner.planning.params import PlannerParams
    from stpik_motion_planner.planning.planner import MotionPlanner

    planner = MotionPlanner(SC, PlannerParams.load())
    plan = plan_relocation(planner, "o2", [], slot=1, placed=[("o1", SLOTS[0])])
    assert plan.slot_index == 1 and plan.placed == [("o1", SLOTS[0])]


def test_the_outcome_names_every_bottle_that_moved_and_a_misplaced_one():
    before = _points(_scene())
    slot = SLOTS[0]
    good = _scene(o2=(slot[0] + 0.004, slot[1], SHELF.bottom_z), o6=(0.8 + 0.003, 0.0, SHELF.top_z))
    assert gc.outcome_problems(SHELF, before, good, "o2", slot, 0.015, 0.02) == []
    # the run that was reported: o6 relocated while o2 and o3 stood; o2 pushed 65 mm, o3 tipped over
    bad = _scene(o6=(*SLOTS[2], SHELF.bottom_z), o2=(0.69 + 0.065, -0.07, SHELF.top_z),
                 o3=(0.69 + 0.08, 0.07, SHELF.top_z + 0.033))
    problems = gc.outcome_problems(SHELF, before, bad, "o6", SLOTS[2], 0.015, 0.02)
    assert problems == ["o2 moved 65 mm", "o3 moved 87 mm (no longer standing on its board)"], problems
    off = gc.outcome_problems(SHELF, before, _scene(o2=(slot[0], slot[1] + 0.05, SHELF.bottom_z)), "o2", slot,
                              0.015, 0.02)
    assert off == [f"o2 is 50 mm from its slot ({slot[0]:.3f}, {slot[1]:.3f})"]
    assert gc.outcome_problems(SHELF, before, _scene(), "o2", slot, 0.015, 0.02) == ["o2 is still on the top shelf"]
    assert gc.outcome_problems(SHELF, before, {}, "o2", slot, 0.015, 0.02) == []  # nothing seen: nothing contradicts


@pytest.mark.parametrize("value", [0.0, -1.0, math.nan, "x", True])
def test_outcome_parameters_must_be_positive(value):
    with pytest.raises(ValueError, match="outcome_timeout"):
        gc.check_parameters({"outcome_tolerance": 0.01, "slot_tolerance": 0.02, "outcome_timeout": value})


# -- scene updates against the scenario ---------------------------------------------------------------------------
def _objects(**change):
    out = [(b.id, b.x, b.y, SHELF.top_z) for b in SC.objects]
    for old, new in change.items():
        out = [new if o[0] == old else o for o in out]
    return out


def test_a_scene_of_the_scenario_passes():
    check_scene(SC, _objects())
    check_scene(SC, _objects(o2=("o2", *SLOTS[0], SHELF.bottom_z)))  # relocated
    check_scene(SC, _objects()[:3])  # perception sees part of the scene


@pytest.mark.parametrize("change, words", [
    ({"o3": ("zz3", 0.69, 0.07, 0.02)}, "id 'zz3' is not in scenario"),
    ({"o3": ("o2", 0.69, 0.07, 0.02)}, "'o2' appears twice"),
    ({"o3": ("o3", math.nan, 0.07, 0.02)}, "not finite"),
    ({"o3": ("o3", 1e6, 0.07, 0.02)}, "away from the shelf"),
    ({"o3": ("o3", 0.69, 0.07, -5.0)}, "away from the shelf"),
])
def test_a_bad_scene_is_refused_naming_the_fault(change, words):
    with pytest.raises(ScenarioError, match=words):
        check_scene(SC, _objects(**change), "scene on /sim/objects")


def test_foreign_ids_name_what_the_planner_holds_and_the_scene_does_not():
    assert foreign_ids(["o1", "zz3", "o2"], ["o1", "o2"]).startswith("; the motion planner's scene holds zz3,")
    assert foreign_ids(["o1"], ["o1", "o2"]) == ""


def test_goal_refusal_checks_ids_own_set_and_the_scene():
    assert "unknown object id 'ghost'" in gc.goal_refusal(SC, "ghost", [], _scene(), {})
    assert "unknown object id 'zz'" in gc.goal_refusal(SC, "o2", ["zz"], _scene(), {})
    assert "in its own removed set" in gc.goal_refusal(SC, "o3", ["o3"], _scene(), {})
    assert "standing on the top shelf" in gc.goal_refusal(SC, "o6", ["o2"], _scene(), {})
    assert gc.goal_refusal(SC, "o2", [], _scene(), {}) is None
    full = {f"b{k}": k for k in range(len(SLOTS))}  # every slot taken by bottles this node placed
    assert "no free slot" in gc.goal_refusal(SC, "o2", [], {}, full)


VALUES = {"outcome_tolerance": 0.015, "slot_tolerance": 0.02, "outcome_timeout": 0.3}


def test_the_outcome_waits_for_a_scene_after_the_motion():
    watch = gc.SceneWatch()
    # never a scene: unknown, never a success (the old check returned True, "outcome unverified")
    assert gc.outcome(watch, {}, SC, "o2", 0, VALUES, "/sim/objects") == (
        False, "relocated o2 to slot 0, but no scene on /sim/objects within outcome_timeout after the motion: "
               "outcome unknown")
    before = _points(_scene())
    watch.update(_standing())  # received before the motion ended: not used
    ok, msg = gc.outcome(watch, before, SC, "o2", 0, VALUES, "/sim/objects")
    assert not ok and msg.endswith("but no scene on /sim/objects within outcome_timeout after the motion: outcome "
                                   "unknown"), msg
    after = _standing(o2=(*SLOTS[0], SHELF.bottom_z), o1=(0.69 + 0.03, -0.21, SHELF.top_z))
    _stream(watch, after)
    values = dict(VALUES, outcome_timeout=3.0)
    assert gc.outcome(watch, before, SC, "o2", 0, values, "t") == (False, "relocated o2 to slot 0, but the scene "
                                                                          "shows: o1 moved 30 mm")


def test_without_a_scene_before_the_motion_the_scene_after_decides():
    """A node that got its first scene only after the motion (perception restarting): the moved bottle is checked,
    the others cannot be. The old check answered success without waiting for any scene."""
    watch = gc.SceneWatch()
    still_there = _standing()  # o2 still standing on the top shelf: not a success
    first = _stream(watch, still_there)
    ok, msg = gc.outcome(watch, {}, SC, "o2", 0, dict(VALUES, outcome_timeout=3.0), "t")
    assert (ok, msg) == (False, "relocated o2 to slot 0, but the scene shows: o2 is still on the top shelf")
    placed = _standing(o2=(*SLOTS[0], SHELF.bottom_z))
    first.set()  # that camera's stream ends before the next motion does
    _stream(watch, placed)
    assert gc.outcome(watch, {}, SC, "o2", 0, dict(VALUES, outcome_timeout=3.0), "t") == (
        True, "relocated o2 to slot 0 (the other bottles not checked: no scene on t before the motion)")


# -- objects lying on the bottom shelf -----------------------------------------------------------------------------
BOX10 = load_scenario("config/scenarios/world/shapes_box_10.yaml")


def _lying_scene(sc, lying_id, x, y, yaw):
    """The motion planner's scene of `sc` (as the ground truth's message gives it: ros_conversions) with `lying_id`
    lying on the bottom shelf, its footprint centred at (x, y), its axis at `yaw`."""
    lying = replace(sc.object(lying_id), x=x, y=y, yaw=yaw, lying=True, support_z=sc.shelf.bottom_z)
    objects = [lying if b.id == lying_id else replace(b, support_z=sc.shelf.top_z) for b in sc.objects]
    return {o.id: gc.seen_bottle(o) for o in msg_to_objects(objects_to_msg(objects), require_target=False)}


@pytest.mark.parametrize("yaw", [math.pi / 2, 0.0, 0.6])
def test_a_bottle_lying_on_the_bottom_shelf_takes_the_slots_it_covers(yaw):
    """A bottle lying at (0.72, 0.12) on the bottom shelf of shapes_box_10, between slots 1, 3, 7 and 9: its base
    centre is a radius above the board, so the old check found it on no shelf and every one of the 10 slots free
    (the next carry was planned into it). It is on the bottom shelf, and the destination never is a slot its
    footprint comes within the widest object's radius of (checked against the footprint itself)."""
    seen = _lying_scene(BOX10, "o1", 0.72, 0.12, yaw)
    assert gc.on_bottom_shelf(BOX10.shelf, seen["o1"]) and not gc.on_top_shelf(BOX10.shelf, seen["o1"])
    chosen = {gc.destination(BOX10, seen, {}, n)[0] for n in range(len(BOX10.slots))}
    foot = seen["o1"].footprint
    covered = {k for k, xy in enumerate(BOX10.slots) if foot.overlaps(Footprint(xy, BOX10.slot_radius, ()))}
    assert {1, 7} <= covered and not chosen & covered, (chosen, covered)
    assert chosen == set(range(len(BOX10.slots))) - covered
    assert "already relocated" in gc.refusal(BOX10.shelf, "o1", [], seen, {})  # lying there, it is relocated


def test_a_bottle_that_lay_before_is_placed_lying_on_its_slot_as_planned():
    """o2 lay on the top shelf (its base centre a radius above the board) and was relocated by the grasp along its
    axis, placed lying, its footprint centred on slot 1: as planned (before: "tipped over on the bottom shelf");
    20 mm beyond slot_tolerance it lies off its slot."""
    seen = _lying_scene(BOX10, "o2", *BOX10.slots[1], 0.0)
    before = {b.id: (b.x, b.y, BOX10.shelf.top_z + (0.033 if b.id == "o2" else 0.0)) for b in BOX10.objects}
    assert gc.outcome_problems(BOX10.shelf, before, seen, "o2", BOX10.slots[1], 0.015, 0.02) == []
    off = _lying_scene(BOX10, "o2", BOX10.slots[1][0], BOX10.slots[1][1] + 0.04, 0.0)
    assert gc.outcome_problems(BOX10.shelf, before, off, "o2", BOX10.slots[1], 0.015, 0.02) == [
        "o2 lies 40 mm from its slot (0.760, 0.060)"]


def test_a_bottle_that_tipped_over_at_its_slot_is_on_the_bottom_shelf_tipped():
    """o2 relocated to slot 1 and tipped over there (its axis along x, its footprint centred on the slot). Before,
    the outcome said 'o2 is 87 mm from its slot' and the next carry's destination was slot 1 again. Now: on the
    bottom shelf, tipped (still not a success: not placed as asked), and its slot taken."""
    seen = _lying_scene(BOX10, "o2", *BOX10.slots[1], 0.0)
    assert gc.on_bottom_shelf(BOX10.shelf, seen["o2"])
    before = {b.id: (b.x, b.y, BOX10.shelf.top_z) for b in BOX10.objects}
    problems = gc.outcome_problems(BOX10.shelf, before, seen, "o2", BOX10.slots[1], 0.015, 0.02)
    assert problems == ["o2 tipped over on the bottom shelf (90 deg), lying 0 mm from its slot (0.760, 0.060)"]
    assert gc.destination(BOX10, seen, {}, 1)[0] != 1
    watch = gc.SceneWatch()
    tipped = replace(BOX10.object("o2"), x=BOX10.slots[1][0], y=BOX10.slots[1][1], lying=True,
                     support_z=BOX10.shelf.bottom_z)
    after = [tipped if b.id == "o2" else replace(b, support_z=BOX10.shelf.top_z) for b in BOX10.objects]
    _stream(watch, msg_to_objects(objects_to_msg(after)))
    assert gc.outcome(watch, before, BOX10, "o2", 1, dict(VALUES, outcome_timeout=3.0), "t") == (
        False, "relocated o2 to slot 1, but the scene shows: " + problems[0])
