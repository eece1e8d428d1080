"""Where the package's files are: the one place that knows (config, scenarios, recorded data).

Installed by colcon (or `./run setup` into the venv), the files live in the package's share directory, found
through the ament index (`share/qtree_relocation/`). Run from a source checkout, they are the checkout's own
`config/` and `data/`. The checkout wins when both exist, so a developer's edits are what runs.
"""
from __future__ import annotations

from functools import lru_cache
from pathlib import Path

PACKAGE = "qtree_relocation"
_SOURCE_ROOT = Path(__file__).resolve().parent.parent  # the checkout, when this module runs from one


class PathsError(FileNotFoundError):
    """The package's share directory cannot be found; the message says how to fix it."""


@lru_cache(maxsize=1)
def share_dir() -> Path:
    """The directory holding `config/` (and, in a checkout, `data/`)."""
    if (_SOURCE_ROOT / "config" / "scenarios").is_dir() and (_SOURCE_ROOT / "package.xml").is_file():
        return _SOURCE_ROOT
    try:
        from ament_index_python.packages import PackageNotFoundError, get_package_share_directory
    except ImportError:  # pragma: no cover - ament_index_python ships with rclpy
        raise PathsError(f"cannot find {PACKAGE}'s config: not a source checkout and ament_index_python "
                         "is not installed") from None
    try:
        return Path(get_package_share_directory(PACKAGE))
    except (PackageNotFoundError, LookupError, ValueError):
        raise PathsError(f"cannot find {PACKAGE}'s config: not a source checkout and the package is not in the "
                         "ament index (source install/setup.bash, or set AMENT_PREFIX_PATH to its install "
                         "prefix)") from None


def config_dir() -> Path:
    """The project's config/ directory (source checkout or installed share)."""
    return share_dir() / "config"


def config_file(name: str) -> Path:
    """config/<name>, e.g. config_file('motion_planner.yaml')."""
    return config_dir() / name


def scenarios_dir() -> Path:
    """config/scenarios/, the scene files."""
    return config_dir() / "scenarios"


def default_scenario() -> Path:
    """The embedded default scene: the paper's real experiment (Sect. 5.2)."""
    return scenarios_dir() / "paper_experiment_10.yaml"


def resolve_scenario(name: str | Path) -> Path:
    """A scenario given as a path (absolute, or relative to the working directory) or as a name under
    config/scenarios (with or without `.yaml`, e.g. 'random5/random5_00', or 'random5_00' when one file of the
    tree has that name)."""
    p = Path(name)
    if p.is_file() or p.is_absolute():
        return p
    for cand in (scenarios_dir() / p, scenarios_dir() / p.with_suffix(".yaml"), share_dir() / p):
        if cand.is_file():
            return cand
    if len(p.parts) == 1:
        found = sorted(scenarios_dir().rglob(p.with_suffix(".yaml").name))
        if len(found) == 1:
            return found[0]
    return p  # let the loader say it cannot be read, naming what was given


def python_path() -> Path:
    """The directory holding the project's Python packages (for PYTHONPATH of child processes)."""
    return _SOURCE_ROOT


def data_dir() -> Path:
    """Recorded data (feasibility caches). Only in a checkout: the evaluation is a developer's tool."""
    return share_dir() / "data"
