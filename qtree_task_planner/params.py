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

import yaml

DEFAULT_PARAMS_FILE = Path(__file__).resolve().parent.parent / "config" / "task_planner.yaml"
NODE_NAME = "task_planner"
POLICIES = ("lrnd", "h-lrnd", "h-eg")
SEARCHES = ("breadth", "depth")
# The task_planner node's own (non-training) parameters: they share config/task_planner.yaml and from_yaml skips
# them; the node validates them (qtree_task_planner.task_planner_node).
NODE_PARAMETERS = ("scene_topic", "scene_source", "scene_max_age", "scene_wait", "feasibility_service", "relocate_action",
                   "feasibility_timeout", "feasibility_margin", "planner_wait", "relocate_timeout", "checkpoint_path",
                   "checkpoint_every")


def read_yaml(path: str | Path, error: type[Exception] = ValueError, what: str = "file"):
    """Parse a YAML file; `error` with one line naming the file (and the line of a syntax error) otherwise. The
    one reader of the project's YAML files: scenarios, node parameters, planner settings."""
    path = Path(path)
    try:
        return yaml.safe_load(path.read_text())
    except OSError as e:
        raise error(f"{path}: cannot read {what} ({e.strerror})") from None
    except yaml.YAMLError as e:
        mark = getattr(e, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""
        raise error(f"{path}: malformed YAML{where}: {getattr(e, 'problem', e)}") from None


class ParameterError(ValueError):
    """A training parameter that cannot be used; the message names it and says what is allowed."""


@dataclass(frozen=True)
class TrainingParams:
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
        def num(name, lo, hi, lo_open=False):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise ParameterError(f"{name} must be a finite number, got {v!r}")
            if v < lo or v > hi or (lo_open and v == lo):
                raise ParameterError(f"{name} must be in {'(' if lo_open else '['}{lo}, {hi}], got {v}")
            object.__setattr__(self, name, float(v))

        def integer(name, lo):
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
        return tuple(f.name for f in dataclasses.fields(cls))

    @classmethod
    def from_dict(cls, d: Mapping[str, Any], base: "TrainingParams | None" = None) -> "TrainingParams":
        """All fields from `d`, or those missing from `base`. Unknown keys are an error (typos are not ignored)."""
        if not isinstance(d, Mapping):
            raise ParameterError(f"parameters must be a mapping, got {type(d).__name__}")
        unknown = sorted(set(d) - set(cls.fields()))
        if unknown:
            raise ParameterError(f"unknown parameter(s): {', '.join(map(str, unknown))}; known: {', '.join(cls.fields())}")
        values = dataclasses.asdict(base) if base is not None else {}
        values.update(d)
        missing = [f for f in cls.fields() if f not in values]
        if missing:
            raise ParameterError(f"missing parameter(s): {', '.join(missing)}")
        return cls(**values)

    @classmethod
    def from_yaml(cls, path: str | Path = DEFAULT_PARAMS_FILE, node: str = NODE_NAME,
                  ignore_unknown: bool = False) -> "TrainingParams":
        """Read `node: ros__parameters: {...}` from a ROS params file. `ignore_unknown` lets a node's other
        parameters share the file; by default an unknown key is an error."""
        path = Path(path)
        data = read_yaml(path, ParameterError, "parameters file")
        try:
            section = data[node]["ros__parameters"]
        except (TypeError, KeyError):
            raise ParameterError(f"{path}: expected '{node}: ros__parameters: {{...}}'") from None
        if not isinstance(section, Mapping):
            raise ParameterError(f"{path}: {node}.ros__parameters must be a mapping")
        if ignore_unknown:
            section = {k: v for k, v in section.items() if k in cls.fields()}
        elif node == NODE_NAME:
            section = {k: v for k, v in section.items() if k not in NODE_PARAMETERS}
        try:
            return cls.from_dict(section)
        except ParameterError as e:
            raise ParameterError(f"{path}: {e}") from None

    @classmethod
    def defaults(cls) -> "TrainingParams":
        return cls.from_yaml(DEFAULT_PARAMS_FILE)

    def replace(self, **changes: Any) -> "TrainingParams":
        """A copy with some fields changed (validated); None values are ignored."""
        return self.from_dict({k: v for k, v in changes.items() if v is not None}, base=self)

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


def check_params_files(argv) -> None:
    """ParameterError (one line) for a `--params-file` in a ROS command line that is unreadable, not YAML, or not a
    mapping of node sections. Called by the nodes' main() before rclpy.init, whose own error is a traceback."""
    argv = list(argv)
    for flag, path in zip(argv, argv[1:]):
        if flag != "--params-file":
            continue
        data = read_yaml(path, ParameterError, "parameters file")
        if not _node_sections(data):
            raise ParameterError(f"{path}: expected '<node>: ros__parameters: {{...}}' sections")


def _node_sections(data) -> bool:
    """Every branch ends in a `ros__parameters` mapping (node names may be nested in namespaces, or `/**`)."""
    if not isinstance(data, Mapping) or not data:
        return False
    if "ros__parameters" in data:
        return isinstance(data["ros__parameters"], Mapping)
    return all(_node_sections(v) for v in data.values())
