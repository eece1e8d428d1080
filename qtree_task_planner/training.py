"""Q-Tree training (paper Sect. 4.2): episodes of breadth or depth search, Eq. 14 exploration, Eq. 16 stop.

An episode starts at the root s_H and ends when the target is relocated, after I_max actions, when no action is
offered, or (breadth search only) at the first unfeasible action. In depth search the agent goes on choosing
another action from the same node (the unfeasible one is pruned there). Training stops after E_max episodes, or
when Eq. 16 holds, |Q_sum(e) - Q_sum(e-1)| <= beta, for `quiet_episodes` consecutive episodes.

`train` is the one entry point: the CLI, the task_planner node (with a ROS service-client oracle) and the
evaluation sweeps (with a shared CachedOracle) call it.
"""
from __future__ import annotations

import gc
import itertools
import random
import time
from dataclasses import dataclass, field
from typing import Any, Callable

from relocation_common.feasibility import Label

from . import kernel
from .checkpoint import Checkpoint, problem_hash
from .oracles import CachedOracle
from .params import TrainingParams
from .policies import POLICY_FUNCTIONS, epsilon_greedy, epsilon_schedule, h_lrnd, lrnd
from .problem import RelocationProblem
from .q_tree import R_TARGET, R_UNFEASIBLE, Node, QTree

WEIGHT_TOL = 1e-9


@dataclass(frozen=True)
class EpisodeStats:
    """What the per-episode callback receives (progress bars, ROS feedback)."""

    episode: int  # 1-based
    max_episodes: int
    q_sum: float  # Eq. 15
    q_sum_delta: float
    tree_nodes: int
    mp_q: int
    planner_calls: int
    epsilon: float
    steps: int
    reached_target: bool


@dataclass
class TrainingResult:
    sequence: tuple[str, ...] | None  # obstacles in order, then the target; None if the greedy path misses it
    total_weight: float | None  # Eq. 8 of `sequence`
    episodes: int  # episodes run
    converged: bool  # Eq. 16 met
    e_ss: int  # episodes to steady state: the episode where training stopped (Eq. 16, else E_max / cancel)
    mp_q: int  # new tree edges = motion-planner queries as the paper counts them
    planner_calls: int  # real oracle calls after the set-keyed cache
    e_1st: int | None  # first episode whose greedy best sequence has the optimal weight (needs the optimum)
    optimal_weight: float | None
    cancelled: bool
    tree_nodes: int
    tree_edges: int
    q_sum_history: list[float]  # Eq. 15 after each episode (paper Fig. 4)
    params: TrainingParams
    elapsed_s: float = field(default=0.0, compare=False)
    tree: QTree | None = field(default=None, compare=False, repr=False)

    @property
    def found(self) -> bool:
        return self.sequence is not None

    def to_dict(self) -> dict[str, Any]:
        return {
            "found": self.found,
            "sequence": list(self.sequence) if self.sequence is not None else None,
            "total_weight": self.total_weight,
            "episodes": self.episodes,
            "converged": self.converged,
            "E_ss": self.e_ss,
            "MP_q": self.mp_q,
            "planner_calls": self.planner_calls,
            "E_1st": self.e_1st,
            "optimal_weight": self.optimal_weight,
            "cancelled": self.cancelled,
            "tree_nodes": self.tree_nodes,
            "tree_edges": self.tree_edges,
            "elapsed_s": self.elapsed_s,
            "params": self.params.to_dict(),
            "q_sum_history": self.q_sum_history,
        }


def train(problem, oracle, params: TrainingParams, *, optimal_weight: float | None = None,
          callback: Callable[[EpisodeStats], bool | None] | None = None,
          resume: Checkpoint | None = None, checkpoint_every: int = 0,
          on_checkpoint: Callable[[Checkpoint], None] | None = None) -> TrainingResult:
    """Train a Q-Tree on `problem` (a RelocationProblem or a Scenario) asking `oracle`.

    oracle: any object with feasibility(object_id, removed: frozenset) -> FeasibilityAnswer; wrapped in a
        CachedOracle unless it is one already (pass a shared CachedOracle to reuse answers across runs;
        planner_calls counts only the calls made during this run).
    optimal_weight: the minimum total weight (exact.solve) to report E_1st; None leaves E_1st None.
    callback: called after every episode; returning False stops training (cancelled=True).
    resume: a Checkpoint (qtree_task_planner.checkpoint) of this problem and these params: training goes on from
        it exactly as the uninterrupted run would (same tree, RNG state, counters); CheckpointError otherwise.
    checkpoint_every, on_checkpoint: on_checkpoint(Checkpoint) after every `checkpoint_every` episodes (0: never)
        and when training stops (converged, E_max, cancelled). If the oracle raises in the middle of an episode
        (planner gone), that episode is rolled back, on_checkpoint receives the state at its start (with every
        feasibility answer gathered so far, so nothing the planner computed is lost) and the error propagates.

    Speed: the episodes run in an inlined loop (`_episode`, bit-identical to policy + QTree.step) unless
    on_checkpoint is given or QTree / the policy is replaced; the cyclic garbage collector is held off while
    training (the tree has no reference cycles; collections passing over a growing tree cost up to ~40 %).
    """
    gc_enabled = gc.isenabled()
    gc.disable()
    try:
        return _train(problem, oracle, params, optimal_weight, callback, resume, checkpoint_every, on_checkpoint)
    finally:
        if gc_enabled:
            gc.enable()


def _train(problem, oracle, params, optimal_weight, callback, resume, checkpoint_every, on_checkpoint):
    """train() with the garbage collector held off: the C kernel when nothing needs the Python loop (no callback,
    resume or checkpoints, stock QTree and policy), else the Python episode loop."""
    if not isinstance(problem, RelocationProblem):
        problem = RelocationProblem.from_scenario(problem)
    cache = oracle if isinstance(oracle, CachedOracle) else CachedOracle(oracle)
    run = _Run(problem, params, cache, optimal_weight)
    policy = POLICY_FUNCTIONS[params.policy]
    use_kernel = (callback is None and resume is None and on_checkpoint is None and policy in _KIND
                  and type(cache) is CachedOracle and len(problem.ids) <= kernel.MAX_ACTIONS
                  and QTree.step is _STOCK_STEP and QTree.edge_label is _STOCK_EDGE_LABEL
                  and QTree.child is _STOCK_CHILD and kernel.available())
    run.tree = (kernel.KernelTree if use_kernel else QTree)(problem, cache, params.alpha, params.gamma)
    if use_kernel:
        _run_kernel(run, _KIND[policy])
    else:
        if resume is not None:
            run.resume(resume)
        _run_python(run, policy, callback, checkpoint_every, on_checkpoint)
    return run.result()


class _Run:
    """One training: problem, params, oracle cache, tree, RNG, and the counters a Checkpoint stores (episode,
    epsilon of Eq. 14, Q_sum history of Eq. 15, the Eq. 16 state prev_sum / quiet / converged, cancelled, E_1st,
    and the planner calls and seconds of the runs before a resume)."""

    def __init__(self, problem: RelocationProblem, params: TrainingParams, cache: CachedOracle,
                 optimal_weight: float | None) -> None:
        self.problem, self.params, self.cache, self.optimal_weight = problem, params, cache, optimal_weight
        self.calls0 = cache.calls
        self.t0 = time.perf_counter()
        self.tree: QTree | None = None
        self.rng = random.Random(params.seed)
        self.episode, self.epsilon, self.history = 0, params.epsilon0, []
        self.prev_sum, self.quiet, self.converged, self.cancelled, self.e_1st = 0.0, 0, False, False, None
        self.calls_before, self.elapsed_before = 0, 0.0

    def resume(self, checkpoint: Checkpoint) -> None:
        """Go on from `checkpoint` (CheckpointError unless it was written for this problem and these params)."""
        checkpoint.check_matches(self.problem, self.params)
        checkpoint.fill_cache(self.cache)
        self.calls0 = self.cache.calls
        checkpoint.restore_tree(self.tree)
        self.rng.setstate(checkpoint.rng_state)
        self.history = list(checkpoint.q_sum_history)
        self.prev_sum, self.quiet, self.converged = checkpoint.prev_sum, checkpoint.quiet, checkpoint.converged
        self.e_1st, self.episode, self.epsilon = checkpoint.e_1st, checkpoint.episode, checkpoint.epsilon
        self.calls_before, self.elapsed_before = checkpoint.planner_calls, checkpoint.elapsed_s

    def planner_calls(self) -> int:
        """Real oracle calls of this training (before a resume included)."""
        return self.calls_before + self.cache.calls - self.calls0

    def elapsed(self) -> float:
        """Seconds of training (before a resume included)."""
        return self.elapsed_before + time.perf_counter() - self.t0

    def snapshot(self, reason: str) -> Checkpoint:
        """The state at the end of the last completed episode, for on_checkpoint."""
        return Checkpoint(self.params, problem_hash(self.problem), self.episode, list(self.history), self.prev_sum,
                          self.quiet, self.e_1st, self.rng.getstate(), self.epsilon, self.planner_calls(),
                          self.converged, self.cancelled, self.tree.to_state(), Checkpoint.table_of(self.cache),
                          self.elapsed(), reason)

    def result(self) -> TrainingResult:
        """The greedy best sequence (Eq. 8 weight) and the training's counters."""
        tree = self.tree
        seq = tree.best_sequence()
        return TrainingResult(
            sequence=seq,
            total_weight=self.problem.weight(seq) if seq is not None else None,
            episodes=self.episode,
            converged=self.converged,
            e_ss=self.episode,
            mp_q=tree.mp_q,
            planner_calls=self.planner_calls(),
            e_1st=self.e_1st,
            optimal_weight=self.optimal_weight,
            cancelled=self.cancelled,
            tree_nodes=tree.node_count,
            tree_edges=tree.n_edges,
            q_sum_history=self.history,
            params=self.params,
            elapsed_s=self.elapsed(),
            tree=tree,
        )


def _optimal_path_test(problem: RelocationProblem, optimal_weight: float | None):
    """For the kernel's E_1st: path_ok(actions) -> the sequence's Eq. 8 weight is the optimum; None without one."""
    if optimal_weight is None:
        return None

    def path_ok(actions, ids=problem.ids):
        return problem.weight(tuple(ids[a] for a in actions)) <= optimal_weight + WEIGHT_TOL
    return path_ok


def _run_kernel(run: _Run, kind: int) -> None:
    """The whole training loop in C (kernel.py), bit-identical to the Python loop: Eq. 14's epsilons of every
    episode, the Eq. 16 stop and E_1st computed there."""
    p = run.params
    epsilons = [epsilon_schedule(e, p.max_episodes, p.epsilon0, p.epsilon_min) for e in range(p.max_episodes)]
    run.episode, run.converged, run.e_1st, run.history = run.tree.run(
        run.rng, kind, p.search == "depth", p.max_steps, p.max_episodes, epsilons, p.beta, p.quiet_episodes,
        _optimal_path_test(run.problem, run.optimal_weight))


def _run_python(run: _Run, policy, callback, checkpoint_every: int, on_checkpoint) -> None:
    """The Python training loop. Per episode: epsilon (Eq. 14), the episode (inlined `_episode`, or
    `_reference_episode` when checkpointing or when QTree / the policy is replaced), Q_sum (Eq. 15) and the
    Eq. 16 stop test, E_1st, the callback, checkpoints. An episode the oracle interrupts is rolled back and
    checkpointed (see train). The counters stay in locals while looping and go back to `run` for a snapshot and
    at the end."""
    tree, rng, problem, optimal_weight, params = run.tree, run.rng, run.problem, run.optimal_weight, run.params
    depth = params.search == "depth"
    e_max, i_max = params.max_episodes, params.max_steps
    eps0, eps_min, beta, quiet_needed = params.epsilon0, params.epsilon_min, params.beta, params.quiet_episodes
    history, prev_sum, quiet, converged, cancelled = run.history, run.prev_sum, run.quiet, run.converged, False
    e_1st, episode, epsilon = run.e_1st, run.episode, run.epsilon
    fast = _Fast(tree, _KIND[policy], depth, i_max) if on_checkpoint is None and _stock(tree, policy) else None
    rand = rng.random
    journal = [] if on_checkpoint is not None else None  # undo log, only to checkpoint an interrupted episode
    last_seq, last_ok = None, False

    def sync() -> None:  # the loop's counters -> run
        run.episode, run.epsilon, run.prev_sum, run.quiet = episode, epsilon, prev_sum, quiet
        run.converged, run.cancelled, run.e_1st = converged, cancelled, e_1st

    while episode < e_max and not converged:
        if journal is not None:
            episode_start = (rng.getstate(), len(tree.nodes), tree.mp_q, tree.q_sum)
            journal.clear()
        epsilon_prev, epsilon = epsilon, epsilon_schedule(episode, e_max, eps0, eps_min)
        episode += 1
        if fast is not None:
            steps, reached = _episode(fast, epsilon, rand)
        else:
            try:
                steps, reached = _reference_episode(tree, policy, rng, epsilon, depth, i_max, journal)
            except Exception as e:
                if journal is not None:
                    rng_state, n_nodes, mp_q0, q_sum0 = episode_start
                    tree.rollback(journal, n_nodes, mp_q0, q_sum0)
                    rng.setstate(rng_state)
                    episode, epsilon = episode - 1, epsilon_prev
                    sync()
                    on_checkpoint(run.snapshot(f"interrupted: {type(e).__name__}: {e}"))
                raise
        q_sum = tree.q_sum
        history.append(q_sum)
        delta = q_sum - prev_sum
        prev_sum = q_sum
        quiet = quiet + 1 if abs(delta) <= beta else 0
        if optimal_weight is not None and e_1st is None:
            seq = tree.best_sequence()
            if seq != last_seq:  # Eq. 8 only when the greedy sequence changed
                last_seq, last_ok = seq, seq is not None and problem.weight(seq) <= optimal_weight + WEIGHT_TOL
            if last_ok:
                e_1st = episode
        if callback is not None:
            stats = EpisodeStats(episode, e_max, q_sum, delta, len(tree.nodes), tree.mp_q, run.planner_calls(),
                                 epsilon, steps, reached)
            if callback(stats) is False:
                cancelled = True
        if quiet >= quiet_needed and not cancelled:
            converged = True
        if on_checkpoint is not None:
            stop = cancelled or converged or episode >= e_max
            if stop or (checkpoint_every > 0 and episode % checkpoint_every == 0):
                sync()
                on_checkpoint(run.snapshot("cancelled" if cancelled else "final" if stop else "periodic"))
        if cancelled:
            break
    sync()


def _reference_episode(tree: QTree, policy, rng: random.Random, epsilon: float, depth: bool, i_max: int,
                       journal: list | None) -> tuple[int, bool]:
    """One episode from s_H by the book: the policy (Eq. 14 epsilon) picks an offered action, QTree.step labels it
    (Eq. 11), rewards (Eq. 13) and updates (Eq. 7). `journal` (or None) gets an undo record per step, for
    QTree.rollback. Returns (steps, reached)."""
    node, steps, n_obj, target, step = tree.root, 0, tree.n_objects, tree.target, tree.step
    while steps < i_max:
        offered = node.offered(n_obj)
        if not offered:
            break
        a = policy(node, offered, target, rng, epsilon)
        steps += 1
        if journal is not None:
            journal.append((node, a, (node.q.get(a, node.q_pruned.get(a)) if a in node.label else None)))
        label, nxt = step(node, a)
        if label == Label.TARGET:
            return steps, True
        if label == Label.UNFEASIBLE:
            if depth:
                continue
            break
        node = nxt
    return steps, False


_STOCK_STEP, _STOCK_EDGE_LABEL, _STOCK_CHILD = QTree.step, QTree.edge_label, QTree.child
_KIND = {lrnd: 0, h_lrnd: 1, epsilon_greedy: 2}
_LABELS = {int(lab): lab for lab in Label}
_ZEROS = itertools.repeat(0.0)


def _stock(tree: QTree, policy) -> bool:
    """The fast episode loop applies when the tree's step and the policy are the stock ones of this package (a
    subclass or a replaced QTree.step / policy goes through the reference loop, which calls them)."""
    cls = type(tree)
    return (policy in _KIND and cls.step is _STOCK_STEP and cls.edge_label is _STOCK_EDGE_LABEL
            and cls.child is _STOCK_CHILD)


class _Fast:
    """Per-training constants of the fast episode loop, and the answer memo.

    memo: (removed mask * (n + 1) + action) -> Label of every (object, removed set) this tree has asked. Only
    used when the oracle is a plain CachedOracle: a repeated question is then answered from the memo and counted
    in CachedOracle.queries exactly as CachedOracle.feasibility would (its answer for a known key never changes),
    so the cache's table, calls and queries are the same as with one call per new edge.
    consts: what `_episode` reads, unpacked in one go (the tree's root, parameters and node list do not change
    while the loop runs)."""

    __slots__ = ("tree", "kind", "depth", "i_max", "memo", "cache", "n1", "consts")

    def __init__(self, tree: QTree, kind: int, depth: bool, i_max: int) -> None:
        self.tree, self.kind, self.depth, self.i_max = tree, kind, depth, i_max
        self.cache = tree.oracle if type(tree.oracle) is CachedOracle else None
        self.memo: dict[int, Label] = {}
        self.n1 = tree.n_objects
        self.consts = (tree, kind, depth, i_max, tree.root, tree.target, tree.alpha, tree.gamma, tree.phi, tree.nodes,
                       tree._actions, self.n1, self.cache, self.memo, Label.OBSTACLE, Label.UNFEASIBLE, _ZEROS)


def _ask(f: _Fast, node: Node, a: int, key: int) -> Label:
    """A new edge's label from the oracle (Eq. 11, as QTree.edge_label): object a after the node's removed set;
    the answer checked (TARGET is for the target only) and memoised under `key` when the memo is in use."""
    tree = f.tree
    ids = tree.ids
    removed = node.removed
    if removed is None:
        removed = node.removed = frozenset([ids[i] for i in node.seq])
    raw = tree.oracle.feasibility(ids[a], removed).label
    label = _LABELS.get(raw)
    if label is None:
        label = Label(raw)
    if (label is Label.TARGET) != (a == tree.target) and label is not Label.UNFEASIBLE:
        raise ValueError(f"oracle answered {label.name} for {ids[a]!r}: TARGET is for the target only")
    if f.cache is not None:
        f.memo[key] = label
    return label


def _episode(f: _Fast, epsilon: float, rand) -> tuple[int, bool]:
    """One episode from s_H: the reference loop (policy function + QTree.step -> edge_label, child, update)
    inlined. Same random draws, same choices, same float operations in the same order (Eq. 7, Eq. 15), same
    oracle questions, hence bit-identical trees (test/test_q_tree_equivalence.py). Returns (steps, reached)."""
    (tree, kind, depth, i_max, node, target, alpha, gamma, phi, nodes, actions, n1, cache, memo, obstacle, unfeasible,
     zeros) = f.consts
    steps, q_sum, mp_q = 0, tree.q_sum, tree.mp_q
    try:
        while steps < i_max:
            offered = node.offer
            if offered is None:
                offered = tree.offered(node)
            n_off = len(offered)
            if not n_off:
                break
            # the policy (policies.py), same draws
            if kind == 0:
                a = offered[int(rand() * n_off)]
            elif offered[-1] == target:
                a = target
            elif kind == 1 or rand() < epsilon:
                a = offered[int(rand() * n_off)]
            else:
                vals = list(map(node.q.get, offered, zeros))  # an edge not in the tree counts 0
                best_v = max(vals)
                if vals.count(best_v) == 1:
                    a = offered[vals.index(best_v)]
                else:  # ties: uniform among them, in offered order
                    best = [b for b, v in zip(offered, vals) if v == best_v]
                    a = best[int(rand() * len(best))]
            steps += 1
            # QTree.step: label (Eq. 11, QTree.edge_label), reward (Eq. 13), update (Eq. 7), Eq. 15
            label = node.label.get(a)
            if label is None:  # new edge: one MP_q query
                key = node.mask * n1 + a
                label = memo.get(key) if cache is not None else None
                if label is None:
                    label = _ask(f, node, a, key)
                else:
                    cache.queries += 1
                node.label[a] = label
                mp_q += 1
                if label is unfeasible:
                    node.q_pruned[a] = 0.0
                    node.pruned |= 1 << a
                    offered.remove(a)
                else:
                    node.q[a] = 0.0
            if label is obstacle:
                nxt = node.child.get(a)
                if nxt is None:  # QTree.child
                    mask = node.mask | (1 << a)
                    nxt = Node(len(nodes), node.seq + (a,), mask)
                    free = node.free
                    if free is None:
                        free = node.free = tuple(b for b in actions if not (node.mask >> b) & 1)
                    offer = list(free)
                    offer.remove(a)  # = nxt.offered(n): nothing pruned there yet
                    nxt.offer = offer
                    nxt.free = tuple(offer)
                    nodes.append(nxt)
                    node.child[a] = nxt
                nq = nxt.q
                q = node.q
                old = q[a]
                new = old + alpha * ((-phi[a] + gamma * (max(nq.values()) if nq else 0.0)) - old)
                q[a] = new
                q_sum += abs(new) - abs(old)
                node = nxt
            elif label is unfeasible:
                q = node.q_pruned
                old = q[a]
                new = old + alpha * (R_UNFEASIBLE - old)
                q[a] = new
                q_sum += abs(new) - abs(old)
                if not depth:
                    break
            else:
                q = node.q
                old = q[a]
                new = old + alpha * (R_TARGET - old)
                q[a] = new
                q_sum += abs(new) - abs(old)
                return steps, True
        return steps, False
    finally:
        tree.q_sum, tree.mp_q = q_sum, mp_q
