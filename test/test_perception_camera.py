"""Perception on a real camera's frames: the cases of scripts/bench_perception_robustness.py that were reported
missing or refused before (docs/bench/perception.md, "Summary per category"), one per failure mode: a marker plate
off its scenario pose taken for bottles, markers that disagree, a covered marker on the blocking scenes (the arm at
Q_HOME hid the second one), colour noise sigma 20, blur sigma 2 px, exposure x1.7, low resolutions. Each is now
placed within 10 mm, never wrong."""
import importlib.util
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from jaco2_sim_driver import sensor_model as sm
from jaco2_sim_driver.camera import render_frame
from jaco2_sim_driver.params import CameraSpec
from perception_aruco.aruco import MarkerLocalizer
from perception_aruco.pipeline import Perception
from perception_aruco.segmentation import SegmentationParams, classify_colours, plate_levels
from relocation_common.paths import scenarios_dir
from relocation_common.scenario import PALETTE, load_scenario

_spec = importlib.util.spec_from_file_location(
    "bench_perception_robustness", Path(__file__).resolve().parent.parent / "scripts/bench_perception_robustness.py")
assert _spec is not None and _spec.loader is not None
bench = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(bench)

_FRAMES: dict = {}


def _frame(name: str):
    """(scenario, frame at Q_HOME, ids the benchmark requires: >= 300 pixels in view), rendered once."""
    if name not in _FRAMES:
        s = load_scenario(scenarios_dir() / f"{name}.yaml")
        f = render_frame(s)
        _FRAMES[name] = (s, f, {i for i, n in bench.visible_pixels(s, bench.Q_HOME).items()
                                if n >= bench.VISIBLE_PIXELS})
    return _FRAMES[name]


def _bench_case(name: str, cat: str, level: int):
    """The benchmark's case (same seed, same draws): (truth, result, required ids)."""
    s, f, required = _frame(name)
    rng = np.random.default_rng([0, bench.SCENES.index(name), bench.CATEGORIES.index(cat), level, 0])
    cover = sorted(required)[int(rng.integers(len(required)))]
    given, K, rgb, depth = bench.perturb(cat, level, s, f, rng, cover)
    return s, Perception(given).process(rgb, depth, K), required


def _errors(truth, result) -> dict[str, float]:
    return {i: math.hypot(d.x - truth.object(i).x, d.y - truth.object(i).y) for i, d in result.detections.items()}


@pytest.mark.parametrize("name,cat,level,why", [
    # the marker's plate, 3 cm from its scenario pose, passed the workspace gate: its white and black were taken for
    # the white and black bottles ("only 479 of 4212 points within 4 mm of the fitted circle")
    ("blocking_15", "marker_pose", 3, "plate"),
    # marker 8 seen 44 mm from where the moved marker 7 put it: refused; now the shelf confirms marker 8's frame
    ("paper_experiment_10", "marker_pose", 3, "disagree"),
    # a third of marker 7 covered on a blocking scene: marker 8 (hidden by the arm at Q_HOME) could not stand in
    ("blocking_10", "marker_occl", 3, "arm"),
    # colour noise sigma 20: the dark bottles lost their pixels ("33 pixels of colour 'brown'")
    ("paper_experiment_10", "colour_noise", 3, "noise"),
    ("scenario2_10", "colour_noise", 3, "noise"),
    # blur sigma 2 px: the brown bottle's edge pixels mixed into 'orange' ("colour 'orange' seen at two places")
    ("paper_experiment_10", "blur", 3, "blur"),
    ("blocking_10", "blur", 3, "blur"),
    # exposure x1.7: orange's red saturates, the rest reads as yellow ("colour 'yellow' seen at two places")
    ("paper_experiment_10", "exposure", 3, "exposure"),
    ("scenario2_10", "exposure", 3, "exposure"),
])
def test_case_now_ok(name, cat, level, why):
    truth, r, required = _bench_case(name, cat, level)
    err = _errors(truth, r)
    assert max(err.values()) < 0.002, {i: e for i, e in err.items() if e >= 0.002}
    assert required <= set(r.detections), {i: r.missing.get(i) for i in required - set(r.detections)}
    if why == "disagree":
        assert any("the shelf confirms marker id 8" in n for n in r.notes), r.notes


def test_blocking_scene_second_marker_seen_past_the_arm():
    """The blocking scenes' marker 8 stands on the shelf's top: the arm at Q_HOME does not hide it."""
    s, f, _ = _frame("blocking_10")
    r = Perception(s).process(f.rgb, f.depth, f.K)
    assert any(n.startswith("markers 7, 8 fused") for n in r.notes), r.notes


def test_colour_noise_measured_on_the_marker():
    """The noise on the marker's white (Laplacian-difference kernel): ~0 on a clean frame, the sigma added."""
    s, f, _ = _frame("paper_experiment_10")
    corners = MarkerLocalizer(s.marker).detect(f.rgb)
    assert plate_levels(f.rgb, corners).noise < 1.0
    for sigma in (5.0, 20.0):
        noisy = sm.colour_noise(f.rgb, sigma, np.random.default_rng(1))
        assert abs(plate_levels(noisy, corners).noise - sigma) < 0.15 * sigma


def test_blur_measured_on_the_marker():
    """The blur of the marker's edges: ~0.8 px on a sharp frame (anti-aliasing), growing with the blur added;
    colour noise does not pass for blur."""
    s, f, _ = _frame("blocking_10")
    corners = MarkerLocalizer(s.marker).detect(f.rgb)
    sharp, blurred = plate_levels(f.rgb, corners).blur, plate_levels(sm.blur(f.rgb, 2.0), corners).blur
    noisy = plate_levels(sm.colour_noise(f.rgb, 20.0, np.random.default_rng(1)), corners).blur
    assert sharp < 1.0 and blurred > 1.7 and noisy < 1.0, (sharp, blurred, noisy)


def test_saturated_channel_is_a_lower_bound():
    """An over-exposed orange pixel (red saturated) reads as yellow from its values; with the red taken as a lower
    bound it is orange. A yellow pixel that is not saturated stays yellow."""
    refs = np.array([PALETTE["orange"], PALETTE["yellow"]]) * 255.0
    over = np.array([[195.0, 169.0, 17.0]])   # orange x1.7 after the plate normalisation, red at its clip level
    params = SegmentationParams()
    assert classify_colours(over, refs, params)[0] == 1                                   # values alone: yellow
    assert classify_colours(over, refs, params, np.array([[True, False, False]]))[0] == 0  # red censored: orange
    yellow = np.array([[157.0, 141.0, 16.6]])
    assert classify_colours(yellow, refs, params, np.zeros((1, 3), bool))[0] == 1


@pytest.mark.parametrize("name,size", [
    ("scenario2_10", (320, 240)),          # the target showed 5 pixels after the erosion: refused
    ("paper_experiment_10", (424, 240)),   # no side panel over the pixel bound: bottles 3-9 mm off along the front
])
def test_low_resolution(name, size):
    s = load_scenario(scenarios_dir() / f"{name}.yaml")
    f = render_frame(s, camera=replace(CameraSpec.configured(), width=size[0], height=size[1]))
    r = Perception(s).process(f.rgb, f.depth, f.K)
    err = _errors(s, r)
    assert s.target_id in r.detections, r.missing
    assert max(err.values()) < 0.002, {i: e for i, e in err.items() if e >= 0.002}
