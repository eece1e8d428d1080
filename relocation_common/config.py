"""Reading the project's YAML (scenarios, node parameters, planner settings) and the errors for bad input.

One reader, one error family: every message is one line naming the file (and, for a syntax error, the line and
column), so a node can print it and exit 2 instead of showing a traceback.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any, Mapping

import yaml


class ConfigError(ValueError):
    """Input that cannot be used (a file, a parameter, a scene); the message says what and where, in one line."""


class ParameterError(ConfigError):
    """A parameter that cannot be used; the message names it and says what is allowed."""


def read_yaml(path: str | Path, error: type[Exception] = ConfigError, what: str = "file"):
    """Parse a YAML file; `error` with one line naming the file (and the line of a syntax error) otherwise."""
    path = Path(path)
    try:
        return yaml.safe_load(path.read_text())
    except OSError as e:
        raise error(f"{path}: cannot read {what} ({e.strerror})") from None
    except yaml.YAMLError as e:
        mark = getattr(e, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""
        raise error(f"{path}: malformed YAML{where}: {getattr(e, 'problem', e)}") from None


def node_section(path: str | Path, node: str) -> dict[str, Any]:
    """The `node: ros__parameters: {...}` mapping of a ROS params file; ParameterError naming the file otherwise."""
    data = read_yaml(path, ParameterError, "parameters file")
    try:
        section = data[node]["ros__parameters"]
    except (TypeError, KeyError):
        raise ParameterError(f"{path}: expected '{node}: ros__parameters: {{...}}'") from None
    if not isinstance(section, Mapping):
        raise ParameterError(f"{path}: {node}.ros__parameters must be a mapping")
    return dict(section)


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
