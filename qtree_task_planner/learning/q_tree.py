"""The Q-Tree of the paper (Sect. 4.2): a tree whose nodes are states and whose edges carry Q-values.

A node is the sequence of objects relocated so far; the root s_H is the initial scene. A node is allocated the
first time an action leads to it; the value of the edge (s_k, a_k) is Q(s_k, a_k). Creating an edge asks the
feasibility oracle once (the paper's MP_q accounting); afterwards the edge remembers its label (Eq. 11).

- Eq. 7:  Q(s_k, a_k) <- Q + alpha * (r_k + gamma * max_a' Q(s_{k+1}, a') - Q), the max over the next node's
  known feasible edges, 0 when it has none. A target edge and an unfeasible edge have no next node (terminal),
  so their max term is 0.
- Eq. 13: r = -phi_i when obstacle i is relocated, -10 when the chosen action is unfeasible, +100 when the target
  is relocated; with the action model, -phi_i is the obstacle's cost (phi_i x its action's factor:
  qtree_task_planner.problem, "One action model"), the weight itself at factor 1.
- Pruning: an action found unfeasible at a node is never offered at that node again.
- Eq. 15: Q_sum = sum over all edges of |Q(s, a)|, kept up to date incrementally.
"""
from __future__ import annotations

from typing import Iterable

from qtree_task_planner.problem import RelocationProblem
from relocation_common.feasibility import FeasibilityOracle, Label

R_UNFEASIBLE = -10.0  # Eq. 13; the C kernel is compiled with these (kernel.FLAGS)
R_TARGET = 100.0  # Eq. 13
_LABELS = {int(lab): lab for lab in Label}


class Node:
    """A state s_k: the sequence of relocated objects (indices) and its bitmask. Edges by action index:
    `q` feasible edges (offered, used by max and greedy), `q_pruned` unfeasible edges (never offered again),
    `label` of every known edge, `child` node of every obstacle edge. `offer` caches `offered()` (ascending
    action indices; kept up to date by QTree when an action is pruned here, None = not computed yet)."""

    __slots__ = ("id", "seq", "mask", "q", "q_pruned", "label", "child", "pruned", "offer", "removed")

    def __init__(self, node_id: int, seq: tuple[int, ...], mask: int) -> None:
        self.id = node_id
        self.seq = seq
        self.mask = mask
        self.q: dict[int, float] = {}
        self.q_pruned: dict[int, float] = {}
        self.label: dict[int, Label] = {}
        self.child: dict[int, Node] = {}
        self.pruned = 0  # bitmask of unfeasible actions at this node
        self.offer: list[int] | None = None  # cache of offered(), see QTree.offered
        self.removed: frozenset[str] | None = None  # cache of the removed ids, see QTree.edge_label

    def max_q(self) -> float:
        """max_a' Q(s, a') over the known feasible edges; 0 where there is none (Eq. 7)."""
        return max(self.q.values()) if self.q else 0.0

    def offered(self, n_objects: int) -> list[int]:
        """Actions offered at this node: not relocated yet in this sequence and not pruned here."""
        blocked = self.mask | self.pruned
        return [a for a in range(n_objects) if not (blocked >> a) & 1]


class QTree:
    """The tree and its read-outs (best sequence, Eq. 15, Graphviz). Episodes and their Eq. 7 updates run in the C
    kernel (kernel.py); the Python reference of an episode is the tests' oracle (test/qtree_reference.py)."""

    def __init__(self, problem: RelocationProblem, oracle: FeasibilityOracle, alpha: float, gamma: float) -> None:
        """`oracle`: any object with feasibility(object_id, removed: frozenset) -> FeasibilityAnswer."""
        self.problem = problem
        self.oracle = oracle
        self.alpha = alpha
        self.gamma = gamma
        self.ids = problem.ids
        self.n_objects = len(self.ids)
        self._actions = tuple(range(self.n_objects))
        self.target = problem.n
        self.phi = [problem.costs[o] for o in problem.obstacles] + [0.0]  # Eq. 13's -phi_i: the costs
        self.root = Node(0, (), 0)
        self.nodes = [self.root]
        self.mp_q = 0  # new edges = motion-planner queries as the paper counts them
        self.q_sum = 0.0  # Eq. 15, incremental

    # -- edges -------------------------------------------------------------------------------------
    def edge_label(self, node: Node, a: int) -> Label:
        """The label of edge (node, a), asking the oracle the first time (one MP_q query)."""
        label = node.label.get(a)
        if label is None:
            removed = node.removed
            if removed is None:
                ids = self.ids
                removed = node.removed = frozenset([ids[i] for i in node.seq])
            raw = self.oracle.feasibility(self.ids[a], removed).label
            label = _LABELS.get(raw)
            if label is None:
                label = Label(raw)  # raises the enum's ValueError for a bad value
            if (label is Label.TARGET) != (a == self.target) and label is not Label.UNFEASIBLE:
                raise ValueError(f"oracle answered {label.name} for {self.ids[a]!r}: TARGET is for the target only")
            node.label[a] = label
            self.mp_q += 1
            if label is Label.UNFEASIBLE:
                node.q_pruned[a] = 0.0
                node.pruned |= 1 << a
                if node.offer is not None:
                    node.offer.remove(a)
            else:
                node.q[a] = 0.0
        return label

    def offered(self, node: Node) -> list[int]:
        """node.offered(n_objects), cached on the node (the list is shared: do not modify it)."""
        offer = node.offer
        if offer is None:
            offer = node.offer = node.offered(self.n_objects)
        return offer

    def child(self, node: Node, a: int) -> Node:
        """The node reached by relocating obstacle a, allocated on first use."""
        c = node.child.get(a)
        if c is None:
            mask = node.mask | (1 << a)
            c = Node(len(self.nodes), node.seq + (a,), mask)
            c.offer = [b for b in self._actions if not (mask >> b) & 1]  # = c.offered(n): nothing pruned here yet
            self.nodes.append(c)
            node.child[a] = c
        return c

    # -- read-outs ---------------------------------------------------------------------------------
    def q_abs_sum(self) -> float:
        """Eq. 15 recomputed from scratch (q_sum is the incremental copy)."""
        return float(sum(abs(v) for n in self.nodes for v in (*n.q.values(), *n.q_pruned.values())))

    @property
    def node_count(self) -> int:
        """Nodes allocated (s_H included)."""
        return len(self.nodes)

    @property
    def n_edges(self) -> int:
        """Edges known (= MP_q)."""
        return sum(len(n.label) for n in self.nodes)

    def best_path(self) -> list[tuple[Node, int]] | None:
        """Follow the highest feasible edge value from the root (ties: lowest index) to the target edge."""
        node, path = self.root, []
        for _ in range(self.n_objects):
            q = node.q
            if not q:
                return None
            best = max(q.values())
            a = min(k for k, v in q.items() if v == best)  # = max(q, key=(q[k], -k))
            path.append((node, a))
            if a == self.target:
                return path
            nxt = node.child.get(a)
            if nxt is None:
                return None
            node = nxt
        return None

    def best_sequence(self) -> tuple[str, ...] | None:
        """The learned sequence: obstacles in order, then the target; None if the greedy path misses it."""
        path = self.best_path()
        return None if path is None else tuple(self.ids[a] for _, a in path)

    def to_dot(self, name: str = "q_tree", highlight: Iterable[tuple[Node, int]] | None = None) -> str:
        """Graphviz text of the tree (paper Fig. 3): edges labelled with the object and Q, unfeasible edges red
        dashed, target edges green, the best sequence in bold."""
        best = {(n.id, a) for n, a in (highlight if highlight is not None else (self.best_path() or []))}
        lines = [f"digraph {name} {{", "  rankdir=TB;", '  node [shape=circle, fontsize=10];']
        for n in self.nodes:
            text = "s_H" if not n.seq else ",".join(self.ids[i] for i in n.seq)
            lines.append(f'  n{n.id} [label="{text}"];')
        for n in self.nodes:
            for a, label in n.label.items():
                q = n.q[a] if a in n.q else n.q_pruned[a]
                style = ", style=bold, penwidth=3" if (n.id, a) in best else ""
                text = f'label="{self.ids[a]}\\nQ={q:.3g}"'
                if label == Label.OBSTACLE:
                    lines.append(f"  n{n.id} -> n{n.child[a].id} [{text}{style}];")
                elif label == Label.TARGET:
                    lines.append(f'  t{n.id} [label="{self.ids[a]}", shape=doublecircle, color=green];')
                    lines.append(f"  n{n.id} -> t{n.id} [{text}, color=green{style}];")
                else:
                    lines.append(f'  u{n.id}_{a} [label="", shape=point, color=red];')
                    lines.append(f"  n{n.id} -> u{n.id}_{a} [{text}, color=red, style=dashed];")
        lines.append("}")
        return "\n".join(lines) + "\n"

    # -- checkpoint state (qtree_task_planner.learning.checkpoint) ------------------------------------------
    def to_state(self) -> dict:
        """Plain data of the whole tree: nodes in allocation order (node id = index), each with its sequence of
        action indices and its edges in creation order as [action, label (Eq. 11), Q]; plus MP_q and the
        incremental Eq. 15 sum, so that a restored tree continues bit for bit."""
        nodes = []
        for n in self.nodes:
            edges = [[a, int(lab), n.q[a] if a in n.q else n.q_pruned[a]] for a, lab in n.label.items()]
            nodes.append({"seq": list(n.seq), "edges": edges})
        return {"nodes": nodes, "mp_q": self.mp_q, "q_sum": self.q_sum}

    def load_state(self, state: dict) -> None:
        """Replace the contents of this tree by `state` (from to_state). ValueError when it does not describe a
        Q-Tree of this problem (bad action index, label, Q, missing parent or child)."""
        n_obj, target = self.n_objects, self.target
        raw = state["nodes"]
        if not raw or list(raw[0]["seq"]):
            raise ValueError("the first node must be the root s_H (empty sequence)")
        nodes: list[Node] = []
        by_seq: dict[tuple[int, ...], Node] = {}
        for k, item in enumerate(raw):
            seq = tuple(item["seq"])
            if any(not isinstance(a, int) or not 0 <= a < target for a in seq) or len(set(seq)) != len(seq):
                raise ValueError(f"node {k}: sequence {list(seq)} is not a sequence of distinct obstacle indices")
            if seq in by_seq:
                raise ValueError(f"node {k}: sequence {list(seq)} appears twice")
            mask = 0
            for a in seq:
                mask |= 1 << a
            node = Node(k, seq, mask)
            for edge in item["edges"]:
                a, lab, q = edge
                if not isinstance(a, int) or not 0 <= a < n_obj or (mask >> a) & 1 or a in node.label:
                    raise ValueError(f"node {k}: bad or repeated action {a!r}")
                label = Label(lab)
                if not isinstance(q, (int, float)) or isinstance(q, bool) or q != q or abs(q) == float("inf"):
                    raise ValueError(f"node {k}: Q of action {a} is not a finite number: {q!r}")
                if label == Label.TARGET and a != target or label == Label.OBSTACLE and a == target:
                    raise ValueError(f"node {k}: label {label.name} does not fit action {a}")
                node.label[a] = label
                if label == Label.UNFEASIBLE:
                    node.q_pruned[a] = float(q)
                    node.pruned |= 1 << a
                else:
                    node.q[a] = float(q)
            if seq:
                parent = by_seq.get(seq[:-1])
                if parent is None or parent.label.get(seq[-1]) != Label.OBSTACLE:
                    raise ValueError(f"node {k}: no parent with a feasible edge {seq[-1]} before it")
                parent.child[seq[-1]] = node
            by_seq[seq] = node
            nodes.append(node)
        for node in nodes:
            for a, label in node.label.items():
                if label == Label.OBSTACLE and a not in node.child:
                    raise ValueError(f"node {node.id}: feasible obstacle edge {a} has no child node")
        self.root, self.nodes = nodes[0], nodes
        self.mp_q = int(state["mp_q"])
        self.q_sum = float(state["q_sum"])
        if self.mp_q != self.n_edges or abs(self.q_sum - self.q_abs_sum()) > 1e-6 * max(1.0, self.q_sum):
            raise ValueError("MP_q or the Eq. 15 sum does not match the edges")
