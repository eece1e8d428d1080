"""The task_planner node's own parameters (config/task_planner.yaml beside TrainingParams), checked without ROS.

`check_node_parameters` raises ParameterError naming the first unusable one (the node's main() prints it as one
line and exits 2: docs/reliability.md); `SCENE_SOURCES` names the topic each `scene_source` stands for.
"""
from __future__ import annotations

import math
from typing import Callable

from qtree_task_planner.executive.keeper import check_checkpoint_path
from qtree_task_planner.executive.world import Tolerances
from qtree_task_planner.learning.params import TrainingParams
from qtree_task_planner.problem import ActionCosts
from relocation_common.config import ParameterError

SCENE_SOURCES = {"perception": "/scene/objects", "sim": "/sim/objects"}  # scene_source -> topic
POSITIVE_SECONDS = (("scene_max_age", 0.0), ("scene_wait", 0.0), ("feasibility_timeout", 1e-3),
                    ("feasibility_margin", 0.0), ("planner_wait", 0.0), ("relocate_timeout", 1e-3),
                    ("relocate_silence", 1e-3), ("scene_after_wait", 0.0), ("scene_outage_wait", 0.0))  # (name,
# least value)


def check_node_parameters(p: Callable[[str], object]) -> None:
    """ParameterError naming the first unusable parameter; p(name) is the parameter's value."""
    TrainingParams.from_dict({f: p(f) for f in TrainingParams.fields()})
    ActionCosts.from_parameters(p)
    Tolerances.from_parameters(p)
    for name, lo in POSITIVE_SECONDS:
        v = p(name)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v < lo:
            raise ParameterError(f"{name} must be a finite number >= {lo:g}, got {v!r}")
    if p("scene_source") not in ("", *SCENE_SOURCES):
        raise ParameterError(f"scene_source must be one of {', '.join(SCENE_SOURCES)} (or empty: scene_topic), "
                             f"got {p('scene_source')!r}")
    n = p("replicas")
    if isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= 64:
        raise ParameterError(f"replicas must be an integer in 1..64 (motion planners), got {n!r}")
    if not isinstance(p("reuse_answers"), bool):
        raise ParameterError(f"reuse_answers must be true or false, got {p('reuse_answers')!r}")
    every = p("checkpoint_every")
    if isinstance(every, bool) or not isinstance(every, int) or every < 1:
        raise ParameterError(f"checkpoint_every must be an integer >= 1 (episodes), got {every!r}")
    pushes = p("max_pushes")
    if isinstance(pushes, bool) or not isinstance(pushes, int) or pushes < 0:
        raise ParameterError(f"max_pushes must be an integer >= 0 (pushes per goal; 0: none), got {pushes!r}")
    path = p("checkpoint_path")
    if not isinstance(path, str):
        raise ParameterError(f"checkpoint_path must be a string (a file name, or empty), got {path!r}")
    check_checkpoint_path(path)


def pushes_on(p: Callable[[str], object]) -> bool:
    """Whether an execution pushes when no pick sequence remains: closed loop only (an open-loop run never does),
    and max_pushes > 0."""
    pushes = p("max_pushes")
    return bool(p("closed_loop")) and isinstance(pushes, int) and pushes > 0
