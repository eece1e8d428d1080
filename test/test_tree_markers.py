"""The Q-Tree drawn as RViz markers, from a real training on a synthetic scene."""
import pytest

pytest.importorskip("visualization_msgs")

from qtree_task_planner.learning.params import TrainingParams
from qtree_task_planner.learning.training import train
from qtree_task_planner.markers import tree_markers
from qtree_task_planner.oracles import BlockingOracle
from qtree_task_planner.problem import RelocationProblem
from relocation_common.paths import scenarios_dir
from relocation_common.scenario import load_scenario

SCENE = load_scenario(scenarios_dir() / "blocking_5.yaml")


def test_tree_markers_draw_every_feasible_edge_and_the_learned_path():
    params = TrainingParams.defaults().replace(seed=2, max_episodes=300)
    r = train(SCENE, BlockingOracle(SCENE), params)
    state = r.tree.to_state()
    ids = RelocationProblem.from_scenario(SCENE).ids
    arr = tree_markers(state, ids, r.sequence, "base")
    by_id = {m.id: m for m in arr.markers}
    dots, edges, goals, path = by_id[0], by_id[1], by_id[2], by_id[3]
    assert len(dots.points) == len(state["nodes"]) == r.tree_nodes
    feasible = [e for n in state["nodes"] for e in n["edges"] if e[1] != 0]
    assert len(edges.points) == 2 * len(feasible) and len(edges.colors) == len(edges.points)
    assert len(goals.points) == sum(1 for e in feasible if e[0] == len(ids) - 1)
    assert len(path.points) == len(r.sequence) + 1  # root, one node per obstacle, the target edge
    labels = [m.text for m in arr.markers if m.type == m.TEXT_VIEW_FACING]
    assert labels == list(r.sequence)
    # the highest-valued edge is the greenest
    best_edge = max(range(len(feasible)), key=lambda k: feasible[k][2])
    assert edges.colors[2 * best_edge].g == pytest.approx(1.0)


def test_scene_markers_draw_each_object_as_its_shape_at_its_centre():
    """The scene's markers (RViz) come from the objects as msg_to_objects reads them: a box a CUBE of its size, a
    lying bottle a CYLINDER along its axis, each at its primitive's centre, in its colour."""
    from visualization_msgs.msg import Marker

    from qtree_task_planner.markers import scene_markers
    from relocation_common.ros_conversions import objects_to_msg
    sc = load_scenario("world/shapes_box_10")
    lying = load_scenario("world/lying_start_8")
    arr = scene_markers(objects_to_msg(sc.objects), ("T",))
    shapes = {m.id: m for m in arr.markers if m.ns == "scene"}
    for k, o in enumerate(sc.objects):
        m = shapes[k]
        assert m.type == (Marker.CUBE if o.shape == "box" else Marker.CYLINDER)
        assert (m.scale.x, m.scale.y, m.scale.z) == pytest.approx(o.size)
        assert (m.pose.position.x, m.pose.position.y, m.pose.position.z) == pytest.approx(tuple(o.centre()))
        assert (m.color.r, m.color.g, m.color.b) == pytest.approx(o.rgb)
    k, o = next((k, o) for k, o in enumerate(lying.objects) if o.lying)
    m = next(m for m in scene_markers(objects_to_msg(lying.objects), ()).markers if m.ns == "scene" and m.id == k)
    assert m.pose.position.z == pytest.approx(lying.shelf.top_z + o.radius) and abs(m.pose.orientation.w) < 0.99
