"""stpik_motion_planner.scene_update: which perceived bottles replace the planner's (ROS-free)."""
from dataclasses import replace

from relocation_common.scenario import load_scenario
from stpik_motion_planner.scene_update import MOVED, merge_perceived

SC = load_scenario("scenario1_5")
TOP = SC.shelf.top_z
CURRENT = {b.id: b for b in SC.objects}


def test_a_bottle_moved_on_the_top_shelf_replaces_the_planners():
    o1 = replace(CURRENT["o1"], x=CURRENT["o1"].x + 0.02)
    merged, changed, seen = merge_perceived(SC.shelf, CURRENT, [(o1, TOP), (CURRENT["o2"], TOP)])
    assert changed == ["o1"] and merged["o1"].x == o1.x and seen == {"o1", "o2"}
    assert merged["o3"] is CURRENT["o3"]  # not seen: keeps its last pose


def test_jitter_below_the_threshold_changes_nothing():
    o1 = replace(CURRENT["o1"], x=CURRENT["o1"].x + MOVED / 2)
    assert merge_perceived(SC.shelf, CURRENT, [(o1, TOP)])[1] == []


def test_lifted_held_or_off_shelf_bottles_are_ignored():
    lifted = replace(CURRENT["o1"], x=CURRENT["o1"].x + 0.05)
    held = replace(CURRENT["o2"], x=CURRENT["o2"].x + 0.05)
    bottom = replace(CURRENT["o3"], x=CURRENT["o3"].x + 0.05)
    merged, changed, seen = merge_perceived(SC.shelf, CURRENT, [(lifted, TOP + 0.03), (held, TOP),
                                                                (bottom, SC.shelf.bottom_z)], held="o2")
    assert changed == [] and seen == set() and merged == CURRENT
