"""Reading the project's YAML (scenarios, node parameters, planner settings) and the errors for bad input.

One reader, one error family: every message is one line naming the file (and, for a syntax error, the line and
column), so a node can print it and exit 2 instead of showing a traceback.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any, Iterable, Mapping

import yaml

MAX_FILE_BYTES = 1 << 20  # scenarios and parameter files are a few kB; a 50 MB one was a mistake or an attack
MAX_DEPTH = 32  # mapping/list nesting: deeper is refused before Python's recursion limit is reached
MAX_MESSAGE = 300  # characters of an error message (a value's repr can be megabytes)


def short(value: Any, limit: int = 60) -> str:
    """repr of a value for an error message, cut to `limit` characters."""
    text = repr(value)
    return text if len(text) <= limit else text[:limit - 3] + "..."


class ConfigError(ValueError):
    """Input that cannot be used (a file, a parameter, a scene); the message says what and where, in one line
    (newlines folded, cut to MAX_MESSAGE characters)."""

    def __init__(self, message: object = "") -> None:
        text = " ".join(str(message).split())
        super().__init__(text if len(text) <= MAX_MESSAGE else text[:MAX_MESSAGE - 3] + "...")


class ParameterError(ConfigError):
    """A parameter that cannot be used; the message names it and says what is allowed."""


class _StrictLoader(yaml.SafeLoader):
    """SafeLoader without aliases (a "billion laughs" expands a few lines into gigabytes) and with bounded
    nesting (deep nesting ended in a RecursionError traceback)."""

    def compose_node(self, parent: yaml.Node | None, index: Any) -> yaml.Node | None:
        if self.check_event(yaml.AliasEvent):
            event = self.peek_event()
            raise yaml.composer.ComposerError(None, None, "aliases (*name) are not allowed here", event.start_mark)
        self._depth = getattr(self, "_depth", 0) + 1
        try:
            if self._depth > MAX_DEPTH:
                raise yaml.composer.ComposerError(None, None, f"nested deeper than {MAX_DEPTH} levels",
                                                  self.peek_event().start_mark)
            return super().compose_node(parent, index)
        finally:
            self._depth -= 1


def read_yaml(path: str | Path, error: type[Exception] = ConfigError, what: str = "file") -> Any:
    """Parse a YAML file; `error` with one line naming the file (and the line of a syntax error) otherwise.
    Refused: files over MAX_FILE_BYTES, aliases, nesting deeper than MAX_DEPTH, anything that is not a regular
    file (a FIFO would block)."""
    path = Path(path)
    try:
        if path.exists() and not path.is_file():
            raise error(f"{path}: cannot read {what} (not a regular file)")
        size = path.stat().st_size
        if size > MAX_FILE_BYTES:
            raise error(f"{path}: {what} too large ({size} bytes > {MAX_FILE_BYTES})")
        text = path.read_text()
    except OSError as e:
        raise error(f"{path}: cannot read {what} ({e.strerror})") from None
    except UnicodeDecodeError:
        raise error(f"{path}: {what} is not UTF-8 text") from None
    try:
        return yaml.load(text, Loader=_StrictLoader)  # noqa: S506 - a SafeLoader subclass
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


def check_params_files(argv: Iterable[str]) -> None:
    """ParameterError (one line) for a `--params-file` in a ROS command line that is unreadable, not YAML, or not a
    mapping of node sections. Called by the nodes' main() before rclpy.init, whose own error is a traceback."""
    argv = list(argv)
    for flag, path in zip(argv, argv[1:]):
        if flag != "--params-file":
            continue
        data = read_yaml(path, ParameterError, "parameters file")
        if not _node_sections(data):
            raise ParameterError(f"{path}: expected '<node>: ros__parameters: {{...}}' sections")


def _node_sections(data: Any) -> bool:
    """Every branch ends in a `ros__parameters` mapping (node names may be nested in namespaces, or `/**`)."""
    if not isinstance(data, Mapping) or not data:
        return False
    if "ros__parameters" in data:
        return isinstance(data["ros__parameters"], Mapping)
    return all(_node_sections(v) for v in data.values())
