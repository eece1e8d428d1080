"""Checkpoint bookkeeping of the task planner (docs/reliability.md, "Checkpoints"), ROS-free.

What a training goal has learned lives in two places: the last checkpoint in memory (always) and, with
`checkpoint_path` set, the file (written atomically, qtree_task_planner.learning.checkpoint). `CheckpointKeeper` chooses
where a goal resumes from, keeps each new checkpoint, and says exactly where what was learned is (never a file
that was not written, never a newer episode than the file holds). The node passes its logger.
"""
from __future__ import annotations

import tempfile
from pathlib import Path
from typing import Callable

from qtree_task_planner.learning.checkpoint import (
    Checkpoint,
    CheckpointError,
    load_checkpoint,
    problem_hash,
    save_checkpoint,
)
from qtree_task_planner.learning.params import TrainingParams
from qtree_task_planner.oracles import CachedOracle
from qtree_task_planner.problem import RelocationProblem
from relocation_common.config import ParameterError


def check_checkpoint_path(path: str) -> None:
    """ParameterError at start for a checkpoint_path that cannot hold a checkpoint: a directory, something that is
    not a regular file (a FIFO would block the goal forever), or a directory where no file can be created (a
    read-only filesystem; tried for real, as permission bits do not stop root)."""
    if not path:
        return
    p = Path(path)
    if p.is_dir():
        raise ParameterError(f"checkpoint_path {path!r} is a directory: give a file name")
    if p.exists() and not p.is_file():
        raise ParameterError(f"checkpoint_path {path!r} exists and is not a regular file")
    try:
        p.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=p.parent, prefix=f".{p.name}.probe-"):
            pass
    except OSError as e:
        raise ParameterError(f"checkpoint_path {path!r}: cannot write in {str(p.parent)!r} ({e.strerror or e}); "
                             "give a writable location") from None


class CheckpointKeeper:
    """The last checkpoint in memory and at `path` ("" = memory only); `info` / `error` log one line each."""

    def __init__(self, path: str, info: Callable[[str], None] = lambda _: None,
                 error: Callable[[str], None] = lambda _: None) -> None:
        """`path` checked by check_checkpoint_path at start."""
        self.path, self.info, self.error = path, info, error
        self.memory: Checkpoint | None = None  # the last checkpoint, also when path is empty
        self.written: tuple[int, str] | None = None  # (episode, "") of the last one on disk, or (episode, error)

    def resume_point(self, problem: RelocationProblem, params: TrainingParams,
                     cache: CachedOracle, changed: str = "") -> Checkpoint | None:
        """The checkpoint a goal resumes from, its answers put into `cache`: the file when it exists
        (CheckpointError if it is corrupt or for another scene/params), else an unfinished in-memory one of the
        same goal; None: start afresh. It becomes the memory checkpoint. `changed` (why the world is no longer the
        one the goal was first sent for: executive.resume): a file written for another scene is not reused, said in
        the log, and the training starts afresh on `problem` (its checkpoints replace the file)."""
        path = self.path
        if path and Path(path).is_file():
            ck: Checkpoint | None = load_checkpoint(path)
            assert ck is not None
            if changed and ck.problem_hash != problem_hash(problem):
                self.info(f"checkpoint {path} (episode {ck.episode}, {ck.reason}) was written for the scene before "
                          f"{changed}: not reused; the Q-Tree trains afresh on the scene as it is now "
                          f"({len(problem.obstacles)} obstacles, target {problem.target})")
                self.memory = None
                return None
            ck.check_matches(problem, params, f"checkpoint {path}")
            where = path
        elif self.memory is not None and self.memory.reason.startswith("interrupted"):
            # no file (never written, or removed): what this node kept in memory still counts
            ck, where = self.memory, "(in memory)"
            try:
                ck.check_matches(problem, params)
            except CheckpointError:
                ck = None
        else:
            ck = None
        self.memory = ck
        if ck is not None:
            ck.fill_cache(cache)
            self.info(f"resuming from checkpoint {where}: episode {ck.episode}, {len(ck.tree['nodes'])} tree nodes, "
                      f"{len(ck.feasibility)} feasibility answers")
        return ck

    def keep(self, ck: Checkpoint) -> None:
        """Keep `ck` in memory and write it to the file; a failed write is logged and remembered, training goes
        on (the memory copy still holds it)."""
        self.memory = ck
        if self.path:
            try:
                save_checkpoint(ck, self.path)
                self.written = (ck.episode, "")
            except OSError as e:
                self.written = (self.written[0] if self.written else -1, f"{e.strerror or e}")
                self.error(f"cannot write checkpoint {self.path}: {e}")

    def kept_where(self) -> str:
        """Where what was learned is, exactly: never a file that was not written, never a newer episode."""
        ck, path = self.memory, self.path
        memory = f"in memory at episode {ck.episode}" if ck is not None else "in memory"
        if not path:
            return f"{memory} only (set checkpoint_path to keep it across restarts)"
        episode, error = self.written if self.written else (-1, "")
        on_disk = f"checkpoint {path} at episode {episode}" if episode >= 0 else ""
        if ck is not None and ck.episode == episode and not error:
            return on_disk
        failed = f" (writing {path} failed: {error})" if error else ""
        return "; ".join(filter(None, [on_disk, memory + failed]))
