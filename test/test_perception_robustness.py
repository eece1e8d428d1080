"""Perception on perturbed frames (the cases of scripts/bench_perception_robustness.py that published a wrong scene
before the consistency checks, docs/perception.md): it either places every bottle within 10 mm or refuses with the
reason; never silently wrong. Plus the sensor model (jaco2_sim_driver/sensor_model.py), the frame fusion and the
identity check against the previous scene."""
import importlib.util
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from perception_scenes import perceived

from jaco2_sim_driver import sensor_model as sm
from jaco2_sim_driver.camera import render_frame
from perception_aruco.aruco import MarkerOccludedError, PerceptionError
from perception_aruco.pipeline import FrameFusion, Perception, identity_conflicts
from relocation_common.paths import scenarios_dir
from relocation_common.scenario import load_scenario

_spec = importlib.util.spec_from_file_location(
    "bench_perception_robustness", Path(__file__).resolve().parent.parent / "scripts/bench_perception_robustness.py")
assert _spec is not None and _spec.loader is not None
bench = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(bench)


@pytest.fixture(scope="module")
def frames():
    out = {}
    for name in ("paper_experiment_10", "blocking_10"):
        s = load_scenario(scenarios_dir() / f"{name}.yaml")
        out[name] = (s, render_frame(s))
    return out


def _wrong(truth, result) -> list[str]:
    """Published bottles more than 10 mm from their own ground truth (wrong place or wrong identity)."""
    return [f"{i} {math.hypot(d.x - truth.object(i).x, d.y - truth.object(i).y) * 1000:.0f} mm off"
            for i, d in result.detections.items()
            if math.hypot(d.x - truth.object(i).x, d.y - truth.object(i).y) > 0.01]


def _case(frames, name, cat, level):
    s, f = frames[name]
    rng = np.random.default_rng([0, bench.SCENES.index(name), bench.CATEGORIES.index(cat), level, 0])
    given, K, rgb, depth = bench.perturb(cat, level, s, f, rng, None)
    return s, given, K, rgb, depth


@pytest.mark.parametrize("name,cat,level", [
    ("paper_experiment_10", "marker_occl", 1),   # a 7 mm object on the marker: was 10-17 mm off, published
    ("paper_experiment_10", "marker_pose", 2),   # the scenario's marker 2 cm / 2 deg off: was 10-17 mm off
    ("blocking_10", "wb_warm", 3),               # warm white balance: o4 was published where o7 stands
    ("blocking_10", "wb_cool", 2),               # cool white balance: o7 was published where o4 stands
    ("blocking_10", "depth_noise", 2),           # 3 mm depth noise at 0.75 m: o7 was 12 mm off
])
def test_perturbed_frame_is_right_or_refused(frames, name, cat, level):
    truth, given, K, rgb, depth = _case(frames, name, cat, level)
    try:
        r = Perception(given).process(rgb, depth, K)
    except PerceptionError as e:
        assert str(e)  # refused, with its reason
        return
    assert not _wrong(truth, r), _wrong(truth, r)
    if truth.target_id in r.detections:
        assert len(r.detections) >= 5, r.missing


def test_covered_marker_corner_is_named(frames):
    """A corner of the only marker covered: the marker is not decoded; with the pose of earlier frames the reason
    names the covered corners (not 'not in view') and the shelf confirms the earlier pose, so the bottles stay
    placed (test_perception_markers: a second marker carries the frame)."""
    s = replace(frames["paper_experiment_10"][0], more_markers=())   # one marker: the prior bridges it
    f = render_frame(s)
    p = Perception(s)
    prior = p.process(f.rgb, f.depth, f.K).T_base_camera
    g = bench.cover_marker(s, f, 3, np.random.default_rng(0))
    with pytest.raises(MarkerOccludedError, match="corners on an occluding edge"):
        p.localizer.locate(g.rgb, f.K, g.depth, expected=np.linalg.inv(prior) @ p.localizer.T_base_marker)
    r = p.process(g.rgb, g.depth, f.K, prior=prior)
    assert r.marker is None and "partly covered" in r.notes[0]
    assert not _wrong(s, r) and len(r.detections) >= 9


def test_sensor_model_is_seeded_and_noise_grows_with_distance_squared():
    depth = np.full((200, 200), 0.5, np.float32)
    depth[:, 100:] = 1.0
    a = sm.depth_noise(depth, 0.002, np.random.default_rng(1))
    b = sm.depth_noise(depth, 0.002, np.random.default_rng(1))
    assert np.array_equal(a, b)
    near, far = np.std(a[:, :100] - 0.5), np.std(a[:, 100:] - 1.0)
    assert far / near == pytest.approx(4.0, rel=0.15)   # (1.0 / 0.5)^2
    holes = sm.depth_holes(depth, 0.05, np.random.default_rng(2))
    assert 0.03 < np.mean(holes == 0) < 0.07
    edges = sm.edge_holes_and_flying_pixels(depth, np.random.default_rng(3))
    changed = edges != depth
    assert changed.any() and np.all(np.abs(np.nonzero(changed)[1] - 100) <= 1)  # only at the depth edge
    rgb = np.full((4, 4, 3), 100, np.uint8)
    assert tuple(sm.white_balance(rgb, sm.warm(0.2))[0, 0]) == (120, 100, 80)
    with pytest.raises(ValueError, match="ideal, realsense_d435"):
        sm.SensorModel.named("kinect")
    sim = sm.SensorSimulator(sm.SensorModel.named("realsense_d435"), seed=4)
    c, d = sim.apply(np.full((50, 50, 3), 128, np.uint8), np.full((50, 50), 0.75, np.float32))
    valid = d[d > 0]
    assert 0.0015 < np.std(valid) < 0.0025 and np.mean(d == 0) < 0.05 and c.std() > 1


def test_frame_fusion_refuses_a_jump_and_restarts_when_the_camera_moved():
    fusion = FrameFusion(max_jump=0.005, max_jump_deg=0.5, reset_after=3)
    t = np.eye(4)
    assert fusion.update(t) is None
    t2 = t.copy()
    t2[0, 3] = 0.002
    assert fusion.update(t2) is None and fusion.fused[0, 3] == pytest.approx(0.001)
    moved = t.copy()
    moved[1, 3] = 0.05
    assert "mm" in fusion.update(moved) and "mm" in fusion.update(moved)
    assert fusion.update(moved) is None and fusion.fused[1, 3] == pytest.approx(0.05)


def test_identity_conflict_with_the_previous_scene(frames):
    s, _ = frames["blocking_10"]
    o4, o7 = s.object("o4"), s.object("o7")

    def det(i, x, y):
        return perceived(s.object(i), x, y, s.shelf.top_z)
    previous = {"o4": det("o4", o4.x, o4.y), "o7": det("o7", o7.x, o7.y)}
    assert not identity_conflicts({"o4": det("o4", o4.x, o4.y), "o7": det("o7", o7.x, o7.y)}, previous)
    doubt = identity_conflicts({"o4": det("o4", o7.x, o7.y)}, previous)   # o4 where o7 stood, o7 gone
    assert "o7" in doubt["o4"]


def test_realistic_sensor_within_3_mm_median_8_mm_max(frames):
    """The simulator's realsense_d435 camera model (docs/sim_driver.md): the bottles placed within the targets."""
    s, _ = frames["paper_experiment_10"]
    f = render_frame(s, sensor=sm.SensorModel.named("realsense_d435"), seed=1)
    r = Perception(s).process(f.rgb, f.depth, f.K)
    err = [math.hypot(d.x - s.object(i).x, d.y - s.object(i).y) for i, d in r.detections.items()]
    print(f"\nrealsense_d435: {len(err)} bottles, median {np.median(err) * 1000:.1f} mm, max {max(err) * 1000:.1f} mm")
    assert s.target_id in r.detections and len(err) >= 9, r.missing
    assert np.median(err) <= 0.003 and max(err) <= 0.008


def test_depth_holes_do_not_grow(frames):
    """5 % of the depth missing loses about 5 % of a colour class's pixels, not more (the erosion ignores holes)."""
    from perception_aruco.segmentation import segment
    s, f = frames["blocking_10"]
    holes = sm.depth_holes(f.depth, 0.05, np.random.default_rng(0), clump_px=1)
    clean = np.sum(segment(f.rgb, f.depth, f.K, f.T_base_camera, s).labels >= 0)
    holed = np.sum(segment(f.rgb, holes, f.K, f.T_base_camera, s).labels >= 0)
    assert holed >= 0.9 * clean, (holed, clean)


def test_gross_errors_are_refused_with_the_reason(frames):
    """camera_info 8 % off in focal length, or the scenario's marker 8 cm off: the code before the checks published
    every bottle 1-3 cm off; now the frame is refused and the reason names what to check."""
    from dataclasses import replace
    s, f = frames["paper_experiment_10"]
    K = f.K.copy()
    K[0, 0] *= 1.08
    K[1, 1] *= 1.08
    with pytest.raises(PerceptionError, match="disagree|camera_info"):
        Perception(s).process(f.rgb, f.depth, K)
    m = s.marker
    moved = replace(s, marker=replace(m, position=(m.position[0], m.position[1] + 0.08, m.position[2])))
    with pytest.raises(PerceptionError, match="marker pose"):
        Perception(moved).process(f.rgb, f.depth, f.K)
