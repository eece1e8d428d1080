"""Q-Tree checkpoints: what a training has learned, on disk, so that it survives a dead planner or a restart.

A checkpoint holds the Q-Tree (nodes, edges with their Eq. 11 labels and Eq. 7 values, the pruned unfeasible
actions), the training counters (episode, Eq. 15 history, the Eq. 16 quiet count, the RNG state, the last
epsilon of Eq. 14), the feasibility answers the planner gave (set-keyed, labels only), the training parameters
and a hash of the problem (obstacle ids, weights phi_i, target). Resuming from it continues the training as if
it had never stopped: same seed, same episodes, same tree (test/test_reliability_checkpoint.py).

File format (JSON, UTF-8): {"format": "qtree-checkpoint", "version": 1, "sha256": <hex of the canonical
payload>, "payload": {...}}. Written atomically (temporary file in the same folder, fsync, os.replace): a crash
while writing leaves the previous checkpoint intact. `load_checkpoint` refuses with a CheckpointError anything
it cannot trust (unreadable, not JSON, another format or version, checksum mismatch, inconsistent tree) and
`Checkpoint.check_matches` refuses one written for another problem or other parameters. Nothing is ever reset
silently: the caller decides (the task_planner node aborts the goal with the message).
"""
from __future__ import annotations

import hashlib
import json
import os
import random
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from qtree_task_planner.learning.params import TrainingParams
from qtree_task_planner.learning.q_tree import QTree
from qtree_task_planner.oracles import CachedOracle
from qtree_task_planner.problem import RelocationProblem
from relocation_common.config import ParameterError
from relocation_common.feasibility import BlockerSet, FeasibilityAnswer, Label

FORMAT = "qtree-checkpoint"
VERSION = 1


class CheckpointError(RuntimeError):
    """A checkpoint that cannot be used; the message names the file and says why and what to do."""


def problem_hash(problem: RelocationProblem) -> str:
    """sha256 of the problem the Q-Tree learns: obstacle ids in order, their weights, the target, and their costs when
    they differ from the weights (an action factor other than 1: the rewards of Eq. 13 differ).

    Poses are not part of it: perception jitters them by millimetres between frames, and the tree's state space
    is the set of ids. The feasibility answers stored with the tree belong to the scene they were asked in."""
    data = {"obstacles": list(problem.obstacles), "weights": [float(problem.weights[o]) for o in problem.obstacles],
            "target": problem.target}
    if problem.costed:  # a paper problem's hash (and its checkpoints) unchanged
        data["costs"] = [float(problem.costs[o]) for o in problem.obstacles]
    return hashlib.sha256(_canonical(data)).hexdigest()


def _canonical(obj: Any) -> bytes:
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), allow_nan=False).encode()


_last_nodes: tuple[list[dict], list[bytes]] = ([], [])  # the last payload's tree node entries and their bytes


def _canonical_payload(payload: dict) -> bytes:
    """_canonical(payload), each of the tree's node entries encoded once across checkpoints: an entry that is the same
    object as the last payload's at its place (KernelTree.to_state hands out the entries of unchanged nodes again; an
    entry is never changed in place) reuses its bytes. The same bytes as _canonical(payload) (test_checkpoint_cost)."""
    global _last_nodes
    tree = payload["tree"]
    head = _canonical(dict(payload, tree=None))
    if not head.endswith(b'"tree":null}') or set(tree) != {"mp_q", "nodes", "q_sum"}:
        return _canonical(payload)  # not the layout of QTree.to_state: encoded whole
    nodes, (before, encoded) = tree["nodes"], _last_nodes
    m = min(len(nodes), len(before))
    parts = [encoded[k] if before[k] is node else _canonical(node) for k, node in enumerate(nodes[:m])]
    parts += [_canonical(node) for node in nodes[m:]]
    _last_nodes = (list(nodes), parts)
    body = b'{"mp_q":%s,"nodes":[%s],"q_sum":%s}' % (_canonical(tree["mp_q"]), b",".join(parts),
                                                      _canonical(tree["q_sum"]))
    return head[:-len(b"null}")] + body + b"}"


def _canonical_body(payload: bytes) -> bytes:
    """_canonical of the file's body {format, version, sha256, payload} from the payload's canonical bytes, which are
    hashed and written as they are: the payload (the whole tree, every checkpoint) is encoded once, not twice."""
    head = _canonical({"format": FORMAT, "version": VERSION, "sha256": hashlib.sha256(payload).hexdigest(),
                       "payload": None})
    return head.replace(b'"payload":null', b'"payload":' + payload, 1)


@dataclass
class Checkpoint:
    """The state of a training at the end of an episode (see training.train's resume/on_checkpoint)."""

    params: TrainingParams
    problem_hash: str
    episode: int  # episodes completed
    q_sum_history: list[float]  # Eq. 15 after each completed episode
    prev_sum: float
    quiet: int  # consecutive episodes within beta (Eq. 16)
    e_1st: int | None
    rng_state: tuple  # random.Random.getstate()
    epsilon: float  # Eq. 14 value of the last completed episode
    planner_calls: int  # real oracle calls of this training so far
    converged: bool
    cancelled: bool
    tree: dict  # QTree.to_state(); never changed in place (save_checkpoint reuses the bytes of unchanged nodes)
    feasibility: list = field(default_factory=list)  # [[object_id, [removed ids], label(, blocker sets(, near))]]
    elapsed_s: float = 0.0
    reason: str = "periodic"  # periodic | final | cancelled | interrupted: <why>

    @classmethod
    def initial(cls, problem: RelocationProblem, params: TrainingParams, cache: CachedOracle | None = None,
                reason: str = "initial") -> "Checkpoint":
        """The state before the first episode (empty tree s_H, RNG seeded), with the answers already in `cache`:
        resuming from it is the same as starting the training."""
        return cls(params, problem_hash(problem), 0, [], 0.0, 0, None, random.Random(params.seed).getstate(),
                   params.epsilon0, 0, False, False, {"nodes": [{"seq": [], "edges": []}], "mp_q": 0, "q_sum": 0.0},
                   cls.table_of(cache) if cache is not None else [], 0.0, reason)

    # -- matching ------------------------------------------------------------------------------------
    def check_matches(self, problem: RelocationProblem, params: TrainingParams, source: str = "checkpoint") -> None:
        """CheckpointError unless this checkpoint was written for `problem` with `params`."""
        if self.problem_hash != problem_hash(problem):
            raise CheckpointError(
                f"{source} was written for another scene (objects, weights or target differ); delete it to "
                "start afresh, or point checkpoint_path elsewhere")
        if self.params != params:
            mine, theirs = self.params.to_dict(), params.to_dict()
            diff = ", ".join(f"{k} {mine[k]!r} != {theirs[k]!r}" for k in mine if mine[k] != theirs[k])
            raise CheckpointError(f"{source} was written with other training parameters ({diff}); send the goal it "
                                  "was written for to resume, or delete it to start afresh")

    # -- feasibility table ---------------------------------------------------------------------------
    def fill_cache(self, cache: CachedOracle) -> int:
        """Put the stored feasibility answers into `cache` (not counted as calls); returns how many were new."""
        added = 0
        for object_id, removed, label, *rest in self.feasibility:
            key = (object_id, frozenset(removed))
            if key not in cache.table:
                sets = tuple(BlockerSet(frozenset(objs), bool(certain), str(lane))
                             for objs, certain, lane in (rest[0] if rest else ()))
                near = frozenset(rest[1]) if len(rest) > 1 and rest[1] is not None else None
                cache.put(key, FeasibilityAnswer(Label(label), message="from checkpoint", blockers=sets, near=near))
                added += 1
        return added

    @staticmethod
    def table_of(cache: CachedOracle) -> list:
        """[object, removed, label] per answer the planner gave, then the blocker sets [[objects, certain, lane],
        ...] when the answer named any (the blocker A* needs them to ask nothing twice after a resume), then its near
        set when it is a pick alone. The answers the cache reused are left out: the same rule gives them again from
        these (CachedOracle), so a resumed training asks what the uninterrupted one would have."""
        out = []
        for (o, removed), a in cache.table.items():
            if (o, removed) in cache.reused:  # the answers the planner gave: the reused ones follow from them
                continue
            row = [o, sorted(removed), int(a.label)]
            if a.blockers or a.near is not None:
                row.append([[sorted(b.objects), b.certain, b.lane] for b in a.blockers])
            if a.near is not None:
                row.append(sorted(a.near))
            out.append(row)
        return out

    # -- plain data ----------------------------------------------------------------------------------
    def to_payload(self) -> dict:
        """Plain JSON data of the checkpoint (the file's payload)."""
        version, internal, gauss = self.rng_state
        return {
            "params": self.params.to_dict(), "problem_hash": self.problem_hash, "episode": self.episode,
            "q_sum_history": list(self.q_sum_history), "prev_sum": self.prev_sum, "quiet": self.quiet,
            "e_1st": self.e_1st, "rng_state": [version, list(internal), gauss], "epsilon": self.epsilon,
            "planner_calls": self.planner_calls, "converged": self.converged, "cancelled": self.cancelled,
            "tree": self.tree, "feasibility": self.feasibility, "elapsed_s": self.elapsed_s, "reason": self.reason,
        }

    @classmethod
    def from_payload(cls, p: dict, source: str = "checkpoint") -> "Checkpoint":
        """The checkpoint in a file's payload; CheckpointError naming `source` when malformed or inconsistent."""
        try:
            version, internal, gauss = p["rng_state"]
            ck = cls(
                params=TrainingParams.from_dict(p["params"]), problem_hash=str(p["problem_hash"]),
                episode=int(p["episode"]), q_sum_history=[float(x) for x in p["q_sum_history"]],
                prev_sum=float(p["prev_sum"]), quiet=int(p["quiet"]),
                e_1st=None if p["e_1st"] is None else int(p["e_1st"]),
                rng_state=(int(version), tuple(int(x) for x in internal), gauss), epsilon=float(p["epsilon"]),
                planner_calls=int(p["planner_calls"]), converged=bool(p["converged"]),
                cancelled=bool(p["cancelled"]), tree=dict(p["tree"]),
                feasibility=[_answer_row(row) for row in p["feasibility"]],
                elapsed_s=float(p["elapsed_s"]), reason=str(p["reason"]))
        except (KeyError, TypeError, ValueError, ParameterError) as e:
            raise CheckpointError(f"{source}: malformed checkpoint contents ({type(e).__name__}: {e})") from None
        if len(ck.q_sum_history) != ck.episode or not 0 <= ck.quiet <= ck.episode or len(ck.rng_state[1]) != 625:
            raise CheckpointError(f"{source}: inconsistent checkpoint (episode {ck.episode}, "
                                  f"{len(ck.q_sum_history)} history entries, quiet {ck.quiet})")
        return ck

    def restore_tree(self, tree: QTree, source: str = "checkpoint") -> None:
        """Load the stored tree into a fresh QTree of the same problem; CheckpointError when inconsistent."""
        try:
            tree.load_state(self.tree)
        except (KeyError, TypeError, ValueError, IndexError) as e:
            raise CheckpointError(f"{source}: the stored Q-Tree is inconsistent ({e})") from None


def save_checkpoint(ck: Checkpoint, path: str | Path) -> Path:
    """Write atomically: temporary file next to `path`, fsync, os.replace (readers never see half a file)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    payload = _canonical_payload(ck.to_payload())
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    try:
        with open(tmp, "wb") as f:
            f.write(_canonical_body(payload))
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    try:  # make the rename itself durable
        fd = os.open(path.parent, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)
    except OSError:
        pass
    return path


def load_checkpoint(path: str | Path) -> Checkpoint:
    """Read and validate a checkpoint; CheckpointError (never a silent reset) when it cannot be trusted."""
    path = Path(path)
    src = f"checkpoint {path}"
    try:
        raw = path.read_bytes()
    except OSError as e:
        raise CheckpointError(f"{src}: cannot read ({e.strerror})") from None
    try:
        body = json.loads(raw)
    except (ValueError, UnicodeDecodeError) as e:
        raise CheckpointError(f"{src}: not a checkpoint (malformed JSON: {e}); the file is corrupt or truncated: "
                              "delete it to start afresh") from None
    if not isinstance(body, dict) or body.get("format") != FORMAT:
        raise CheckpointError(f"{src}: not a Q-Tree checkpoint (format field missing or wrong)")
    if body.get("version") != VERSION:
        raise CheckpointError(f"{src}: format version {body.get('version')!r}, this build reads version {VERSION}")
    payload = body.get("payload")
    if not isinstance(payload, dict):
        raise CheckpointError(f"{src}: no payload")
    try:
        digest = hashlib.sha256(_canonical(payload)).hexdigest()
    except (TypeError, ValueError):
        digest = None
    if digest != body.get("sha256"):
        raise CheckpointError(f"{src}: checksum mismatch: the file is corrupt or was edited; delete it to start "
                              "afresh (it is never reset silently)")
    return Checkpoint.from_payload(payload, src)


def _answer_row(row: list[Any]) -> list[Any]:
    """One stored answer, checked: [object, removed, label], with its blocker sets [[objects, certain, lane], ...],
    and its near set [objects] (TypeError/ValueError when malformed)."""
    o, r, lab, *rest = row
    out = [str(o), [str(x) for x in r], int(Label(lab))]
    if len(rest) > 2:
        raise ValueError(f"feasibility row of {len(row)} fields")
    if rest:
        out.append([[[str(x) for x in objs], bool(certain), str(lane)] for objs, certain, lane in rest[0]])
    if len(rest) > 1:
        out.append([str(x) for x in rest[1]])
    return out
