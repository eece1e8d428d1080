"""The Q-Tree episode engine (`_kernel.c`, loaded with ctypes): the one production training loop.

`training.train` runs every training on it (the node, the CLI, the evaluation sweeps): the kernel runs a batch
of episodes, then Python calls back (progress, cancel, checkpoints) and starts the next batch. The C source is
compiled once with the system C compiler into $XDG_CACHE_HOME/qtree_task_planner/ (~/.cache/...), keyed by a
hash of the source and the flags; `available()` says whether it loaded, `build_error` why not (training then
stops with that reason: install a C compiler, e.g. Debian's gcc).

Exactness: the kernel runs CPython's MT19937 / random() on the state of the trainer's random.Random (read back
with `KernelTree.pull_rng`), makes the same draws and the same double operations in the same order as the
reference (test/qtree_reference.py; -ffp-contract=off, no fast-math), asks the CachedOracle once per new
(object, removed set) of the tree and counts every other new edge in CachedOracle.queries (what
CachedOracle.feasibility does for a known key). An episode whose oracle call raises is undone in C (tree,
counters, RNG as at its start). The QTree is exported to Python Node objects lazily (tree.nodes / tree.root);
a stored tree (a checkpoint) is loaded into it with load_state. test/test_q_tree_equivalence.py checks trees and
histories bit for bit against a recording of the reference.
"""
from __future__ import annotations

import ctypes
import hashlib
import math
import os
import random
import subprocess
import sysconfig
import tempfile
import time
from pathlib import Path
from typing import Callable, NamedTuple

import numpy as np

from qtree_task_planner.learning.q_tree import R_TARGET, R_UNFEASIBLE, Node, QTree
from qtree_task_planner.oracles import CachedOracle
from qtree_task_planner.problem import RelocationProblem
from relocation_common.feasibility import Label

SOURCE = Path(__file__).with_name("_kernel.c")
FLAGS = ["-O2", "-fPIC", "-shared", "-ffp-contract=off", "-fno-fast-math", "-std=c99",
         f"-DR_UNFEASIBLE=({R_UNFEASIBLE!r})", f"-DR_TARGET=({R_TARGET!r})"]  # Eq. 13 from q_tree.py
MAX_ACTIONS = 63  # removed sets are 64-bit masks
POLICY_CODES = {"lrnd": 0, "h-lrnd": 1, "h-eg": 2}  # TrainingParams.policy -> the kernel's switch

_loaded: ctypes.CDLL | None = None
build_error: str | None = None
_ASK = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_uint64, ctypes.c_int)
_PATH = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_int, ctypes.POINTER(ctypes.c_int))
PathTest = Callable[[tuple[int, ...]], bool]  # E_1st: whether a greedy path's actions have the optimal weight


def _build() -> Path:
    src = SOURCE.read_bytes()
    cc = os.environ.get("CC") or sysconfig.get_config_var("CC") or "cc"
    cc = cc.split()[0]
    tag = hashlib.sha256(src + " ".join([cc] + FLAGS).encode()).hexdigest()[:16]
    cache = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "qtree_task_planner"
    so = cache / f"kernel-{tag}.so"
    if so.exists():
        return so
    cache.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(suffix=".so", dir=cache)
    os.close(fd)
    try:
        r = subprocess.run([cc, *FLAGS, "-o", tmp, str(SOURCE), "-lm"], capture_output=True, text=True,
                           timeout=120)
        if r.returncode != 0:
            raise OSError(f"{cc} failed: {r.stderr.strip()[:500]}")
        os.replace(tmp, so)  # atomic: concurrent builders each install a complete file
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
    return so


class RunState(NamedTuple):
    """The kernel's training counters after a batch (KernelTree.pull_state)."""

    episode: int  # episodes done
    prev_sum: float  # Eq. 15 of the last episode
    quiet: int  # consecutive episodes within beta (Eq. 16)
    converged: bool
    e_1st: int | None
    steps: int  # of the last episode
    reached: bool  # the last episode relocated the target


def _load() -> ctypes.CDLL | None:
    """The loaded library (built on first use), or None (`build_error` says why)."""
    global _loaded, build_error
    if _loaded is not None or build_error is not None:
        return _loaded
    try:
        lib = ctypes.CDLL(str(_build()))
    except (OSError, subprocess.SubprocessError) as e:
        build_error = str(e)
        return None
    P, INT, D, I64 = ctypes.c_void_p, ctypes.c_int, ctypes.c_double, ctypes.c_int64
    U32P, IP, DP = ctypes.POINTER(ctypes.c_uint32), ctypes.POINTER(INT), ctypes.POINTER(D)
    lib.kt_new.restype = P
    lib.kt_new.argtypes = [INT, INT, D, D, DP]
    lib.kt_free.argtypes = [P]
    lib.kt_train.restype = INT
    lib.kt_train.argtypes = [P, INT, INT, INT, INT, DP, D, INT, INT, _ASK, _PATH, DP]
    lib.kt_set_state.argtypes = [P, U32P, INT, INT, D, INT, INT, INT]
    lib.kt_get_state.argtypes = [P, U32P, IP, DP]
    lib.kt_add_node.restype = INT
    lib.kt_add_node.argtypes = [P, INT, INT]
    lib.kt_add_edge.argtypes = [P, INT, INT, INT, D, INT]
    lib.kt_set_counts.argtypes = [P, I64, D]
    lib.kt_relabel.restype = INT
    lib.kt_relabel.argtypes = [P, ctypes.c_uint64, INT]
    lib.kt_best_path.restype = INT
    lib.kt_best_path.argtypes = [P, IP]
    for name, res in (("kt_n_nodes", INT), ("kt_mp_q", I64), ("kt_memo_hits", I64), ("kt_q_sum", D)):
        getattr(lib, name).restype = res
        getattr(lib, name).argtypes = [P]
    lib.kt_export.argtypes = [P] + [ctypes.c_void_p] * 9
    _loaded = lib
    return lib


def available() -> bool:
    """Whether the kernel is built and loaded (`build_error` says why not)."""
    return _load() is not None


def _lib() -> ctypes.CDLL:
    lib = _load()
    if lib is None:
        raise RuntimeError(f"the Q-Tree training kernel (qtree_task_planner/learning/_kernel.c) did not build: "
                           f"{build_error}; install a C compiler (Debian: apt-get install gcc) or set CC")
    return lib


class KernelTree(QTree):
    """A QTree trained by the kernel. Counts (mp_q, q_sum, n_edges, len(nodes)) come from the kernel; the
    Python nodes (root, nodes) are built on first access, identical to those the Python loop builds. Its oracle is
    a CachedOracle: the kernel counts the questions it answers from its own memo in `queries`."""

    oracle: CachedOracle

    def __init__(self, problem: RelocationProblem, oracle: CachedOracle, alpha: float, gamma: float) -> None:
        """A fresh tree (only s_H) in the kernel; RuntimeError naming the fix when the kernel did not build."""
        self._handle = None
        self._py_nodes: list[Node] | None = None
        lib = _lib()
        if problem.n + 1 > MAX_ACTIONS:
            raise ValueError(f"the Q-Tree kernel takes up to {MAX_ACTIONS - 1} obstacles, got {problem.n}")
        super().__init__(problem, oracle, alpha, gamma)
        phi = (ctypes.c_double * self.n_objects)(*self.phi)
        self._handle = lib.kt_new(self.n_objects, self.target, alpha, gamma, phi)
        if not self._handle:
            raise MemoryError("Q-Tree kernel: out of memory")
        self._n_nodes: int | None = 1
        self._n_edges = 0
        self._mt = (ctypes.c_uint32 * 624)()
        self._state_rows: tuple[dict[str, np.ndarray], list[dict], list[list[int]]] = (
            {k: np.empty(0, np.int32) for k in ("parent", "action")}, [], [])  # to_state's last arrays and entries

    def __del__(self) -> None:
        h = getattr(self, "_handle", None)
        if h and _loaded is not None:
            _loaded.kt_free(h)
            self._handle = None

    # root / nodes: plain attributes of QTree, here materialised from the kernel on first use
    @property
    def nodes(self) -> list[Node]:
        """The Python nodes, exported from the kernel on first use."""
        if self._py_nodes is None:
            self._py_nodes = self._export()
        return self._py_nodes

    @nodes.setter
    def nodes(self, value: list[Node]) -> None:
        self._py_nodes = value
        self._n_nodes = None  # set by QTree.__init__ / load_state: the Python nodes are the truth now

    @property
    def root(self) -> Node:
        """s_H."""
        return self.nodes[0]

    @root.setter
    def root(self, value: Node) -> None:  # QTree.__init__ sets root, then nodes = [root]
        self._py_nodes = [value]

    @property
    def n_edges(self) -> int:
        """Edges known (= MP_q)."""
        if self._py_nodes is None:
            return self._n_edges
        return sum(len(n.label) for n in self._py_nodes)

    @property
    def node_count(self) -> int:
        """Nodes allocated (s_H included)."""
        if self._py_nodes is not None:
            return len(self._py_nodes)
        assert self._n_nodes is not None  # set by _sync whenever the Python nodes are dropped
        return self._n_nodes

    def best_sequence(self) -> tuple[str, ...] | None:
        """QTree.best_sequence, from the kernel unless the Python nodes are there."""
        if self._py_nodes is not None:
            return super().best_sequence()
        actions = self.best_actions()
        return None if actions is None else tuple(self.ids[a] for a in actions)

    def _sync(self) -> None:
        lib, h = _lib(), self._handle
        self.mp_q = lib.kt_mp_q(h)
        self.q_sum = lib.kt_q_sum(h)
        self._n_nodes = lib.kt_n_nodes(h)
        self._n_edges = self.mp_q
        self._py_nodes = None

    def _arrays(self) -> dict[str, list]:
        """The kernel's tree as lists (n nodes): parent, action, n_edges, n_offer; per node rows of n1 actions:
        order (edges in creation order), label, q, child, offer."""
        return {k: v.tolist() for k, v in self._arrays_np().items()}

    def _arrays_np(self) -> dict[str, np.ndarray]:
        """_arrays as numpy arrays (one copy out of the kernel)."""
        lib, h, n1 = _lib(), self._handle, self.n_objects
        n = lib.kt_n_nodes(h)
        out = {name: np.empty(n, np.int32) for name in ("parent", "action", "n_edges", "n_offer")}
        for name, dtype in (("order", np.int8), ("label", np.int8), ("q", np.float64), ("child", np.int32),
                            ("offer", np.int8)):
            out[name] = np.empty((n, n1), dtype)
        lib.kt_export(h, *(out[k].ctypes.data for k in ("parent", "action", "n_edges", "n_offer", "order", "label",
                                                         "q", "child", "offer")))
        return out

    def _export(self) -> list[Node]:
        """The Python nodes exactly as the reference loop builds them: ids in creation order, edges (label, q,
        q_pruned, child dicts) in creation order, the offered-action cache."""
        t = self._arrays()
        parent, action, n_edges, n_offer = t["parent"], t["action"], t["n_edges"], t["n_offer"]
        order, label, q, child, offer = t["order"], t["label"], t["q"], t["child"], t["offer"]
        labels = {int(lab): lab for lab in Label}
        nodes: list[Node] = []
        for i in range(len(parent)):
            if i == 0:
                node = Node(0, (), 0)
            else:
                p, a = nodes[parent[i]], action[i]
                node = Node(i, p.seq + (a,), p.mask | (1 << a))
            nodes.append(node)
        for i, node in enumerate(nodes):
            lab_row, q_row, child_row = label[i], q[i], child[i]
            for a in order[i][:n_edges[i]]:
                lab = labels[lab_row[a]]
                node.label[a] = lab
                if lab is Label.UNFEASIBLE:
                    node.q_pruned[a] = q_row[a]
                    node.pruned |= 1 << a
                else:
                    node.q[a] = q_row[a]
                    if lab is Label.OBSTACLE:
                        node.child[a] = nodes[child_row[a]]
            node.offer = offer[i][:n_offer[i]]
        return nodes

    def to_state(self) -> dict:
        """QTree.to_state, read from the kernel's arrays without building Python nodes. A checkpoint every
        `checkpoint_every` episodes stays cheap: the entries of the nodes unchanged since the last call are the
        same objects (never changed in place; learning.checkpoint encodes each once), only the nodes new or
        changed since are read again."""
        if self._py_nodes is not None:
            return super().to_state()
        t = self._arrays_np()
        keep, changed = self._unchanged(t)
        nodes, seqs = self._state_rows[1][:keep], self._state_rows[2][:keep]
        parent, action, n_edges = (t[k] for k in ("parent", "action", "n_edges"))
        for i in changed:
            nodes[i] = {"seq": seqs[i], "edges": self._edges(t, i, int(n_edges[i]))}
        for i in range(keep, len(parent)):
            seqs.append(seqs[parent[i]] + [int(action[i])] if i else [])
            nodes.append({"seq": seqs[i], "edges": self._edges(t, i, int(n_edges[i]))})
        self._state_rows = (t, nodes, seqs)
        return {"nodes": list(nodes), "mp_q": self.mp_q, "q_sum": self.q_sum}

    def _unchanged(self, t: dict[str, np.ndarray]) -> tuple[int, list[int]]:
        """Against the arrays of the last to_state: (keep, changed) where nodes below `keep` have the same
        sequence (parent and action of every node up to them), and `changed` are those of them whose edges differ
        (count, order, labels or Q bit for bit)."""
        before = self._state_rows[0]
        m = min(len(t["parent"]), len(before["parent"]))
        moved = np.flatnonzero((t["parent"][:m] != before["parent"][:m]) | (t["action"][:m] != before["action"][:m]))
        keep = int(moved[0]) if moved.size else m
        if keep == 0:
            return 0, []
        differ = t["n_edges"][:keep] != before["n_edges"][:keep]
        for k in ("order", "label"):
            differ |= (t[k][:keep] != before[k][:keep]).any(axis=1)
        differ |= (t["q"][:keep].view(np.int64) != before["q"][:keep].view(np.int64)).any(axis=1)
        return keep, np.flatnonzero(differ).tolist()

    @staticmethod
    def _edges(t: dict[str, np.ndarray], i: int, n_edges: int) -> list[list]:
        """Node i's edges in creation order as [action, label (Eq. 11), Q]."""
        lab_row, q_row = t["label"][i].tolist(), t["q"][i].tolist()
        return [[a, lab_row[a], q_row[a]] for a in t["order"][i, :n_edges].tolist()]

    def load_state(self, state: dict) -> None:
        """QTree.load_state (validated into Python nodes), then the same tree into the kernel, node by node in
        allocation order (a fresh tree only: a checkpoint is resumed into a new training)."""
        super().load_state(state)
        lib, h = _lib(), self._handle
        if lib.kt_n_nodes(h) != 1 or lib.kt_mp_q(h) != 0:
            raise ValueError("load_state needs a fresh kernel tree")
        for node in self.nodes[1:]:
            lib.kt_add_node(h, self._parent_id(node), node.seq[-1])
        for node in self.nodes:
            for a, label in node.label.items():
                q = node.q[a] if a in node.q else node.q_pruned[a]
                child = node.child[a].id if a in node.child else -1
                lib.kt_add_edge(h, node.id, a, int(label), q, child)
        lib.kt_set_counts(h, self.mp_q, self.q_sum)
        self._sync()

    def _parent_id(self, node: Node) -> int:
        parent = self.root
        for a in node.seq[:-1]:
            parent = parent.child[a]
        return parent.id

    def push_state(self, rng: random.Random, episode: int, prev_sum: float, quiet: int, converged: bool,
                   e_1st: int | None) -> None:
        """Hand the training state to the kernel: the random.Random's state (CPython MT19937), the episodes done,
        the Eq. 16 state and E_1st."""
        _, internal, _ = rng.getstate()
        mt = (ctypes.c_uint32 * 624)(*internal[:624])
        _lib().kt_set_state(self._handle, mt, internal[624], episode, prev_sum, quiet, int(converged), e_1st or 0)

    def pull_state(self, rng: random.Random | None = None) -> RunState:
        """The kernel's training state; `rng` (the random.Random it started from), if given, gets the kernel's RNG
        state."""
        mt = self._mt
        ints = (ctypes.c_int * 7)()
        prev_sum = ctypes.c_double()
        _lib().kt_get_state(self._handle, mt, ints, ctypes.byref(prev_sum))
        if rng is not None:
            version, _, gauss = rng.getstate()
            rng.setstate((version, tuple(mt) + (ints[0],), gauss))
        return RunState(ints[1], prev_sum.value, ints[2], bool(ints[3]), ints[4] or None, ints[5], bool(ints[6]))

    def run(self, policy: str, depth: bool, i_max: int, stop_at: int, epsilons: ctypes.Array[ctypes.c_double],
            beta: float, quiet_needed: int, path_ok: PathTest | None,
            history: ctypes.Array[ctypes.c_double], deadline: float = math.inf) -> None:
        """Episodes until `stop_at` episodes are done or Eq. 16 holds, or, after an episode in which the oracle
        was asked past `deadline` (time.monotonic), earlier. policy: a name of POLICY_CODES.
        epsilons, history: ctypes double arrays of E_max entries (Eq. 14 per episode; Eq. 15 written per episode).
        path_ok(actions) -> bool, or None: no E_1st. An oracle error is raised after the kernel has undone the
        episode it interrupted."""
        lib, h = _lib(), self._handle
        cache, ids = self.oracle, self.ids
        errors: list[BaseException] = []
        removed_of: dict[int, frozenset] = {}

        def ask(mask: int, a: int) -> int:
            try:
                removed = removed_of.get(mask)
                if removed is None:
                    removed = removed_of[mask] = frozenset(ids[i] for i in range(self.target) if (mask >> i) & 1)
                label = Label(cache.feasibility(ids[a], removed).label)
                if (label == Label.TARGET) != (a == self.target) and label != Label.UNFEASIBLE:
                    raise ValueError(f"oracle answered {label.name} for {ids[a]!r}: TARGET is for the target only")
                return int(label) | (4 if time.monotonic() > deadline else 0)
            except BaseException as e:  # noqa: BLE001 - re-raised below, after the kernel returns
                errors.append(e)
                return -1

        def path(length: int, actions: ctypes._Pointer[ctypes.c_int]) -> int:
            try:
                assert path_ok is not None  # the kernel asks only when told there is a path test
                return 1 if path_ok(tuple(actions[k] for k in range(length))) else 0
            except BaseException as e:  # noqa: BLE001 - re-raised below, after the kernel returns
                errors.append(e)
                return -1

        hits0 = lib.kt_memo_hits(h)
        rc = lib.kt_train(h, POLICY_CODES[policy], int(depth), i_max, stop_at, epsilons, beta, quiet_needed,
                          int(path_ok is not None), _ASK(ask), _PATH(path), history)
        cache.queries += lib.kt_memo_hits(h) - hits0
        self._sync()
        if errors:
            raise errors[0]
        if rc == -2:
            raise MemoryError("Q-Tree kernel: out of memory")
        if rc != 0:
            raise RuntimeError(f"Q-Tree kernel failed ({rc})")

    def relabel(self, object_id: str, removed: frozenset[str]) -> int:
        """A certification turned (object_id, removed) unfeasible: every node with that removed set has the edge
        unfeasible from now on and the subtree below it dropped (kt_relabel in _kernel.c); the number of edges
        relabelled (0 when the tree never took it)."""
        mask = sum(1 << self.ids.index(o) for o in removed)
        n = _lib().kt_relabel(self._handle, mask, self.ids.index(object_id))
        if n == -2:
            raise MemoryError("Q-Tree kernel: out of memory")
        self._sync()
        return int(n)

    def best_actions(self) -> list[int] | None:
        """QTree.best_path's actions, in C; None when the greedy path misses the target."""
        buf = (ctypes.c_int * max(1, self.n_objects))()
        n = _lib().kt_best_path(self._handle, buf)
        return None if n < 0 else buf[:n]
