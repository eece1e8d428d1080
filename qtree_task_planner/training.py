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

from . import kernel
from .checkpoint import Checkpoint, problem_hash
from .oracles import CachedOracle
from relocation_common.feasibility import Label
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
    if not isinstance(problem, RelocationProblem):
        problem = RelocationProblem.from_scenario(problem)
    cache = oracle if isinstance(oracle, CachedOracle) else CachedOracle(oracle)
    calls0 = cache.calls
    t0 = time.perf_counter()
    policy = POLICY_FUNCTIONS[params.policy]
    use_kernel = (callback is None and resume is None and on_checkpoint is None and policy in _KIND
                  and type(cache) is CachedOracle and len(problem.ids) <= kernel.MAX_ACTIONS
                  and QTree.step is _STOCK_STEP and QTree.edge_label is _STOCK_EDGE_LABEL
                  and QTree.child is _STOCK_CHILD and kernel.available())
    tree = (kernel.KernelTree if use_kernel else QTree)(problem, cache, params.alpha, params.gamma)
    rng = random.Random(params.seed)
    depth = params.search == "depth"
    n_obj, target, root = tree.n_objects, tree.target, tree.root
    e_max, i_max = params.max_episodes, params.max_steps
    eps0, eps_min, beta, quiet_needed = params.epsilon0, params.epsilon_min, params.beta, params.quiet_episodes
    step = tree.step
    history: list[float] = []
    prev_sum, quiet, converged, cancelled, e_1st = 0.0, 0, False, False, None
    episode, epsilon, calls_before, elapsed_before = 0, eps0, 0, 0.0
    if resume is not None:
        resume.check_matches(problem, params)
        resume.fill_cache(cache)
        calls0 = cache.calls
        resume.restore_tree(tree)
        root = tree.root
        rng.setstate(resume.rng_state)
        history = list(resume.q_sum_history)
        prev_sum, quiet, converged, cancelled = resume.prev_sum, resume.quiet, resume.converged, False
        e_1st, episode, epsilon = resume.e_1st, resume.episode, resume.epsilon
        calls_before, elapsed_before = resume.planner_calls, resume.elapsed_s

    def snapshot(reason: str) -> Checkpoint:
        return Checkpoint(params, problem_hash(problem), episode, list(history), prev_sum, quiet, e_1st,
                          rng.getstate(), epsilon, calls_before + cache.calls - calls0, converged, cancelled,
                          tree.to_state(), Checkpoint.table_of(cache), elapsed_before + time.perf_counter() - t0,
                          reason)

    if use_kernel:  # the whole loop in C (kernel.py), bit-identical
        path_ok = None
        if optimal_weight is not None:
            def path_ok(actions, ids=problem.ids):
                return problem.weight(tuple(ids[a] for a in actions)) <= optimal_weight + WEIGHT_TOL
        epsilons = [epsilon_schedule(e, e_max, eps0, eps_min) for e in range(e_max)]
        episode, converged, e_1st, history = tree.run(rng, _KIND[policy], depth, i_max, e_max, epsilons, beta,
                                                      quiet_needed, path_ok)
    fast = _Fast(tree, _KIND[policy], depth, i_max) if on_checkpoint is None and _stock(tree, policy) else None
    rand = rng.random
    journal: list = []
    last_seq, last_ok = None, False
    while not use_kernel and episode < e_max and not converged:
        if on_checkpoint is not None:
            episode_start = (rng.getstate(), len(tree.nodes), tree.mp_q, tree.q_sum)
            journal.clear()
        epsilon_prev, epsilon = epsilon, epsilon_schedule(episode, e_max, eps0, eps_min)
        episode += 1
        if fast is not None:
            steps, reached = _episode(fast, epsilon, rand)
        else:
            node, steps, reached = root, 0, False
            try:
                while steps < i_max:
                    offered = node.offered(n_obj)
                    if not offered:
                        break
                    a = policy(node, offered, target, rng, epsilon)
                    steps += 1
                    if on_checkpoint is not None:  # undo log, only needed to checkpoint an interrupted episode
                        journal.append((node, a, (node.q.get(a, node.q_pruned.get(a)) if a in node.label else None)))
                    label, nxt = step(node, a)
                    if label == Label.TARGET:
                        reached = True
                        break
                    if label == Label.UNFEASIBLE:
                        if depth:
                            continue
                        break
                    node = nxt
            except Exception as e:
                if on_checkpoint is not None:
                    rng_state, n_nodes, mp_q0, q_sum0 = episode_start
                    tree.rollback(journal, n_nodes, mp_q0, q_sum0)
                    rng.setstate(rng_state)
                    episode, epsilon = episode - 1, epsilon_prev
                    on_checkpoint(snapshot(f"interrupted: {type(e).__name__}: {e}"))
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
            stats = EpisodeStats(episode, e_max, q_sum, delta, len(tree.nodes), tree.mp_q,
                                 calls_before + cache.calls - calls0, epsilon, steps, reached)
            if callback(stats) is False:
                cancelled = True
        if quiet >= quiet_needed and not cancelled:
            converged = True
        if on_checkpoint is not None:
            stop = cancelled or converged or episode >= e_max
            if stop or (checkpoint_every > 0 and episode % checkpoint_every == 0):
                on_checkpoint(snapshot("cancelled" if cancelled else "final" if stop else "periodic"))
        if cancelled:
            break
    seq = tree.best_sequence()
    return TrainingResult(
        sequence=seq,
        total_weight=problem.weight(seq) if seq is not None else None,
        episodes=episode,
        converged=converged,
        e_ss=episode,
        mp_q=tree.mp_q,
        planner_calls=calls_before + cache.calls - calls0,
        e_1st=e_1st,
        optimal_weight=optimal_weight,
        cancelled=cancelled,
        tree_nodes=tree.node_count,
        tree_edges=tree.n_edges,
        q_sum_history=history,
        params=params,
        elapsed_s=elapsed_before + time.perf_counter() - t0,
        tree=tree,
    )


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
    so the cache's table, calls and queries are the same as with one call per new edge."""

    __slots__ = ("tree", "kind", "depth", "i_max", "memo", "cache", "n1")

    def __init__(self, tree: QTree, kind: int, depth: bool, i_max: int) -> None:
        self.tree, self.kind, self.depth, self.i_max = tree, kind, depth, i_max
        self.cache = tree.oracle if type(tree.oracle) is CachedOracle else None
        self.memo: dict[int, Label] = {}
        self.n1 = tree.n_objects


def _episode(f: _Fast, epsilon: float, rand) -> tuple[int, bool]:
    """One episode from s_H: the reference loop (policy function + QTree.step -> edge_label, child, update)
    inlined. Same random draws, same choices, same float operations in the same order (Eq. 7, Eq. 15), same
    oracle questions, hence bit-identical trees (test/test_q_tree_equivalence.py). Returns (steps, reached)."""
    tree, kind, depth = f.tree, f.kind, f.depth
    node, steps, i_max, target = tree.root, 0, f.i_max, tree.target
    alpha, gamma, phi, ids = tree.alpha, tree.gamma, tree.phi, tree.ids
    nodes, actions, n1 = tree.nodes, tree._actions, f.n1
    cache, memo = f.cache, f.memo
    ask = tree.oracle.feasibility
    obstacle, unfeasible, target_label = Label.OBSTACLE, Label.UNFEASIBLE, Label.TARGET
    q_sum, mp_q = tree.q_sum, tree.mp_q
    zeros = _ZEROS
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
                    removed = node.removed
                    if removed is None:
                        removed = node.removed = frozenset([ids[i] for i in node.seq])
                    raw = ask(ids[a], removed).label
                    label = _LABELS.get(raw)
                    if label is None:
                        label = Label(raw)
                    if (label is target_label) != (a == target) and label is not unfeasible:
                        raise ValueError(f"oracle answered {label.name} for {ids[a]!r}: TARGET is for the target "
                                         "only")
                    if cache is not None:
                        memo[key] = label
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
