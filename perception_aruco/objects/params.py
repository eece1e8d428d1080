"""The parameters of the geometry-first object perception: every one from config/perception.yaml (the node's
declared parameters, or the file itself for the ROS-free core), none with a second default here."""
from __future__ import annotations

import math
from dataclasses import dataclass, fields
from functools import lru_cache
from typing import Any, Callable, Mapping

from relocation_common.config import ParameterError, node_section
from relocation_common.paths import config_file


@dataclass(frozen=True)
class ObjectParams:
    """Clustering, primitive fits, identity and the unlisted objects' weight (config/perception.yaml says what each
    is; docs/perception.md, "Objects", why)."""

    voxel: float
    cluster_eps: float
    cluster_min_samples: int
    cluster_colour: float
    min_cluster_pixels: int
    wall_noise: float
    arm_padding: float
    arm_reach: float
    radius_min: float
    radius_max: float
    size_min: float
    size_max: float
    fit_rms: float
    fit_noise: float
    hidden_extent: float
    unlisted_density: float
    size_tol: float
    flat_margin: float
    arm_near: float
    cluster_gain_min: float
    cluster_gain_max: float
    position_scale: float
    max_cost: float
    unlisted_gate: float
    merge_gap: float
    absorb_tol: float
    absorb_outside: float
    held_tol: float

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
                raise ParameterError(f"perception parameter {f.name} must be a number > 0, got {v!r}")
        if not self.radius_min < self.radius_max or not self.size_min < self.size_max:
            raise ParameterError("perception parameters: need radius_min < radius_max and size_min < size_max")

    @classmethod
    def from_mapping(cls, values: Mapping[str, Any]) -> ObjectParams:
        """From the node's parameters (or the file's section): every field must be there."""
        missing = [f.name for f in fields(cls) if f.name not in values]
        if missing:
            raise ParameterError(f"perception parameters missing: {', '.join(missing)} (config/perception.yaml)")
        return cls(**{f.name: values[f.name] for f in fields(cls)})

    @classmethod
    def configured(cls) -> ObjectParams:
        """From config/perception.yaml (the node's file), for the ROS-free core, tests and benchmarks."""
        return cls.from_mapping(node_section(config_file("perception.yaml"), "perception"))


@lru_cache(maxsize=1)
def section() -> dict[str, Any]:
    """The `perception` node's parameters in config/perception.yaml, read once: also the one place of the values the
    core's other parameter dataclasses share with the node (segmentation.SegmentationParams, localize.LocalizeParams),
    so a core built without the node (tests, benchmarks, the calibration) uses the node's values."""
    return dict(node_section(config_file("perception.yaml"), "perception"))


def value(name: str) -> Callable[[], Any]:
    """A dataclass field's default_factory: the file's value of `name` (KeyError naming it when the file lacks it)."""
    return lambda: section()[name]
