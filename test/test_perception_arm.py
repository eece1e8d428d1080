"""The arm in the camera's view is never an object: frames rendered by the project's simulated camera with the arm
in the shelf (joint states of a recorded carry, test/data/arm_in_shelf_joint_states.json), the carried bottle left
out. Perception is given the joint state 0.2 s later (a stale or early state, as a node gets it when images come
late): the body between the two poses and the pieces it cuts out of bottles make clusters, which must not become
objects. And a listed bottle's edge, split off by the clustering, is no object of its own."""
import copy
import json
import math
from pathlib import Path

import numpy as np
import pytest
from perception_scenes import generated_layout, render_scene, with_objects

from jaco2_sim_driver.sensor_model import SensorModel
from perception_aruco.objects.self_filter import arm_in_shelf
from perception_aruco.pipeline import Perception, SceneMemory
from perception_aruco.tracking import JointHistory
from relocation_common.paths import default_scenario
from relocation_common.robot_description import Q_HOME
from relocation_common.scenario import load_scenario

DATA = json.loads((Path(__file__).resolve().parent / "data" / "arm_in_shelf_joint_states.json").read_text())
SCENE = Path(__file__).resolve().parent.parent / "config" / "scenarios" / "scenario1_5.yaml"


def test_no_object_made_of_the_arm_in_the_shelf():
    """During a carry (the node saw the shelf with the arm at home before: its memory holds that frame)."""
    s = load_scenario(SCENE)
    s = s.with_objects([o for o in s.objects if o.id != "o4"])  # o4: in the hand
    home, _ = render_scene(s, q=Q_HOME)
    p, seen = Perception(s), SceneMemory(s.ids, 3, 3)
    r0 = p.process(home.rgb, home.depth, home.K, memory=seen, q=Q_HOME)
    seen.update(r0.objects, r0.uncounted)
    phantoms = []
    for k, sample in enumerate(DATA["samples"]):
        f, _ = render_scene(s, q=np.array(sample["q"]))
        later = np.array(sample["q_later"])
        assert arm_in_shelf(later, s.shelf, 0.02)
        r = p.process(f.rgb, f.depth, f.K, memory=copy.deepcopy(seen), q=later)
        phantoms += [f"t={sample['t']} {i} at ({o.x:.3f}, {o.y:.3f})" for i, o in r.unlisted.items()]
    assert not phantoms, phantoms


def test_a_first_frame_with_the_arm_in_the_shelf_and_an_unknown_cluster_is_refused():
    """On the blocking shelves the arm at home reaches into the top compartment (its hand above the bottles), so new
    objects are not taken there; at 424 x 240 the orange o6, behind o2 and o3 and under the hand, shows as two
    fragments of 13-15 pixels that no listed object takes. Before, the frame was published with o6 missing and no
    object in its place (occupied space published as free: the robustness benchmark's two silently wrong cases).
    Now a first frame (nothing earlier explains that space) is refused with the reason."""
    from dataclasses import replace

    from jaco2_sim_driver.camera import render_frame
    from jaco2_sim_driver.params import CameraSpec
    from perception_aruco.aruco import PerceptionError
    s = load_scenario("blocking_10")
    assert arm_in_shelf(Q_HOME, s.shelf, 0.02)
    f = render_frame(s, q=Q_HOME, camera=replace(CameraSpec.configured(), width=424, height=240))
    with pytest.raises(PerceptionError, match="no scene until the arm is out of the shelf"):
        Perception(s).process(f.rgb, f.depth, f.K, q=Q_HOME)


def test_the_joint_states_around_a_frame():
    h = JointHistory(0.1, 0.02)
    for k in range(300):  # 100 Hz, joint 1 at 0.5 rad/s from t = 1 s
        h.add(k * 0.01, Q_HOME + np.r_[0.5 * max(0.0, k * 0.01 - 1.0), np.zeros(6)])
    still, moving = h.around(0.5), h.around(2.0)
    assert len(still) == 1 and np.allclose(still[0], Q_HOME)
    assert 2 <= len(moving) <= 6 and math.isclose(moving[0][0] - Q_HOME[0], 0.45, abs_tol=0.011)
    assert moving[-1][0] - Q_HOME[0] >= 0.54 - 0.02
    assert not arm_in_shelf(Q_HOME, load_scenario(default_scenario()).shelf, 0.02)
    # a frame newer than every joint state: its arm pose is unknown while the arm moved, known while it stood still
    assert h.unknown_at(3.2) and not h.unknown_at(2.0)
    still = JointHistory(0.1, 0.02)
    for k in range(50):
        still.add(k * 0.01, Q_HOME)
    assert not still.unknown_at(1.0) and not JointHistory(0.1, 0.02).unknown_at(1.0)


def _phantoms(r, s) -> list[str]:
    """Unlisted objects published on a scene that lists every object: each must cover a listed object perception
    did not identify (its cluster published unlisted, as designed); one on an identified object (a piece of it) or
    on nothing is a phantom."""
    out = []
    for i, o in r.unlisted.items():
        near = min(s.objects, key=lambda b: math.hypot(b.x - o.x, b.y - o.y))
        if near.id in r.detections or math.hypot(near.x - o.x, near.y - o.y) > near.radius + o.reach:
            out.append(f"{i} {o.shape} at ({o.x:.3f}, {o.y:.3f}), {o.n_points} px, nearest {near.id} "
                       f"({'identified' if near.id in r.detections else 'not identified'})")
    return out


def test_no_phantom_where_every_object_is_listed():
    """Generated layouts of 5-15 bottles (seeds 10-17, fixed before any result), every one listed, ideal and
    realistic camera, the arm home: no unlisted object published but on a listed bottle perception did not identify
    (a piece of an identified bottle seen past another, split off by the clustering, was one)."""
    base = load_scenario(default_scenario())
    phantoms, covering = [], 0
    for seed in range(10, 18):
        s = with_objects(base, generated_layout(base, seed, 5 + (seed % 3) * 5))
        for camera in ("ideal", "realsense_d435"):
            f, _ = render_scene(s, sensor=SensorModel.named(camera), seed=seed)
            r = Perception(s).process(f.rgb, f.depth, f.K, q=Q_HOME)
            found = _phantoms(r, s)
            covering += len(r.unlisted) - len(found)
            phantoms += [f"seed {seed} {camera}: {x}" for x in found]
    print(f"\n16 frames, every object listed: {covering} unlisted objects covering a listed bottle not identified, "
          f"{len(phantoms)} phantoms {phantoms}")
    assert not phantoms


def test_no_unlisted_object_published_while_the_arm_passes_in_front_with_its_joint_states_late():
    """The demo's phantoms under load: frames rendered with the arm on its way from home into the shelf (the poses
    between Q_HOME and three recorded carry poses, 35-80 % of the way), perception given the joint states of an
    earlier moment (15-20 % of the way: outside the shelf, late as under load), after a frame at home. These frames
    make clusters of the arm's body and of the pieces it cuts out of bottles, at places like the demo's u3 (0.632,
    -0.089); none may be published as an unlisted object (the old code published 1-6 per sequence)."""
    s = load_scenario(default_scenario())
    p = Perception(s)
    home, _ = render_scene(s)
    published, made = [], 0
    for sample in DATA["samples"][:3]:
        memory = SceneMemory(s.ids, 10, 3)
        r = p.process(home.rgb, home.depth, home.K, memory=memory, q=Q_HOME)
        memory.update(r.objects, r.uncounted)
        def on_way(a: float) -> np.ndarray:
            return Q_HOME + a * (np.array(sample["q"]) - Q_HOME)
        late = np.array([on_way(0.15), on_way(0.2)])
        assert not arm_in_shelf(late, s.shelf, 0.02)
        for a in (0.35, 0.45, 0.6, 0.8):
            f, _ = render_scene(s, q=on_way(a))
            r = p.process(f.rgb, f.depth, f.K, memory=memory, q=late)
            made += len(r.unlisted)
            published += [f"t={sample['t']} a={a} {o.id} at ({o.x:.3f}, {o.y:.3f})"
                          for o in memory.update(r.objects, r.uncounted)[0] if not o.listed]
    print(f"\n12 frames with the arm in front, joint states late: {made} unlisted clusters in the frames, "
          f"{len(published)} published")
    assert not published, published
