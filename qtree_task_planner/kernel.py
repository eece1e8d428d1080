"""C kernel of the Q-Tree training loop (`_kernel.c`), loaded with ctypes; bit-identical to training.py's loop.

`train` uses it for plain batch training (no callback, checkpoint or resume; stock QTree and policies; the
oracle is a plain CachedOracle, which `train` always puts in front) and falls back to the Python loop when the
kernel is unavailable. The C source is compiled once with the system C compiler into
$XDG_CACHE_HOME/qtree_task_planner/ (~/.cache/...), keyed by a hash of the source and the flags; set
QTREE_KERNEL=0 to disable it. `available()` says whether it loaded, `build_error` why not.

Exactness: the kernel runs CPython's MT19937 / random() on the state of the trainer's random.Random (written
back afterwards), makes the same draws and the same double operations in the same order (-ffp-contract=off,
no fast-math), asks the CachedOracle once per new (object, removed set) of the tree and counts every other new
edge in CachedOracle.queries (what CachedOracle.feasibility does for a known key). The resulting QTree is
exported to Python Node objects lazily (on first use of tree.nodes / tree.root): the evaluation sweeps only
read counts from it. test/test_q_tree_equivalence.py checks the whole tree and history bit for bit.
"""
from __future__ import annotations

import ctypes
import hashlib
import os
import subprocess
import sysconfig
import tempfile
from pathlib import Path

from relocation_common.feasibility import Label

from .q_tree import Node, QTree

SOURCE = Path(__file__).with_name("_kernel.c")
FLAGS = ["-O2", "-fPIC", "-shared", "-ffp-contract=off", "-fno-fast-math", "-std=c99"]
MAX_ACTIONS = 63  # removed sets are 64-bit masks

_lib = None
build_error: str | None = None
_ASK = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_uint64, ctypes.c_int)
_PATH = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_int, ctypes.POINTER(ctypes.c_int))


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


def _load():
    global _lib, build_error
    if _lib is not None or build_error is not None:
        return _lib
    if os.environ.get("QTREE_KERNEL", "1") == "0":
        build_error = "disabled by QTREE_KERNEL=0"
        return None
    try:
        lib = ctypes.CDLL(str(_build()))
    except (OSError, subprocess.SubprocessError) as e:
        build_error = str(e)
        return None
    P, I, D, I64 = ctypes.c_void_p, ctypes.c_int, ctypes.c_double, ctypes.c_int64
    lib.kt_new.restype = P
    lib.kt_new.argtypes = [I, I, D, D, ctypes.POINTER(D)]
    lib.kt_free.argtypes = [P]
    lib.kt_train.restype = I
    lib.kt_train.argtypes = [P, ctypes.POINTER(ctypes.c_uint32), ctypes.POINTER(I), I, I, I, I, ctypes.POINTER(D),
                             D, I, I, _ASK, _PATH, ctypes.POINTER(D), ctypes.POINTER(I)]
    lib.kt_best_path.restype = I
    lib.kt_best_path.argtypes = [P, ctypes.POINTER(I)]
    for name, res in (("kt_n_nodes", I), ("kt_mp_q", I64), ("kt_memo_hits", I64), ("kt_q_sum", D)):
        getattr(lib, name).restype = res
        getattr(lib, name).argtypes = [P]
    lib.kt_export.argtypes = [P] + [ctypes.c_void_p] * 9
    _lib = lib
    return lib


def available() -> bool:
    return _load() is not None


class KernelTree(QTree):
    """A QTree trained by the kernel. Counts (mp_q, q_sum, n_edges, len(nodes)) come from the kernel; the
    Python nodes (root, nodes) are built on first access, identical to those the Python loop builds."""

    def __init__(self, problem, oracle, alpha: float, gamma: float) -> None:
        self._handle = None
        self._py_nodes: list[Node] | None = None
        super().__init__(problem, oracle, alpha, gamma)
        lib = _load()
        phi = (ctypes.c_double * self.n_objects)(*self.phi)
        self._handle = lib.kt_new(self.n_objects, self.target, alpha, gamma, phi)
        if not self._handle:
            raise MemoryError("Q-Tree kernel: out of memory")
        self._n_nodes = 1
        self._n_edges = 0

    def __del__(self):
        h = getattr(self, "_handle", None)
        if h and _lib is not None:
            _lib.kt_free(h)
            self._handle = None

    # root / nodes: plain attributes of QTree, here materialised from the kernel on first use
    @property
    def nodes(self) -> list[Node]:
        if self._py_nodes is None:
            self._export()
        return self._py_nodes

    @nodes.setter
    def nodes(self, value: list[Node]) -> None:
        self._py_nodes = value
        self._n_nodes = None  # set by QTree.__init__ / load_state: the Python nodes are the truth now

    @property
    def root(self) -> Node:
        return self.nodes[0]

    @root.setter
    def root(self, value: Node) -> None:  # QTree.__init__ sets root, then nodes = [root]
        self._py_nodes = [value]

    @property
    def n_edges(self) -> int:
        if self._py_nodes is None:
            return self._n_edges
        return sum(len(n.label) for n in self._py_nodes)

    @property
    def node_count(self) -> int:
        return self._n_nodes if self._py_nodes is None else len(self._py_nodes)

    def best_sequence(self) -> tuple[str, ...] | None:
        if self._py_nodes is not None:
            return super().best_sequence()
        actions = self.best_actions()
        return None if actions is None else tuple(self.ids[a] for a in actions)

    def _sync(self) -> None:
        lib, h = _lib, self._handle
        self.mp_q = lib.kt_mp_q(h)
        self.q_sum = lib.kt_q_sum(h)
        self._n_nodes = lib.kt_n_nodes(h)
        self._n_edges = self.mp_q
        self._py_nodes = None

    def _export(self) -> None:
        """Build the Python nodes exactly as the Python loop would have: ids in creation order, edges (label, q,
        q_pruned, child dicts) in creation order, the offered-action cache."""
        import numpy as np
        lib, h, n1 = _lib, self._handle, self.n_objects
        n = lib.kt_n_nodes(h)
        parent = np.empty(n, np.int32)
        action = np.empty(n, np.int32)
        n_edges = np.empty(n, np.int32)
        n_offer = np.empty(n, np.int32)
        order = np.empty((n, n1), np.int8)
        label = np.empty((n, n1), np.int8)
        q = np.empty((n, n1), np.float64)
        child = np.empty((n, n1), np.int32)
        offer = np.empty((n, n1), np.int8)
        lib.kt_export(h, *(a.ctypes.data for a in (parent, action, n_edges, n_offer, order, label, q, child,
                                                   offer)))
        parent, action, n_edges, n_offer = parent.tolist(), action.tolist(), n_edges.tolist(), n_offer.tolist()
        order, label, q, child, offer = order.tolist(), label.tolist(), q.tolist(), child.tolist(), offer.tolist()
        labels = {int(lab): lab for lab in Label}
        nodes: list[Node] = []
        for i in range(n):
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
        self._py_nodes = nodes

    def run(self, rng, kind: int, depth: bool, i_max: int, e_max: int, epsilons: list[float], beta: float,
            quiet_needed: int, path_ok) -> tuple[int, bool, int | None, list[float]]:
        """Train: returns (episodes, converged, e_1st, Eq. 15 history). rng: the random.Random (state read and
        written back). path_ok(actions) -> bool, or None: no E_1st."""
        lib, h = _lib, self._handle
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
                return int(label)
            except BaseException as e:  # noqa: BLE001 - re-raised below, after the kernel returns
                errors.append(e)
                return -1

        def path(length: int, actions) -> int:
            try:
                return 1 if path_ok(tuple(actions[k] for k in range(length))) else 0
            except BaseException as e:  # noqa: BLE001
                errors.append(e)
                return -1

        version, internal, gauss = rng.getstate()
        mt = (ctypes.c_uint32 * 624)(*internal[:624])
        index = ctypes.c_int(internal[624])
        eps = (ctypes.c_double * max(1, e_max))(*epsilons)
        history = (ctypes.c_double * max(1, e_max))()
        out = (ctypes.c_int * 3)()
        hits0 = lib.kt_memo_hits(h)
        ask_c, path_c = _ASK(ask), _PATH(path)
        rc = lib.kt_train(h, mt, ctypes.byref(index), kind, int(depth), i_max, e_max, eps, beta, quiet_needed,
                          int(path_ok is not None), ask_c, path_c, history, out)
        cache.queries += lib.kt_memo_hits(h) - hits0
        rng.setstate((version, tuple(mt) + (index.value,), gauss))
        self._sync()
        if errors:
            raise errors[0]
        if rc == -2:
            raise MemoryError("Q-Tree kernel: out of memory")
        if rc != 0:
            raise RuntimeError(f"Q-Tree kernel failed ({rc})")
        episodes = out[0]
        return episodes, bool(out[1]), (out[2] or None), history[:episodes]

    def best_actions(self) -> list[int] | None:
        buf = (ctypes.c_int * max(1, self.n_objects))()
        n = _lib.kt_best_path(self._handle, buf)
        return None if n < 0 else buf[:n]
