"""The motion planner's journal: what a new process needs after the old one died mid-relocation or mid-push
(ROS-free).

A relocation's `Progress` (the object, the removed set, the bottles placed, the motions followed so far, whether the
bottle was released) is written before each motion and at the release, with the slot and the scene seen before the
motion (for the outcome check), and the bottles this node placed on the bottom shelf (`relocated`). A push is
journalled the same way (execution.push: its `Progress`, each motion recorded before it starts, the approach before
the gripper shuts) with its plan (`Running.push`: the object's predicted end pose, the lane, every planned motion),
written once planned, before the arm moves; `push.recover_push` then brings the arm home from where it is (on
along the retreat and the way home once the object was pushed, else back along the motions made) and opens the
fingers. The file is JSON, written atomically (temporary file, fsync, os.replace), so a SIGKILL at any moment leaves
the previous entry or the new one, never half of one. A new process reads it (`load`): `running` not None means a
relocation (or push) was interrupted; `relocation.recover` brings the arm back along the recorded motions (the
bottle set down where it was picked, or, once released, the arm home), as after a cancel. docs/reliability.md, "A
node that dies".
"""
from __future__ import annotations

import json
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from stpik_motion_planner.execution.relocation import Progress
from stpik_motion_planner.planning.push import PushPlan
from stpik_motion_planner.planning.results import Segment
from stpik_motion_planner.planning.trajectory import Trajectory

FORMAT = "qtree-motion-planner-journal/1"
NEAR_RECORDED = 0.2  # rad (largest joint): an arm this close to a recorded motion is where the journal left it


@dataclass
class Running:
    """An unfinished relocation or push: its progress, its slot (a push: -1), the scene before its motion ((id, x,
    y, base z)), and for a push its plan (None: a relocation)."""

    progress: Progress
    slot: int
    before: list[tuple[str, float, float, float]]
    push: PushPlan | None


class JournalError(ValueError):
    """The journal cannot be read (named file, reason): the node starts without it and says so."""


class Journal:
    """The journal file at `path` ("" or None: none kept, every call a no-op)."""

    def __init__(self, path: str | Path | None) -> None:
        self.path = Path(path) if path else None

    def write(self, relocated: dict[str, int], running: Running | None) -> None:
        """The journal now: the bottles this node placed (id -> slot) and the relocation in progress (or None)."""
        if self.path is None:
            return
        data: dict[str, Any] = {"format": FORMAT, "relocated": dict(relocated), "running": None}
        if running is not None:
            p = running.progress
            data["running"] = {"object_id": p.object_id, "removed": list(p.removed), "released": p.released,
                               "carried": p.carried,
                               "placed": [[i, list(xy)] for i, xy in p.placed], "slot": running.slot,
                               "before": [list(b) for b in running.before],
                               "moves": [[phase, _trajectory(t)] for phase, t in p.moves],
                               "push": None if running.push is None else _push(running.push)}
        self.path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=self.path.parent, prefix=self.path.name + ".")
        try:
            with os.fdopen(fd, "w") as f:
                json.dump(data, f)
                f.flush()
                os.fsync(f.fileno())
            os.replace(tmp, self.path)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise

    def load(self) -> tuple[dict[str, int], Running | None]:
        """(relocated, running) as last written; ({}, None) without a file. JournalError when it cannot be read."""
        if self.path is None or not self.path.exists():
            return {}, None
        try:
            data = json.loads(self.path.read_text())
            if data.get("format") != FORMAT:
                raise ValueError(f"format {data.get('format')!r}, expected {FORMAT!r}")
            relocated = {str(k): int(v) for k, v in data["relocated"].items()}
            r = data["running"]
            if r is None:
                return relocated, None
            progress = Progress(str(r["object_id"]), [str(i) for i in r["removed"]],
                                [(str(i), (float(xy[0]), float(xy[1]))) for i, xy in r["placed"]],
                                [(str(phase), _from(t)) for phase, t in r["moves"]], bool(r["released"]),
                                bool(r["carried"]))
            before = [(str(i), float(x), float(y), float(z)) for i, x, y, z in r["before"]]
            push = None if r.get("push") is None else _push_from(r["push"])
            return relocated, Running(progress, int(r["slot"]), before, push)
        except (OSError, ValueError, KeyError, TypeError, IndexError) as e:
            raise JournalError(f"journal {self.path} unreadable: {type(e).__name__}: {e}") from None

    def clear(self) -> None:
        """Forget everything (a fresh world: the demo starts a new simulator)."""
        if self.path is not None:
            self.path.unlink(missing_ok=True)


def near_recorded(progress: Progress, q: np.ndarray) -> bool:
    """True when the measured configuration q lies within NEAR_RECORDED of a sample of the recorded motions: the
    arm is where the journal left it (else the journal is not this arm's: a reset world, another run)."""
    return any(float(np.min(np.max(np.abs(t.positions - q), axis=1))) < NEAR_RECORDED
               for _, t in progress.moves if len(t))


def _trajectory(t: Trajectory) -> dict[str, Any]:
    return {"times": t.times.tolist(), "positions": t.positions.tolist(), "velocities": t.velocities.tolist(),
            "joint_names": list(t.joint_names)}


def _from(d: dict[str, Any]) -> Trajectory:
    return Trajectory(np.asarray(d["times"], float), np.asarray(d["positions"], float).reshape(-1, 7),
                      np.asarray(d["velocities"], float).reshape(-1, 7), tuple(d["joint_names"]))


def _push(m: PushPlan) -> dict[str, Any]:
    return {"object_id": m.object_id, "clear_for": m.clear_for, "yaw": m.yaw, "distance": m.distance,
            "end": list(m.end), "lane": m.lane, "kind": m.kind,
            "segments": [[g.name, _trajectory(g.trajectory), g.gripper_after] for g in m.segments]}


def _push_from(d: dict[str, Any]) -> PushPlan:
    x, y, z = (float(v) for v in d["end"])
    return PushPlan(str(d["object_id"]), str(d["clear_for"]), float(d["yaw"]), float(d["distance"]), (x, y, z),
                    str(d["lane"]), [Segment(str(n), _from(t), None if g is None else str(g))
                                     for n, t, g in d["segments"]], str(d.get("kind", "standing")))
