"""The crowded scenes of config/scenarios/world/ (crowd_20, crowd_30: the demo's 20- and 30-object scenes) are drawn
by the rule their header states and leave the target retrievable (docs/scenarios.md, "Admission"): the file is the
generator's draw for the seed and spare columns it names; the lane screen finds a sequence (the layouts shipped before
were blocking cycles: the demo failed in 8 s, docs/bench/demo.md); the admission refuses a blocking cycle at the
screen. The whole rule (every earlier seed refused, this one admitted by the exact A* with the real planner) is
re-run under `-m extended`."""
from __future__ import annotations

import re

import pytest
import yaml

from qtree_task_planner.problem import RelocationProblem
from qtree_task_planner.search import astar
from relocation_app.evaluation.feasibility_cache import planner_params, worker_planner
from relocation_app.evaluation.scenes import admission, world
from relocation_common.paths import scenarios_dir

CROWDS = tuple(world.RETRIEVABLE_SCENES)


def _shipped(name: str) -> tuple[str, dict]:
    text = (scenarios_dir() / world.DIR / f"{name}.yaml").read_text()
    return text, yaml.safe_load(text)


def _rule(text: str) -> tuple[int, int]:
    """(seed, spare columns) the header names."""
    m = re.search(r"seed (\d+)(?:, (\d+) spare columns?)?, the first", text)
    assert m, text[:400]
    return int(m.group(1)), int(m.group(2) or 0)


@pytest.mark.parametrize("name", CROWDS)
def test_a_crowd_scene_is_the_draw_its_header_names(name):
    text, data = _shipped(name)
    seed, spare = _rule(text)
    assert world.recipe_scene(name, seed, spare) == data
    assert "meets its purpose (admission.py)" in text and "retrievable" in text


@pytest.mark.parametrize("name", CROWDS)
def test_a_crowd_scene_passes_the_lane_screen(name):
    """The blocker A* on the grasp lanes alone (no motion planning) finds a sequence to the target."""
    sc = admission.planners_view(_shipped(name)[1])
    lanes = worker_planner(sc, planner_params()).lane_blockers(frozenset())
    found = astar.solve(RelocationProblem.from_bottles(sc.objects), admission.LaneScreen(lanes, sc.target_id))
    assert found.sequence is not None and found.sequence[-1] == sc.target_id, found.reason


def test_the_admission_refuses_a_blocking_cycle_at_the_screen():
    """crowd_20's first seed stocked in columns: the lane screen proves a blocking cycle, no motion planning."""
    v = admission.judge(world.recipe_scene("crowd_20", world.SEED0 + 100 * world.ORDER.index("crowd_20")),
                        world.RETRIEVABLE_SCENES["crowd_20"], planner_params())
    assert (v.admitted, v.stage, v.planner_calls) == (False, "screen", 0) and "blocking cycle" in v.reason, v


@pytest.mark.extended  # minutes: every seed before the admitted one is judged again
@pytest.mark.parametrize("name", CROWDS)
def test_the_scene_maker_writes_a_crowd_scene_again(name, tmp_path):
    world.make_world(tmp_path, (name,), log=lambda s: None)
    assert (tmp_path / f"{name}.yaml").read_text() == _shipped(name)[0]
