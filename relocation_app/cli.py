"""`qtree` command line: train the Q-Tree on a scenario, or solve it exactly.

    qtree train --scenario FILE [--policy h-eg --search depth --alpha ... --seed ...] [--json OUT] [--tree-dot F]
    qtree solve --scenario FILE [--solver astar|ucs] [--oracle planner|blocking|replicas [--replicas N]] [--json OUT]

Defaults come from config/task_planner.yaml (or --params FILE). Bad input: one line on stderr, exit 2.
Feasibility oracles are built by ORACLES[name](scenario, args): `blocking` (the scenario's declared relation, a
test double) or `planner` (the real motion planner in this process, config/motion_planner.yaml, with its lane
blockers) or `replicas` (N motion planner processes started over ROS, asked one question each at once by the
exact solvers: qtree_task_planner.executive.replicas); the default is `blocking` for a scenario with a `blocking:`
section,
`planner` otherwise. Exact solvers:
`astar` (qtree_task_planner.search.astar, blockers) or `ucs` (qtree_task_planner.search.exact, the uniform-cost
reference). The
real oracle calls and the wall time go into the JSON and, as one line, to stderr.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from contextlib import ExitStack
from pathlib import Path
from typing import Callable

from qtree_task_planner.learning.params import POLICIES, SEARCHES, TrainingParams
from qtree_task_planner.learning.training import train
from qtree_task_planner.oracles import BlockingOracle, CachedOracle
from qtree_task_planner.problem import ActionCosts, ProblemError, RelocationProblem
from qtree_task_planner.search import astar, exact
from qtree_task_planner.search.exact import no_sequence
from relocation_app.progress import Progress
from relocation_common.config import ParameterError
from relocation_common.scenario import ScenarioError, UnknownObjectError, load_scenario


class CliError(Exception):
    """A one-line user error."""


def _blocking_oracle(scenario, args):
    return BlockingOracle(scenario)


def _planner_oracle(scenario, args):
    from stpik_motion_planner.model.grasp import WorkspaceError
    from stpik_motion_planner.planning.params import PlannerParams
    from stpik_motion_planner.planning.planner import MotionPlanner

    try:
        return MotionPlanner(scenario, PlannerParams.load())  # a LaneOracle: lane_blockers too
    except (WorkspaceError, ValueError) as e:
        raise CliError(f"motion planner: {e}") from None


def _replicas_oracle(scenario, args):
    """N motion planner processes over ROS, one question in flight each (stopped when qtree exits)."""
    from relocation_app.evaluation.replica_fill import replica_oracle
    from relocation_common.paths import resolve_scenario
    if not 1 <= args.replicas <= 16:
        raise CliError(f"--replicas must be in 1..16, got {args.replicas}")
    return args.stack.enter_context(replica_oracle(resolve_scenario(args.scenario), args.replicas))


# name -> factory(scenario, args) -> oracle with feasibility(object_id, removed)
ORACLES: dict[str, Callable] = {"blocking": _blocking_oracle, "planner": _planner_oracle,
                                "replicas": _replicas_oracle}
SOLVERS: dict[str, Callable] = {"astar": astar.solve, "ucs": exact.solve}


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # one line, no usage block
        raise CliError(f"{message} (see {self.prog} --help)")


def _parser() -> argparse.ArgumentParser:
    p = _Parser(prog="qtree", description="Q-Tree task planner: train, or solve exactly.")
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)

    def common(sp):
        sp.add_argument("--scenario", required=True, help="scenario YAML, or a name under config/scenarios")
        sp.add_argument("--oracle", choices=sorted(ORACLES),
                        help="feasibility oracle (blocking: the scenario's declared relation, a test double; "
                             "planner: the motion planner in this process; replicas: N planner processes over "
                             "ROS). Default: blocking if the scenario has a blocking: section, else planner")
        sp.add_argument("--replicas", type=int, default=2,
                        help="--oracle replicas: motion planner processes started over ROS (default 2)")
        sp.add_argument("--solver", choices=sorted(SOLVERS), default="astar",
                        help="exact solver (astar: lazy A* with blockers; ucs: uniform-cost reference)")
        sp.add_argument("--json", metavar="OUT", help="write the JSON result here instead of stdout")

    t = sub.add_parser("train", help="train the Q-Tree")
    common(t)
    t.add_argument("--params", help="ROS params file with the defaults (default: config/task_planner.yaml)")
    t.add_argument("--policy", choices=POLICIES)
    t.add_argument("--search", choices=SEARCHES)
    for name, typ in (("alpha", float), ("gamma", float), ("epsilon0", float), ("epsilon-min", float),
                      ("max-episodes", int), ("max-steps", int), ("beta", float), ("quiet-episodes", int),
                      ("seed", int)):
        t.add_argument(f"--{name}", type=typ)
    t.add_argument("--tree-dot", metavar="FILE", help="write the tree in Graphviz form (paper Fig. 3)")
    t.add_argument("--solve-first", action="store_true",
                   help="run the exact solver (--solver) first, own cache, to report E_1st")
    t.add_argument("--no-progress", action="store_true", help="no progress bar")
    s = sub.add_parser("solve", help="the exact minimum-weight sequence (Eq. 8)")
    common(s)
    return p


def _load(args):
    scenario = load_scenario(args.scenario)
    # each obstacle costed by the pick its pose takes (config/task_planner.yaml action_cost; the --params file's)
    problem = RelocationProblem.from_scenario(scenario, ActionCosts.from_yaml(getattr(args, "params", None)))
    if args.oracle is None:
        args.oracle = "blocking" if getattr(scenario, "blocking", None) is not None else "planner"
    oracle = ORACLES[args.oracle](scenario, args)
    return scenario, problem, oracle


def _exact(problem, oracle, solver: str) -> dict:
    """The exact solver's result with the real oracle calls (a fresh cache) and its wall time."""
    cache = CachedOracle(oracle)
    t0 = time.perf_counter()
    result = SOLVERS[solver](problem, cache)
    return {"solver": solver, **result.to_dict(), "planner_calls": cache.calls,
            "wall_time_s": round(time.perf_counter() - t0, 4)}


def _report(what: str, args, calls: int, wall: float) -> None:
    print(f"qtree: {what}, {args.oracle} oracle: {calls} real oracle calls, {wall:.2f} s", file=sys.stderr)


def _emit(data: dict, out: str | None) -> None:
    text = json.dumps(data, indent=2)
    if out:
        try:
            Path(out).write_text(text + "\n")
        except OSError as e:
            raise CliError(f"cannot write {out}: {e.strerror}") from None
    else:
        print(text)


def _progress_bar(episodes: int) -> tuple[Callable, Progress]:
    """(callback, bar): progress on stderr (relocation_app.progress: a bar on a terminal, a line every few seconds
    in a log) advanced by train()'s callback every few episodes (Q_sum of Eq. 15, tree nodes, MP_q)."""
    bar = Progress("episodes", "ep", total=episodes, leave=False)

    def callback(st) -> None:
        bar.update(st.episode, postfix=f"q_sum={st.q_sum:.1f} nodes={st.tree_nodes} mp_q={st.mp_q}")
    return callback, bar


def _train(args) -> int:
    base = TrainingParams.from_yaml(args.params)
    params = base.replace(policy=args.policy, search=args.search, alpha=args.alpha, gamma=args.gamma,
                          epsilon0=args.epsilon0, epsilon_min=args.epsilon_min, max_episodes=args.max_episodes,
                          max_steps=args.max_steps, beta=args.beta, quiet_episodes=args.quiet_episodes,
                          seed=args.seed)
    scenario, problem, oracle = _load(args)
    optimum = cost = None
    solved = None
    if args.solve_first:
        solved = _exact(problem, oracle, args.solver)
        optimum, cost = solved["total_weight"], solved.get("total_cost", solved["total_weight"])
    callback, bar = (None, None) if args.no_progress else _progress_bar(params.max_episodes)
    t0 = time.perf_counter()
    try:
        result = train(problem, CachedOracle(oracle), params, optimal_weight=optimum, optimal_cost=cost,
                       callback=callback)
    finally:
        if bar is not None:
            bar.close()
    wall = time.perf_counter() - t0
    if args.tree_dot:
        try:
            assert result.tree is not None  # train always returns its tree
            Path(args.tree_dot).write_text(result.tree.to_dot(name=scenario.name.replace("-", "_")))
        except OSError as e:
            raise CliError(f"cannot write {args.tree_dot}: {e.strerror}") from None
    data = {"scenario": scenario.name, "oracle": args.oracle, **result.to_dict(), "wall_time_s": round(wall, 4)}
    if solved is not None:
        data["exact"] = solved
        _report(f"solve {args.solver}", args, solved["planner_calls"], solved["wall_time_s"])
    _emit(data, args.json)
    _report("train", args, data["planner_calls"], wall)
    return 0


def _solve(args) -> int:
    from stpik_motion_planner.model.grasp import WorkspaceError
    scenario, problem, oracle = _load(args)
    try:
        data = {"scenario": scenario.name, "oracle": args.oracle, **_exact(problem, oracle, args.solver)}
    except WorkspaceError as e:  # a grasp out of the arm's reach (its distance against the arm's)
        data = {"scenario": scenario.name, "oracle": args.oracle, "solver": args.solver, "found": False,
                "sequence": None, "reason": f"{no_sequence(problem.action_set)}out of reach: {e}"}
    _emit(data, args.json)
    if not data["found"]:
        print(f"qtree: {' '.join(str(data['reason']).split())}", file=sys.stderr)
    if "planner_calls" in data:
        _report(f"solve {args.solver}", args, data["planner_calls"], data["wall_time_s"])
    return 0


def main(argv: list[str] | None = None) -> int:
    """Run `qtree train` or `qtree solve`; exit status 0, 2 on bad input (one line on stderr), 130 on Ctrl-C."""
    try:
        args = _parser().parse_args(argv)
        with ExitStack() as args.stack:  # what an oracle started (planner processes) stops here
            return _train(args) if args.command == "train" else _solve(args)
    except (CliError, ScenarioError, UnknownObjectError, ParameterError, ProblemError) as e:
        msg = " ".join(str(e).split())  # one line
        print(f"qtree: error: {msg}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("qtree: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
