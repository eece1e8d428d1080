"""Geometry-first perception on frames rendered by the project's simulated camera (perception_scenes: the
simulator's scene, generated layouts with seeds fixed before any result): every visible listed object found within
10 mm; two bottles of one colour kept apart over frames while one moves; an object the scenario does not list
published as u1 with its weight note, nothing listed dropped for it; more than 16 objects; lying bottles and boxes
(the simulator's scene with test-only extras). The rates are printed."""
import importlib.util
import math
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from perception_scenes import extra, generated_layout, perceived, render_scene, with_objects

from jaco2_sim_driver.sensor_model import SensorModel
from perception_aruco.objects.model import BOX, CYLINDER
from perception_aruco.objects.self_filter import arm_segments
from perception_aruco.pipeline import Perception, SceneMemory, arm_reaches
from relocation_common.paths import default_scenario
from relocation_common.robot_description import Q_HOME
from relocation_common.scenario import PALETTE, load_scenario

_spec = importlib.util.spec_from_file_location(
    "bench_perception_objects", Path(__file__).resolve().parent.parent / "scripts/bench_perception_objects.py")
assert _spec is not None and _spec.loader is not None
bench = importlib.util.module_from_spec(_spec)
sys.modules[_spec.name] = bench  # its dataclasses look their module up
_spec.loader.exec_module(bench)

VISIBLE = 300
BASE = load_scenario(default_scenario())


def _found(result, scenario, visible, tol=0.010):
    """(visible listed ids, those found within tol with their id)."""
    must = {b.id for b in scenario.objects if visible.get(b.id, 0) >= VISIBLE}
    ok = {i for i in must if i in result.detections and math.hypot(
        result.detections[i].x - scenario.object(i).x, result.detections[i].y - scenario.object(i).y) <= tol}
    return must, ok


@pytest.mark.parametrize("camera", ["ideal", "realsense_d435"])
def test_every_visible_listed_object_found_within_10_mm(camera):
    """Generated layouts of 10 bottles (seeds 0-5, three sizes): every listed bottle with >= 300 pixels in view found
    with its id within 10 mm, and no listed id published elsewhere."""
    must_all, ok_all, wrong = 0, 0, []
    for seed in range(6):
        s = with_objects(BASE, generated_layout(BASE, seed, 10))
        f, vis = render_scene(s, sensor=SensorModel.named(camera), seed=seed)
        r = Perception(s).process(f.rgb, f.depth, f.K, q=Q_HOME)
        must, ok = _found(r, s, vis)
        must_all, ok_all = must_all + len(must), ok_all + len(ok)
        wrong += [f"seed {seed} {i}" for i, d in r.detections.items()
                  if math.hypot(d.x - s.object(i).x, d.y - s.object(i).y) > 0.010]
        assert must <= ok, (seed, must - ok, {i: r.missing.get(i) for i in must - ok})
    print(f"\n{camera}: {ok_all}/{must_all} visible listed bottles found within 10 mm; wrong: {wrong}")
    assert not wrong


def test_two_bottles_of_one_colour_kept_apart_while_one_moves():
    """Two red bottles (the loader refuses that; the simulator does not): both found, each with its id, over 6
    frames while o2 moves 15 mm a frame towards o1's row; identities from the tracks (SceneMemory)."""
    layout = generated_layout(BASE, 11, 6, colours=["red", "red", "blue", "yellow", "cyan"])
    assert layout[1].label == layout[2].label == "red"
    memory = SceneMemory(tuple(b.id for b in layout), 10, 3)
    p = Perception(with_objects(BASE, layout))
    for k in range(6):
        moved = [replace(b, y=b.y + 0.015 * k) if b.id == "o2" else b for b in layout]
        truth = with_objects(BASE, moved)
        f, vis = render_scene(truth)
        r = p.process(f.rgb, f.depth, f.K, memory=memory, q=Q_HOME)
        memory.update(r.objects, r.uncounted)
        for i in ("o1", "o2"):
            assert vis[i] >= VISIBLE and i in r.detections, (k, i, r.missing)
            d, t = r.detections[i], truth.object(i)
            assert math.hypot(d.x - t.x, d.y - t.y) <= 0.010, (k, i, d.x, d.y, t.x, t.y)


def test_an_unlisted_bottle_appears_as_u1_and_drops_nothing_listed():
    """The user's case: the simulator's scene has an extra bottle (or a short wide jar) the scenario does not list.
    Over seeds 0-5 (colour from the palette, position at random): it is published as u1, listed false, with its
    estimated weight said; every visible listed bottle is still found within 10 mm."""
    rates = []
    for seed in range(6):
        rng = np.random.default_rng([seed, 36])
        layout = generated_layout(BASE, seed, 8)
        jar = seed % 2 == 1
        r_, h_ = (0.045, 0.09) if jar else (0.033, 0.16)
        other = generated_layout(BASE, 100 + seed, 1, radii=(r_,), heights=(h_,),
                                 taken=[(b.x, b.y, b.radius) for b in layout])[0]
        colour = list(PALETTE)[int(rng.integers(len(PALETTE)))]
        other = replace(other, id="extra", label=colour, rgb=PALETTE[colour], is_target=False, listed=False)
        given = with_objects(BASE, layout)
        f, vis = render_scene(with_objects(BASE, layout, [other]))   # the simulator's `unlisted`
        r = Perception(given).process(f.rgb, f.depth, f.K, q=Q_HOME)
        must, ok = _found(r, given, vis)
        assert must <= ok, (seed, must - ok, r.missing)
        if vis["extra"] < VISIBLE:
            continue
        near = [o for o in r.unlisted.values() if math.hypot(o.x - other.x, o.y - other.y) <= 0.010]
        rates.append(bool(near))
        assert near and near[0].id == "u1" and not near[0].listed, (seed, r.unlisted)
        assert "L x 600 kg/m3" in near[0].weight_note and 0 < near[0].weight <= 1
        assert abs(near[0].radius - r_) < 0.005
        # its height as seen, or (its top hidden under the ceiling board) never less: as tall as the compartment
        assert abs(near[0].height - h_) < 0.01 or ("top not seen" in near[0].weight_note and near[0].height > h_)
    print(f"\nunlisted bottle or jar found as u1: {sum(rates)}/{len(rates)} (visible ones)")
    assert len(rates) >= 4


def test_a_jar_at_the_back_under_the_realistic_cameras_noise_is_fitted_on_its_side():
    """An unlisted 90 mm jar at the top board's back (about 1 m from the camera, where the realistic camera's depth
    noise, growing as the distance squared, is 3-4 mm) with 3 listed bottles in front, over 4 sensor seeds and
    positions fixed before any result: it is published as a fitted cylinder (not a conservative box) within 10 mm.
    Its top face's points spread below the cap's margin and lie inside its circle: left in the circle fit, they pull
    it to a smaller radius, off or out of the fit bound (docs/perception.md, "Objects")."""
    sh = BASE.shelf
    for seed in range(4):
        y = sh.y_min + (0.2 + 0.2 * seed) * (sh.y_max - sh.y_min)
        jar = extra(BASE, "jar", CYLINDER, sh.x_back - 0.075, y, (0.09, 0.09, 0.09), 0.0, False, PALETTE["teal"])
        layout = generated_layout(BASE, seed, 3, taken=[(jar.x, jar.y, 0.08)])
        f, vis = render_scene(with_objects(BASE, layout, [jar]), sensor=SensorModel.named("realsense_d435"),
                              seed=seed)
        assert vis["jar"] >= VISIBLE, (seed, vis["jar"])
        r = Perception(with_objects(BASE, layout)).process(f.rgb, f.depth, f.K, q=Q_HOME)
        near = [o for o in r.unlisted.values() if math.hypot(o.x - jar.x, o.y - jar.y) <= 0.05]
        assert near, (seed, r.unlisted)
        o = near[0]
        assert o.shape == CYLINDER and not o.conservative, (seed, o.weight_note)
        assert math.hypot(o.x - jar.x, o.y - jar.y) <= 0.010, (seed, o.x - jar.x, o.y - jar.y, o.radius)


def test_more_than_16_objects():
    """20 bottles, colours repeated past the palette's 16 (seeds 0-2): every visible listed bottle found within
    10 mm (identities of repeated colours from the scenario's positions)."""
    for seed in range(3):
        s = with_objects(BASE, generated_layout(BASE, seed, 20))
        f, vis = render_scene(s, seed=seed)
        r = Perception(s).process(f.rgb, f.depth, f.K, q=Q_HOME)
        must, ok = _found(r, s, vis)
        print(f"\nseed {seed}: {len(ok)}/{len(must)} visible found, {len(r.unlisted)} unlisted")
        assert must <= ok, (seed, must - ok, r.missing)


def test_lying_bottle_and_box_published_with_their_orientation():
    """A lying bottle and a box the scenario does not list, and a listed bottle tipped over: published lying or as
    a box, within 15 mm, with their yaw (mod pi for a cylinder's axis, pi/2 for a box)."""
    layout = generated_layout(BASE, 3, 5, taken=[(0.80, 0.20, 0.1), (0.75, -0.05, 0.1), (0.72, -0.25, 0.09)])
    tipped = layout[2]
    extras = (extra(BASE, "lying", CYLINDER, 0.80, 0.20, (0.06, 0.06, 0.15), 0.5, True, PALETTE["orange"]),
              extra(BASE, "box", BOX, 0.75, -0.05, (0.06, 0.10, 0.12), -0.4, False, PALETTE["purple"]),
              replace(tipped, x=0.72, y=-0.25, yaw=1.2, lying=True))
    # the simulator's world: the tipped bottle lying in the scenario's objects, the lying one and the box unlisted
    f, vis = render_scene(with_objects(BASE, [extras[2] if b.id == tipped.id else b for b in layout], extras[:2]))
    # the scenario has the tipped bottle standing where it fell from: its base at one end of the lying one
    stood = replace(tipped, x=0.72 - tipped.height / 2 * math.cos(1.2), y=-0.25 - tipped.height / 2 * math.sin(1.2))
    given = with_objects(BASE, [stood if b.id == tipped.id else b for b in layout])
    r = Perception(given).process(f.rgb, f.depth, f.K, q=Q_HOME)
    for e in extras:
        assert vis[e.id] >= VISIBLE
        o = r.objects.get(e.id) or min(r.unlisted.values(), key=lambda o: math.hypot(o.x - e.x, o.y - e.y))
        period = math.pi if e.shape == CYLINDER else math.pi / 2
        dyaw = abs((o.yaw - e.yaw + period / 2) % period - period / 2)
        print(f"\n{e.id}: {o.id} {o.shape} lying={o.lying} off {1000 * math.hypot(o.x - e.x, o.y - e.y):.1f} mm, "
              f"yaw off {math.degrees(dyaw):.1f} deg, size {np.round(np.array(o.size) * 1000)} mm, rms "
              f"{o.fit_rms * 1000:.1f} mm")
        assert o.shape == e.shape and o.lying == e.lying and not o.conservative and dyaw < math.radians(8)
        axis = np.array([math.cos(e.yaw), math.sin(e.yaw)])
        off = np.array([o.x - e.x, o.y - e.y])
        across, along = abs(float(off @ [-axis[1], axis[0]])), abs(float(off @ axis))
        # along a listed lying cylinder's axis its place is known from an end cap in view; with both ends hidden
        # (here the near one behind the marker plate) it is the visible part's centre: the published cylinder still
        # holds the true centre (off by half the hidden length, 23 mm here); the others within 15 mm
        bound = e.size[2] / 2 if e.lying and o.listed else 0.015
        assert across <= 0.015 and along <= bound, (across, along, bound)
    assert r.objects[tipped.id].listed and r.objects[tipped.id].lying


def test_generated_benchmark_small():
    """The generated benchmark's small version (scripts/bench_perception_objects.py: 5 and 15 bottles, 0-3
    unlisted, some lying, seeds 0-2, realistic camera): no occupied space dropped, no listed id published wrong."""
    for n in (5, 15):
        for seed in range(3):
            case = bench.make_case(seed, n, seed % 4, 1 if seed % 2 else 0)
            sc, _, _ = bench.run_case(case, "realsense_d435", seed)
            assert "refused" not in sc, sc
            print(f"\nn={n} seed {seed}: {sc['found']}/{sc['visible']} found, {sc['covered']} covered")
            assert not sc["dropped"] and not sc["wrong"], sc


def test_a_listed_bottle_not_identified_is_kept_at_its_last_pose_not_made_unlisted():
    """The demo's case: listed bottles seen in one frame, then not identified for three frames (o4 and o7, the
    demo's, their colour hidden: rendered at a third of their brightness) while their points stand where they
    stood: each is that bottle, held at its last pose, never a new unlisted object at its place (the old code
    published its cluster as u1 in every such frame)."""
    s = BASE
    memory = SceneMemory(s.ids, 10, 3)
    p = Perception(s)
    f, _ = render_scene(s)
    memory.update((r := p.process(f.rgb, f.depth, f.K, memory=memory, q=Q_HOME)).objects, r.uncounted)
    assert {"o4", "o7"} <= set(r.detections) and not r.unlisted, (r.missing, r.unlisted)
    dark = with_objects(s, [replace(b, rgb=tuple(c / 3 for c in b.rgb)) if b.id in ("o4", "o7") else b
                            for b in s.objects])
    for k in range(3):
        f, _ = render_scene(dark, seed=k)
        r = p.process(f.rgb, f.depth, f.K, memory=memory, q=Q_HOME)
        published, held, _ = memory.update(r.objects, r.uncounted)
        for i in ("o4", "o7"):
            b = s.object(i)
            at = [f"{u} at ({o.x:.3f}, {o.y:.3f})" for u, o in r.unlisted.items()
                  if math.hypot(o.x - b.x, o.y - b.y) <= b.radius + o.reach]
            assert not at and i not in r.detections, (k, i, at, r.missing.get(i))
            assert r.missing[i].endswith("kept there") and i in held, (k, i, r.missing[i], held)
            o = next(o for o in published if o.id == i)
            assert math.hypot(o.x - b.x, o.y - b.y) <= 0.010
        assert not [o.id for o in published if not o.listed]


def test_a_listed_bottle_lying_along_the_front_edge_is_itself_not_an_unlisted_object():
    """headroom_lying_6 as its simulator renders it: o1 lies across T's front, its axis along the front edge (0.69 m,
    7 cm behind it). Perception must publish it as o1, lying, and nothing unlisted. Before, the 'inside the shelf'
    check took a lying bottle's bounding circle (8.7 cm) for its depth and refused the fit: o1 missing and the
    same bottle published as u1, which the demo then could never retrieve T past ("o1 needs u1 moved")."""
    s = load_scenario("config/scenarios/headroom_lying_6.yaml")
    f, vis = render_scene(s)
    r = Perception(s).process(f.rgb, f.depth, f.K, q=Q_HOME)
    assert vis["o1"] >= VISIBLE
    assert "o1" in r.objects and r.objects["o1"].lying, r.missing.get("o1")
    o1 = s.object("o1")
    assert math.hypot(r.objects["o1"].x - o1.x, r.objects["o1"].y - o1.y) <= 0.015
    assert not r.unlisted, {i: (o.x, o.y) for i, o in r.unlisted.items()}


def test_a_listed_box_is_identified_as_itself_beside_a_listed_bottle():
    """The demo on world/crowd_20 with perception: both listed boxes (o18, o19) were published as unlisted objects at
    their own poses and sizes, reported missing: the size cost knew cylinders only (a box has no radius). Once boxes
    were identified, o18 (60 x 90 mm) 8 mm from o14 was taken to overlap it by 16 mm (the overlap check used the
    box's bounding circle), and o18, o14 and o13 were all published as unlisted. A listed box fitted as a box of its
    size is that box, at its place; a bottle 8 mm from its side is no overlap, both are found, nothing unlisted."""
    yaw, r = -0.4, 0.025
    d = 0.03 + r + 0.008  # the box's short half side, the bottle's radius, 8 mm between them
    bx, by = 0.75 - d * math.cos(yaw), -0.05 - d * math.sin(yaw)  # in front of the box's short side
    layout = generated_layout(BASE, 3, 5, taken=[(0.75, -0.05, 0.1), (bx, by, 0.06)])
    box = extra(BASE, "bx", BOX, 0.75, -0.05, (0.06, 0.10, 0.12), yaw, False, PALETTE["purple"], listed=True)
    bottle = extra(BASE, "by", CYLINDER, bx, by, (2 * r, 2 * r, 0.12), 0.0, False, PALETTE["white"], listed=True)
    s = with_objects(BASE, [*layout, box, bottle])
    f, vis = render_scene(s)
    r_ = Perception(s).process(f.rgb, f.depth, f.K, q=Q_HOME)
    assert vis["bx"] >= VISIBLE and vis["by"] >= VISIBLE, vis
    assert {"bx", "by"} <= set(r_.objects), {i: r_.missing.get(i) for i in ("bx", "by")}
    o = r_.objects["bx"]
    assert o.listed and o.shape == BOX and math.hypot(o.x - 0.75, o.y + 0.05) <= 0.015, o
    assert not r_.unlisted, r_.unlisted


_box_spec = importlib.util.spec_from_file_location(
    "bench_perception_box_face", Path(__file__).resolve().parent.parent / "scripts/bench_perception_box_face.py")
assert _box_spec is not None and _box_spec.loader is not None
box_bench = importlib.util.module_from_spec(_box_spec)
sys.modules[_box_spec.name] = box_bench
_box_spec.loader.exec_module(box_bench)


@pytest.mark.parametrize("camera", ["ideal", "realsense_d435"])
def test_a_listed_box_seen_by_one_face_is_itself(camera):
    """scripts/bench_perception_box_face.py's cases 0-3: a listed box turned to face the camera among listed bottles.
    The old rule named a listed box only when fitted as a box of its size: a box whose top the ceiling board hides,
    or whose top's grazing points are too noisy for the box fit (the realistic camera), showed one face, went out as
    an unlisted conservative box in its place and was reported missing (ideal 3 of 4, realsense_d435 0 of 4 itself).
    The face's extent and height fit one of its faces and its colour and position match: it is itself, within 15 mm
    (ideal 4 of 4; realsense_d435 3 of 4, case 2's face showing only its upper half above a bottle goes out unlisted
    as before: never another id, off or dropped), and no bottle's id is off."""
    outcomes = {seed: box_bench.run_case(seed, camera) for seed in range(4)}
    assert all(o["box_px"] >= VISIBLE for o in outcomes.values()), outcomes
    itself = [s for s, o in outcomes.items() if o["outcome"] == "itself"]
    assert len(itself) >= (4 if camera == "ideal" else 3), outcomes
    assert all(o["outcome"] in ("itself", "unlisted") for o in outcomes.values()), outcomes
    assert all(o["bottles_found"] == o["bottles"] and not o["bottles_off"] for o in outcomes.values()), outcomes


def test_a_box_face_is_no_listed_bottle_and_a_bottle_no_listed_box():
    """The one-face rule never lets a cylinder and a box take each other's place: a listed bottle of a box's colour,
    as wide as the face, expected where an unlisted box faces the camera, does not take that face (flat_margin); a
    listed box expected where a listed bottle of its colour and of its face's width stands, the box absent, does not
    take the bottle's arc (not one flat face): the bottle is itself, the box missing."""
    s = box_bench.make_case(0)
    b = s.object(box_bench.BOX_ID)
    r = min(b.size[1] / 2, 0.04)
    bottle = extra(BASE, "cy", CYLINDER, b.x, b.y, (2 * r, 2 * r, b.height), 0.0, False, b.rgb, listed=True)
    others = [o for o in s.objects if o.id != b.id]
    given = with_objects(BASE, [*others, bottle])
    sim = with_objects(BASE, others, [replace(b, listed=False)])
    f, _ = render_scene(sim)
    res = Perception(given).process(f.rgb, f.depth, f.K, q=Q_HOME)
    assert "cy" not in res.objects, res.objects.get("cy")
    assert any(not o.listed and math.hypot(o.x - b.x, o.y - b.y) <= o.reach for o in res.objects.values())
    given = with_objects(BASE, [*others, bottle, b])
    sim = with_objects(BASE, [*others, bottle])
    f, _ = render_scene(sim)
    res = Perception(given).process(f.rgb, f.depth, f.K, q=Q_HOME)
    assert "cy" in res.objects and math.hypot(res.objects["cy"].x - b.x, res.objects["cy"].y - b.y) <= 0.010
    assert box_bench.BOX_ID not in res.objects, res.objects[box_bench.BOX_ID]


def test_a_listed_bottle_does_not_take_a_box_face_on_crowd_30():
    """The demo on world/crowd_30 at home: o26 (a brown 50 mm box) shows one face (292 px, no primitive fits it);
    o9 (a black 56 mm bottle, 13 cm behind) took that cluster by the sliver rule (a circle of its radius holds the
    face's points, brown within black's colour residual, 1.1 of position cost) and was published at o26's place, o26
    as nothing. A flat face is no cylinder: o9 is not published there, and o26's space is (by o26, or as an unlisted
    object over it)."""
    s = load_scenario("config/scenarios/world/crowd_30.yaml")
    f, vis = render_scene(s)
    r = Perception(s).process(f.rgb, f.depth, f.K, q=Q_HOME)
    box = s.object("o26")
    assert vis["o26"] >= 200, vis["o26"]
    near = {i: round(math.hypot(o.x - box.x, o.y - box.y), 3) for i, o in r.objects.items()
            if math.hypot(o.x - box.x, o.y - box.y) <= 0.05}
    assert "o9" not in r.objects or math.hypot(r.objects["o9"].x - 0.88, r.objects["o9"].y + 0.137) <= 0.015, near
    covering = [i for i in near if i == "o26" or not r.objects[i].listed]
    assert covering, (near, r.missing.get("o26"))


def test_the_listed_boxes_of_shapes_box_10_are_themselves_under_the_realistic_camera():
    """world/shapes_box_10 with the realistic camera (realsense_d435, seed 0): its three listed boxes (o7, o8, o9)
    went out as unlisted conservative boxes, reported missing: the grazing points of their tops and the flying pixels
    along their edges left the box fit above its rms bound. Their faces fit: each is itself within 15 mm, nothing
    unlisted."""
    s = load_scenario("config/scenarios/world/shapes_box_10.yaml")
    f, vis = render_scene(s, sensor=SensorModel.named("realsense_d435"), seed=0)
    r = Perception(s).process(f.rgb, f.depth, f.K, q=Q_HOME)
    for i in ("o7", "o8", "o9"):
        b = s.object(i)
        assert vis[i] >= VISIBLE and i in r.objects, (i, vis[i], r.missing.get(i))
        assert math.hypot(r.objects[i].x - b.x, r.objects[i].y - b.y) <= 0.015, (i, r.objects[i])
    assert not r.unlisted, r.unlisted


def test_a_listed_box_showing_one_face_on_crowd_30_is_itself_and_no_box_is_off():
    """world/crowd_30 at home: o26 (the brown 50 mm box above) shows one whole face and no top: once an unlisted
    conservative box in its place, it is itself (the one-face rule, objects/box_face.py). o29 (60 x 90 mm, its long
    front face half hidden) is not placed by that rule: with a face's extent allowed 2 x size_tol off a side, its
    visible 45 mm of the 90 mm face were taken for its 60 mm face and it was published 27 mm off, turned a quarter.
    Every listed box published is within 15 mm of its place."""
    s = load_scenario("config/scenarios/world/crowd_30.yaml")
    f, _ = render_scene(s)
    r = Perception(s).process(f.rgb, f.depth, f.K, q=Q_HOME)
    o26 = s.object("o26")
    assert "o26" in r.objects and math.hypot(r.objects["o26"].x - o26.x, r.objects["o26"].y - o26.y) <= 0.015, \
        r.missing.get("o26")
    off = {b.id: round(math.hypot(r.objects[b.id].x - b.x, r.objects[b.id].y - b.y), 3) for b in s.objects
           if b.shape == BOX and b.id in r.objects}
    assert all(d <= 0.015 for d in off.values()), off


def test_a_track_does_not_jump_44_cm_unless_the_arm_came_near():
    """The demo on world/crowd_30 during a relocation: o21 (cyan 25 mm bottle), out of view, took a teal bottle's
    cluster of its size 44 cm away (its track capped the position cost at 1) and was published there. A cyan bottle
    seen in frame 1 is hidden in frame 2 (not rendered) while a teal one of its size stands 44 cm from it (not
    listed), the arm at home: the cyan one is not published there (kept at its last pose), the teal one is an
    unlisted object. Had the arm come near the cyan one's last pose (it may have carried it), the track may jump."""
    cyan = extra(BASE, "c1", CYLINDER, 0.70, 0.25, (0.05, 0.05, 0.12), 0.0, False, PALETTE["cyan"], listed=True)
    teal = extra(BASE, "t1", CYLINDER, 0.80, -0.177, (0.05, 0.05, 0.12), 0.0, False, PALETTE["teal"])
    jump = math.hypot(cyan.x - teal.x, cyan.y - teal.y)
    layout = generated_layout(BASE, 5, 4, taken=[(cyan.x, cyan.y, 0.06), (teal.x, teal.y, 0.06)])
    s = with_objects(BASE, [*layout, cyan])
    p = Perception(s)
    for reached in ((), ("c1",)):
        memory = SceneMemory(s.ids, 10, 1)
        f, vis = render_scene(s)
        r = p.process(f.rgb, f.depth, f.K, memory=memory, q=Q_HOME)
        assert "c1" in r.detections and not r.reached, (r.missing.get("c1"), r.reached)
        memory.update(r.objects, r.uncounted, reached)
        f, vis = render_scene(with_objects(BASE, layout, [teal]))   # c1 out of view, the teal bottle in it
        r = p.process(f.rgb, f.depth, f.K, memory=memory, q=Q_HOME)
        assert vis["t1"] >= VISIBLE and vis.get("c1", 0) == 0, vis
        at = r.objects.get("c1")
        moved = None if at is None else math.hypot(at.x - cyan.x, at.y - cyan.y)
        if reached:
            assert moved is not None and abs(moved - jump) <= 0.01, (moved, r.missing.get("c1"))
        else:
            assert at is None, f"c1 jumped {moved:.3f} m to the teal bottle"
            assert [o for o in r.unlisted.values() if math.hypot(o.x - teal.x, o.y - teal.y) <= 0.01], r.unlisted


def test_the_arm_reaches_only_the_objects_near_its_capsules():
    """PerceptionResult.reached (pipeline.arm_reaches): an object whose last pose stands at the arm's hand (its last
    capsule's end at the joint state) is reached, one 40 cm from every capsule is not; no joint state: every one."""
    b = BASE.objects[1]
    hand = arm_segments(np.asarray(Q_HOME, float))[-1][1]
    far = next(p for p in ((hand[0], hand[1] + 0.4), (hand[0], hand[1] - 0.4))
               if all(np.linalg.norm(np.cross(p1 - p0, p0 - np.array([p[0], p[1], hand[2]]))) / np.linalg.norm(p1 - p0)
                      > 0.3 for p0, p1, _ in arm_segments(np.asarray(Q_HOME, float))))
    memory = SceneMemory(("a", "b"), 10, 1)
    memory.update({"a": perceived(replace(b, id="a"), hand[0], hand[1], hand[2] - 0.05),
                   "b": perceived(replace(b, id="b"), far[0], far[1], hand[2] - 0.05)}, ())
    assert arm_reaches(memory, ("a", "b"), np.asarray(Q_HOME, float), 0.03) == {"a"}
    assert arm_reaches(memory, ("a", "b"), None, 0.03) == {"a", "b"}
