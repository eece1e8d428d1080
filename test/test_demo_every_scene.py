"""scripts/demo_every_scene.py's scene list and table rows (the sweep itself runs the demo: not a unit test)."""
import importlib.util
from pathlib import Path

spec = importlib.util.spec_from_file_location(
    "demo_every_scene", Path(__file__).resolve().parent.parent / "scripts" / "demo_every_scene.py")
sweep = importlib.util.module_from_spec(spec)
spec.loader.exec_module(sweep)


def test_every_shipped_scene_but_the_test_doubles():
    names = sweep.shipped_scenes()
    assert "scenario3_15" in names and "random5_07" in names and "paper_random5_09" in names  # sub-folders too
    assert not any(n.startswith("blocking_") for n in names) and len(names) == len(set(names))


def test_a_row_says_what_the_report_says():
    ok = {"success": True, "learned_sequence": ["o2", "T"], "learned_weight": 0.76, "optimal_sequence": ["o2", "T"],
          "optimal_weight": 0.76, "executed": "learned", "wall_time_s": 40.2,
          "final_scene": {"target_on_bottom_shelf": True, "arm_home": True, "gripper_empty": True}}
    assert sweep.row("s", ok) == "| s | SUCCESS | o2 T (0.76) | o2 T (0.76) | learned | yes | 40 |"
    failed = dict(ok, success=False, message="no sequence remains: T cannot be reached", learned_weight=None,
                  final_scene=dict(ok["final_scene"], arm_home=False))
    assert sweep.row("s", failed) == ("| s | FAILED: no sequence remains: T cannot be reached | - | o2 T (0.76) | "
                                      "learned | no | 40 |")
