"""Q-Tree training (paper Sect. 4.2): episodes of breadth or depth search, Eq. 14 exploration, Eq. 16 stop.

An episode starts at the root s_H and ends when the target is relocated, after I_max actions, when no action is
offered, or (breadth search only) at the first unfeasible action. In depth search the agent goes on choosing
another action from the same node (the unfeasible one is pruned there). Training stops after E_max episodes, or
when Eq. 16 holds, |Q_sum(e) - Q_sum(e-1)| <= beta, for `quiet_episodes` consecutive episodes.

Lazy certification (docs/qtree.md, "Certified sequences"): the episodes learn from pick answers; when training stops
(Eq. 16 or E_max) the learned sequence is certified (CachedOracle.certify_many: the whole relocation of each edge,
all at once over planner replicas). An edge that fails is unfeasible from then on: relabelled in the tree (its
subtree dropped: KernelTree.relabel) and in the cache, and training goes on (more episodes while E_max allows) until
the learned sequence certifies or the greedy path misses the target. An oracle without certification (a test
double, an eager planner) gives final answers: its sequence is certified as it is.

`train` is the one entry point: the CLI, the task_planner node (with a ROS service-client oracle) and the
evaluation sweeps (with a shared CachedOracle) call it. The episodes run in one engine, the C kernel (kernel.py);
the reference (test/qtree_reference.py) is the tests' oracle.
"""
from __future__ import annotations

import ctypes
import gc
import math
import random
import time
from dataclasses import dataclass, field
from typing import Any, Callable

from qtree_task_planner.learning import kernel
from qtree_task_planner.learning.checkpoint import Checkpoint, problem_hash
from qtree_task_planner.learning.kernel import KernelTree
from qtree_task_planner.learning.params import TrainingParams
from qtree_task_planner.learning.policies import epsilon_schedule
from qtree_task_planner.learning.q_tree import QTree
from qtree_task_planner.oracles import CachedOracle
from qtree_task_planner.problem import RelocationProblem
from relocation_common.feasibility import FeasibilityOracle, Label
from relocation_common.scenario import Scenario

WEIGHT_TOL = 1e-9
CALLBACK_S = 0.2  # s: a batch of episodes that asked the oracle longer than this ends early for the callback


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
    """What a training learned (the greedy sequence, Eq. 8) and its counters (E_ss, MP_q, E_1st, Eq. 15)."""

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
    certify_calls: int = 0  # certifications asked of the oracle by this run (not answered by the cache)
    relabelled: int = 0  # learned edges a failed certification turned unfeasible
    total_cost: float | None = None  # `sequence`'s total cost (problem.RelocationProblem.cost) in a costed problem (an
    # action factor other than 1), else None: the costs are the weights
    optimal_cost: float | None = None  # the optimum's total cost E_1st was measured against (a costed problem)
    elapsed_s: float = field(default=0.0, compare=False)
    tree: QTree | None = field(default=None, compare=False, repr=False)

    @property
    def found(self) -> bool:
        """Whether the greedy path reaches the target."""
        return self.sequence is not None

    def to_dict(self) -> dict[str, Any]:
        """Plain data (JSON; the tree left out)."""
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
            "certify_calls": self.certify_calls,
            "relabelled": self.relabelled,
            "elapsed_s": self.elapsed_s,
            "params": self.params.to_dict(),
            "q_sum_history": self.q_sum_history,
            **({} if self.total_cost is None else {"total_cost": self.total_cost}),
            **({} if self.optimal_cost is None else {"optimal_cost": self.optimal_cost}),
        }


def train(problem: RelocationProblem | Scenario, oracle: FeasibilityOracle, params: TrainingParams, *,
          optimal_weight: float | None = None, optimal_cost: float | None = None,
          callback: Callable[[EpisodeStats], bool | None] | None = None, callback_every: int = 10,
          resume: Checkpoint | None = None, checkpoint_every: int = 0,
          on_checkpoint: Callable[[Checkpoint], None] | None = None) -> TrainingResult:
    """Train a Q-Tree on `problem` (a RelocationProblem or a Scenario) asking `oracle`.

    oracle: any object with feasibility(object_id, removed: frozenset) -> FeasibilityAnswer; wrapped in a
        CachedOracle unless it is one already (pass a shared CachedOracle to reuse answers across runs;
        planner_calls counts only the calls made during this run).
    optimal_weight: the optimum's total weight (Eq. 8; exact.solve), reported; E_1st is the first episode whose
        greedy sequence costs no more than `optimal_cost`, the optimum's total cost (problem.RelocationProblem.cost:
        the weight when every action factor is 1, so a problem without a factor other than 1 may give the weight
        alone; ValueError for one with such a factor). Neither: E_1st None.
    callback: called with the last episode's stats every `callback_every` episodes, when training stops, and
        after an episode that asked the oracle for more than CALLBACK_S seconds since the last call (a slow
        planner); returning False stops training there (cancelled=True).
    resume: a Checkpoint (qtree_task_planner.learning.checkpoint) of this problem and these params: training goes on
    from
        it exactly as the uninterrupted run would (same tree, RNG state, counters); CheckpointError otherwise.
    checkpoint_every, on_checkpoint: on_checkpoint(Checkpoint) after every `checkpoint_every` episodes (0: never)
        and when training stops (converged, E_max, cancelled). If the oracle raises in the middle of an episode
        (planner gone), that episode is rolled back, on_checkpoint receives the state at its start (with every
        feasibility answer gathered so far, so nothing the planner computed is lost) and the error propagates.

    The episodes run in the C kernel (kernel.py) in batches between callbacks, bit-identical to the reference
    (test/qtree_reference.py); the cyclic garbage collector is held off while training (the tree has no
    reference cycles; collections passing over a growing tree cost up to ~40 %).
    """
    if not isinstance(problem, RelocationProblem):
        problem = RelocationProblem.from_scenario(problem)
    if callback_every < 1:
        raise ValueError(f"callback_every must be >= 1, got {callback_every}")
    if optimal_cost is None and optimal_weight is not None:
        if problem.costed:
            raise ValueError("the problem's costs are not its weights (an action factor other than 1): give "
                             "optimal_cost, the optimum's total cost, for E_1st")
        optimal_cost = optimal_weight
    cache = oracle if isinstance(oracle, CachedOracle) else CachedOracle(oracle)
    run = _Run(problem, params, cache, optimal_weight, optimal_cost)
    gc_enabled = gc.isenabled()
    gc.disable()
    try:
        if resume is not None:
            run.resume(resume)
        while True:
            _run_batches(run, callback, callback_every if callback is not None else 0, checkpoint_every,
                         on_checkpoint)
            if run.cancelled or run.certified():
                break
    finally:
        if gc_enabled:
            gc.enable()
    return run.result()


class _Run:
    """One training: problem, params, oracle cache, the kernel's tree, the RNG, and the counters a Checkpoint
    stores (episode, epsilon of Eq. 14, Q_sum history of Eq. 15, the Eq. 16 state prev_sum / quiet / converged,
    cancelled, E_1st, and the planner calls and seconds of the runs before a resume)."""

    def __init__(self, problem: RelocationProblem, params: TrainingParams, cache: CachedOracle,
                 optimal_weight: float | None, optimal_cost: float | None) -> None:
        self.problem, self.params, self.cache, self.optimal_weight = problem, params, cache, optimal_weight
        self.optimal_cost = optimal_cost
        self.calls0 = cache.calls
        self.t0 = time.perf_counter()
        self.tree = KernelTree(problem, cache, params.alpha, params.gamma)
        self.rng = random.Random(params.seed)
        self.episode, self.epsilon = 0, params.epsilon0
        self.history: list[float] = []
        self.prev_sum, self.quiet, self.converged, self.cancelled = 0.0, 0, False, False
        self.e_1st: int | None = None
        self.calls_before, self.elapsed_before = 0, 0.0
        self.cert0, self.relabelled = cache.cert_calls, 0

    def certified(self) -> bool:
        """Certify the learned sequence (module doc): True when it certifies or there is none; else its failed edges
        are relabelled unfeasible, Eq. 16's count starts again and False (train goes on: more episodes, or at
        E_max the next greedy sequence)."""
        seq = self.tree.best_sequence()
        if seq is None:
            return True
        edges = [(o, frozenset(seq[:k])) for k, o in enumerate(seq)]
        failed = [e for e, a in zip(edges, self.cache.certify_many(edges)) if a.label == Label.UNFEASIBLE]
        for o, removed in failed:
            self.relabelled += self.tree.relabel(o, removed)
        if failed:
            self.converged, self.quiet = False, 0
            self.tree.push_state(self.rng, self.episode, self.prev_sum, self.quiet, self.converged, self.e_1st)
        return not failed

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

    def pull(self, history: _Buffers, rng: bool = False) -> kernel.RunState:
        """The kernel's counters (and with `rng` its RNG state) -> this run, after a batch."""
        state = self.tree.pull_state(self.rng if rng else None)
        self.history.extend(history[self.episode:state.episode])
        self.episode, self.prev_sum, self.quiet = state.episode, state.prev_sum, state.quiet
        self.converged, self.e_1st = state.converged, state.e_1st
        if self.episode:
            self.epsilon = history.epsilons[self.episode - 1]
        return state

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
            certify_calls=self.cache.cert_calls - self.cert0,
            relabelled=self.relabelled,
            total_cost=self.problem.cost(seq) if seq is not None and self.problem.costed else None,
            optimal_cost=self.optimal_cost if self.problem.costed else None,
            elapsed_s=self.elapsed(),
            tree=tree,
        )


def _optimal_path_test(problem: RelocationProblem, optimal_cost: float | None) -> kernel.PathTest | None:
    """For the kernel's E_1st: path_ok(actions) -> the sequence's total cost (Eq. 8 with the costs: the weight at
    factor 1) is the optimum's; None without one."""
    if optimal_cost is None:
        return None

    def path_ok(actions: tuple[int, ...], ids: tuple[str, ...] = problem.ids) -> bool:
        return problem.cost(tuple(ids[a] for a in actions)) <= optimal_cost + WEIGHT_TOL
    return path_ok


class _Buffers:
    """The kernel's per-episode arrays: Eq. 14 epsilon of every episode (in), Eq. 15 sum (out)."""

    def __init__(self, p: TrainingParams) -> None:
        self.epsilons = [epsilon_schedule(e, p.max_episodes, p.epsilon0, p.epsilon_min) for e in range(p.max_episodes)]
        self.eps_c = (ctypes.c_double * max(1, p.max_episodes))(*self.epsilons)
        self.q_sum = (ctypes.c_double * max(1, p.max_episodes))()

    def __getitem__(self, index: slice) -> list[float]:
        return self.q_sum[index]


def _next_stop(episode: int, e_max: int, *every: int) -> int:
    """The first episode after `episode` where a callback is due (a multiple of a nonzero `every`), or E_max."""
    return min([e_max] + [(episode // n + 1) * n for n in every if n > 0])


def _run_batches(run: _Run, callback: Callable[[EpisodeStats], bool | None] | None, callback_every: int,
                 checkpoint_every: int, on_checkpoint: Callable[[Checkpoint], None] | None) -> None:
    """The training loop: the kernel runs episodes up to the next callback or checkpoint (epsilon of Eq. 14, the
    episode, Q_sum of Eq. 15, the Eq. 16 stop test and E_1st per episode), then Python reports. An episode the
    oracle interrupts is rolled back by the kernel and checkpointed here (see train)."""
    p, tree = run.params, run.tree
    buf = _Buffers(p)
    tree.push_state(run.rng, run.episode, run.prev_sum, run.quiet, run.converged, run.e_1st)
    path_ok = _optimal_path_test(run.problem, run.optimal_cost) if run.e_1st is None else None
    if on_checkpoint is None:
        checkpoint_every = 0
    while run.episode < p.max_episodes and not run.converged:
        stop_at = _next_stop(run.episode, p.max_episodes, callback_every, checkpoint_every)
        deadline = time.monotonic() + CALLBACK_S if callback is not None else math.inf
        try:
            tree.run(p.policy, p.search == "depth", p.max_steps, stop_at, buf.eps_c, p.beta, p.quiet_episodes,
                     path_ok, buf.q_sum, deadline)
        except Exception as e:
            run.pull(buf, rng=True)
            if on_checkpoint is not None:
                on_checkpoint(run.snapshot(f"interrupted: {type(e).__name__}: {e}"))
            raise
        state = run.pull(buf)
        if callback is not None:
            delta = state.prev_sum - (run.history[-2] if len(run.history) > 1 else 0.0)
            stats = EpisodeStats(run.episode, p.max_episodes, state.prev_sum, delta, tree.node_count, tree.mp_q,
                                 run.planner_calls(), run.epsilon, state.steps, state.reached)
            if callback(stats) is False:
                run.cancelled = True
                run.converged = False  # Eq. 16 met at this very episode (the last of the batch): cancel wins
        if on_checkpoint is not None:
            stop = run.cancelled or run.converged or run.episode >= p.max_episodes
            if stop or (checkpoint_every > 0 and run.episode % checkpoint_every == 0):
                run.pull(buf, rng=True)
                on_checkpoint(run.snapshot("cancelled" if run.cancelled else "final" if stop else "periodic"))
        if run.cancelled:
            break
    run.pull(buf, rng=True)
