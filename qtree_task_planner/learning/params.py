"""Training parameters of the Q-Tree (alpha, gamma of Eq. 7; epsilon0, epsilon_min of Eq. 14; E_max, I_max;
beta of Eq. 16; policy, search, seed). Their defaults live in ONE place: config/task_planner.yaml (ROS
params-file form); this module validates and loads them.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping

from relocation_common.config import ParameterError, node_section
from relocation_common.paths import config_file

NODE_NAME = "task_planner"
POLICIES = ("lrnd", "h-lrnd", "h-eg")
SEARCHES = ("breadth", "depth")


@dataclass(frozen=True)
class TrainingParams:
    """The Q-Tree training parameters (Sect. 4.2; Eq. 7, 14, 16), validated; defaults in config/task_planner.yaml."""

    policy: str
    search: str
    alpha: float
    gamma: float
    epsilon0: float
    epsilon_min: float
    max_episodes: int  # E_max
    max_steps: int  # I_max
    beta: float
    quiet_episodes: int
    seed: int

    def __post_init__(self) -> None:
        def num(name: str, lo: float, hi: float, lo_open: bool = False) -> None:
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise ParameterError(f"{name} must be a finite number, got {v!r}")
            if v < lo or v > hi or (lo_open and v == lo):
                raise ParameterError(f"{name} must be in {'(' if lo_open else '['}{lo}, {hi}], got {v}")
            object.__setattr__(self, name, float(v))

        def integer(name: str, lo: int) -> None:
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) and not (isinstance(v, float) and v.is_integer()):
                raise ParameterError(f"{name} must be an integer, got {v!r}")
            if v < lo:
                raise ParameterError(f"{name} must be >= {lo}, got {int(v)}")
            object.__setattr__(self, name, int(v))

        if self.policy not in POLICIES:
            raise ParameterError(f"policy must be one of {', '.join(POLICIES)}, got {self.policy!r}")
        if self.search not in SEARCHES:
            raise ParameterError(f"search must be one of {', '.join(SEARCHES)}, got {self.search!r}")
        num("alpha", 0.0, 1.0)
        num("gamma", 0.0, 1.0)
        num("epsilon0", 0.0, 1.0, lo_open=True)
        num("epsilon_min", 0.0, 1.0, lo_open=True)
        if self.epsilon_min > self.epsilon0:
            raise ParameterError(f"epsilon_min ({self.epsilon_min}) must not exceed epsilon0 ({self.epsilon0})")
        num("beta", 0.0, math.inf)
        integer("max_episodes", 1)
        integer("max_steps", 1)
        integer("quiet_episodes", 1)
        integer("seed", 0)

    @classmethod
    def fields(cls) -> tuple[str, ...]:
        """The parameter names."""
        return tuple(f.name for f in dataclasses.fields(cls))

    @classmethod
    def from_dict(cls, d: Mapping[str, Any], base: "TrainingParams | None" = None) -> "TrainingParams":
        """All fields from `d`, or those missing from `base`. Unknown keys are an error (typos are not ignored)."""
        if not isinstance(d, Mapping):
            raise ParameterError(f"parameters must be a mapping, got {type(d).__name__}")
        unknown = sorted(set(d) - set(cls.fields()))
        if unknown:
            raise ParameterError(f"unknown parameter(s): {', '.join(map(str, unknown))}; "
                                 f"known: {', '.join(cls.fields())}")
        values = dataclasses.asdict(base) if base is not None else {}
        values.update(d)
        missing = [f for f in cls.fields() if f not in values]
        if missing:
            raise ParameterError(f"missing parameter(s): {', '.join(missing)}")
        return cls(**values)

    @classmethod
    def from_yaml(cls, path: str | Path | None = None, node: str = NODE_NAME,
                  ignore_unknown: bool = False) -> "TrainingParams":
        """Read `node: ros__parameters: {...}` from a ROS params file (default config/task_planner.yaml). Keys the
        shipped file gives the task_planner node for itself are skipped; any other unknown key is an error unless
        `ignore_unknown` (typos are not ignored)."""
        shipped = config_file("task_planner.yaml")
        path = Path(path) if path is not None else shipped
        section = node_section(path, node)
        if ignore_unknown:
            skip = set(section) - set(cls.fields())
        else:
            skip = set(node_section(shipped, NODE_NAME)) - set(cls.fields())
        try:
            return cls.from_dict({k: v for k, v in section.items() if k not in skip})
        except ParameterError as e:
            raise ParameterError(f"{path}: {e}") from None

    @classmethod
    def defaults(cls) -> "TrainingParams":
        """config/task_planner.yaml's training parameters: the one place for their defaults."""
        return cls.from_yaml()

    def replace(self, **changes: Any) -> "TrainingParams":
        """A copy with some fields changed (validated); None values are ignored."""
        return self.from_dict({k: v for k, v in changes.items() if v is not None}, base=self)

    def to_dict(self) -> dict[str, Any]:
        """Plain data (JSON, checkpoints)."""
        return dataclasses.asdict(self)
