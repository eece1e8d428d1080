"""Perception's parameters have one source, config/perception.yaml: the core's dataclasses that share values with the
node (segmentation.SegmentationParams: gain_min, gain_max, max_residual; localize.LocalizeParams: min_pixels,
inlier_tol) take them from the file, so a core built without the node uses the node's values. Before, the dataclasses
carried a second set of defaults: a value changed in the file reached the node but not the tests, benchmarks or the
calibration."""
from dataclasses import MISSING, fields

from perception_aruco.localize import LocalizeParams
from perception_aruco.objects import params as configured
from perception_aruco.objects.params import ObjectParams
from perception_aruco.segmentation import SegmentationParams
from relocation_common.config import node_section
from relocation_common.paths import config_file

SHARED = {SegmentationParams: ("gain_min", "gain_max", "max_residual"), LocalizeParams: ("min_pixels", "inlier_tol")}


def test_the_shared_values_are_the_files(monkeypatch):
    values = node_section(config_file("perception.yaml"), "perception")
    for cls, names in SHARED.items():
        built = cls()
        assert {n: getattr(built, n) for n in names} == {n: values[n] for n in names}
    changed = {**configured.section(), "gain_max": 1.7, "inlier_tol": 0.005}
    monkeypatch.setattr(configured, "section", lambda: changed)
    assert SegmentationParams().gain_max == 1.7 and LocalizeParams().inlier_tol == 0.005


def test_no_field_of_the_file_has_a_second_default():
    """Every dataclass field named like a key of the file takes its default from the file (ObjectParams: none)."""
    keys = set(node_section(config_file("perception.yaml"), "perception"))
    for cls in (SegmentationParams, LocalizeParams):
        for f in fields(cls):
            if f.name in keys:
                assert f.name in SHARED[cls], f"{cls.__name__}.{f.name} is in config/perception.yaml: read it there"
    assert all(f.default is MISSING and f.default_factory is MISSING for f in fields(ObjectParams))  # none
