"""Benchmark: pay for certainty only where it is used (docs/benchmarks.md, "Lazy certification"). Not a timed test.

Old and new side by side in one run, on every shipped scene (config/scenarios, its random5/ and paper_random5/
folders, the blocking_* scenes and the world/ ones that load), in-process with the real MotionPlanner and the code the
task planner node runs (qtree_task_planner.oracles.CachedOracle, search.astar.solve, learning.training.train with
config/task_planner.yaml's parameters, no training when the A* proves there is no sequence, as the node;
executive.retrieval.chosen_sequence):

- old: eager certification (certify_relocation: every feasible answer plans its carry, retreat and way home), a
  plain cache (no reuse);
- new: lazy certification (the pick is the answer; the A*'s optimum and the learned sequence certified) and reuse
  across answers (CachedOracle reuse=True: near sets, certain blocker claims).

Per scene and mode: real planner calls (picks; certifications apart), the A*'s and training's calls, training wall
time, learned weight against the proven optimum, the in-process time of a feasible answer (p50, p95 of the planner's
own planning_time) and of an unfeasible one, and the executed sequence (chosen_sequence, as the node executes it)
planned end to end (relocation.plan_relocation) and replayed in MuJoCo by the independent checker
(test/motion_checker.py): contacts counted. Reuse safety (new): every answer given by reuse replayed in MuJoCo in
the scene of the question it answered (the removed objects on the bottom shelf), contacts counted.

    .venv/bin/python scripts/bench_certification.py --out /tmp/cert.jsonl            # every scene (an hour or more)
    .venv/bin/python scripts/bench_certification.py --scenes paper_experiment_10     # one scene
    .venv/bin/python scripts/bench_certification.py --summary /tmp/cert.jsonl        # the table of a run
    .venv/bin/python scripts/bench_certification.py --latency scenario3_15 --rounds 2  # a feasible answer's time

--latency SCENE: a feasible answer's in-process time (the planner's planning_time, p50 / p95) during a uniform-cost
solve of the scene (qtree_task_planner.search.exact.solve, every question asked of the planner), old and new
alternated `--rounds` times in one process, so that a change of the machine's load hits both.

--latency SCENE --baseline REV: the same with the lazy planner of git revision REV (its stpik_motion_planner/,
exported by bench_motion_planner.export_package) against the working tree's, each in a fresh process, alternated
`--rounds` times; prints feasible and unfeasible p50 / p95 of each (wall time, and the feasible ones' process time),
their ratio, and whether both gave the same answers (label, attempts, message and trajectory bit for bit, question
by question).
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "test")]
# BENCH_IMPL_DIR: a directory holding another stpik_motion_planner/ (--latency --baseline), found first
sys.path[:0] = [os.environ["BENCH_IMPL_DIR"]] if os.environ.get("BENCH_IMPL_DIR") else []

SAFETY_NET = 300.0  # s: the wall-clock safety nets, far above the work budgets on a loaded machine (no answer moves)
MODES = ("old", "new")


def scenes() -> list[str]:
    """Every shipped scene: the top level, random5/, paper_random5/, then world/ (those that load are run)."""
    from relocation_common.paths import scenarios_dir
    root = scenarios_dir()
    return [p.stem for p in sorted(root.glob("*.yaml"))] + [
        f"{d}/{p.stem}" for d in ("random5", "paper_random5", "world") for p in sorted((root / d).glob("*.yaml"))]


class Answers:
    """The planner as the node's oracle sees it, with the planner's own time of every answer it gave. `certify`
    only in the new mode: the old (eager) planner's answers are final (a cache asks it nothing more)."""

    def __init__(self, planner: Any, certifying: bool) -> None:
        self.planner, self.times, self.cert_times = planner, [], []
        self.lane_blockers = planner.lane_blockers
        if certifying:
            self.certify = self._certify

    def feasibility(self, object_id: str, removed: frozenset[str]) -> Any:
        a = self.planner.feasibility(object_id, removed)
        self.times.append((int(a.label) != 0, a.planning_time))
        return a

    def _certify(self, object_id: str, removed: frozenset[str]) -> Any:
        a = self.planner.certify(object_id, removed)
        self.cert_times.append((int(a.label) != 0, a.planning_time))
        return a


def _pct(xs: list[float], q: float) -> float | None:
    xs = sorted(xs)
    return round(1000 * xs[min(len(xs) - 1, int(round(q * (len(xs) - 1))))], 1) if xs else None


def run_mode(name: str, mode: str) -> dict:
    """One scene in one mode (the module docstring)."""
    from qtree_task_planner.executive.retrieval import chosen_sequence, proven_none
    from qtree_task_planner.learning.params import TrainingParams
    from qtree_task_planner.learning.training import train
    from qtree_task_planner.oracles import CachedOracle
    from qtree_task_planner.problem import RelocationProblem
    from qtree_task_planner.search import astar
    from relocation_common.scenario import load_scenario
    from stpik_motion_planner.planning.params import PlannerParams
    from stpik_motion_planner.planning.planner import MotionPlanner

    sc = load_scenario(name)
    params = dataclasses.replace(PlannerParams.load(), certify_relocation=mode == "old", timeout=SAFETY_NET,
                                 carry_timeout=SAFETY_NET)
    planner = MotionPlanner(sc, params)
    if sc.unlisted:  # the scene as the node has it: perception (or /sim/objects) reports the unlisted objects too
        planner.set_scenario(sc.with_objects(sc.world))
    answers = Answers(planner, certifying=mode == "new")
    cache = CachedOracle(answers, reuse=mode == "new")
    problem = RelocationProblem.from_scenario(planner.scenario)
    t0 = time.perf_counter()
    opt = astar.solve(problem, cache)
    t1 = time.perf_counter()
    astar_calls, astar_certs = cache.calls, cache.cert_calls
    if opt.found:
        r = train(problem, cache, TrainingParams.defaults(), optimal_weight=opt.total_weight)
    else:  # proven: no sequence; the node trains no episode then either
        r = proven_none(TrainingParams.defaults(), 0)
    t2 = time.perf_counter()
    seq, note = chosen_sequence(r.sequence, r.total_weight, opt.sequence, opt.total_weight, execute_optimum=False,
                                execute_learned=False)
    feasible = [t for ok, t in answers.times if ok]
    out = {"file": name, "scene": sc.name, "mode": mode, "objects": len(sc.objects),
           "optimum": list(opt.sequence or ()), "optimal_weight": opt.total_weight,
           "learned": list(r.sequence or ()), "learned_weight": r.total_weight,
           "learned_is_optimum": r.total_weight is not None and opt.total_weight is not None
           and r.total_weight <= opt.total_weight + 1e-9, "e_ss": r.e_ss, "converged": r.converged,
           "astar_s": round(t1 - t0, 2), "train_s": round(t2 - t1, 2), "astar_calls": astar_calls,
           "astar_certs": astar_certs, "train_calls": cache.calls - astar_calls,
           "train_certs": cache.cert_calls - astar_certs, "relabelled": r.relabelled, "calls": cache.calls,
           "certs": cache.cert_calls, "reused": len(cache.reused), "feasible_p50_ms": _pct(feasible, 0.5),
           "feasible_p95_ms": _pct(feasible, 0.95), "feasible_n": len(feasible),
           "unfeasible_p50_ms": _pct([t for ok, t in answers.times if not ok], 0.5),
           "cert_p50_ms": _pct([t for _, t in answers.cert_times], 0.5), "executed": seq, "note": note}
    out.update(replay_sequence(sc, planner, seq))  # in the simulator's world (sc.world: unlisted objects too)
    if mode == "new":
        out.update(replay_reused(sc, cache))
    return out


def replay_sequence(sc: Any, planner: Any, seq: list[str]) -> dict:
    """The executed sequence planned end to end and replayed in MuJoCo: {'contacts': n or None, 'why': ...}."""
    from motion_checker import MotionChecker, Report, replay_relocation

    from stpik_motion_planner.execution.relocation import plan_relocation
    from stpik_motion_planner.planning.results import PlanningError

    if not seq:
        return {"contacts": None, "why": "no sequence"}
    checker, rep, done = MotionChecker(sc), Report(), []
    try:
        for oid in seq:
            plan = plan_relocation(planner, oid, done)
            rep.merge(replay_relocation(checker, plan.pick, [plan.carry, plan.retreat], plan.home, oid))
            done.append(oid)
    except PlanningError as e:
        return {"contacts": None, "why": f"not planned: {e}"}
    return {"contacts": len(rep.contacts), "why": "; ".join(map(str, rep.contacts[:3]))}


def replay_reused(sc: Any, cache: Any) -> dict:
    """Every feasible answer given by reuse replayed in the scene of its question: the removed objects stand in the
    bottom shelf's slots (beyond the slots: off the shelf), the pick from home to the grasp checked as
    test_motion_checker checks an answer. {'reused_feasible': n, 'reused_contacts': n, 'reused_why': ...}."""
    import mujoco
    from motion_checker import MotionChecker, Report

    rep, n = Report(), 0
    for (oid, removed), a in sorted(cache.table.items(), key=lambda kv: (kv[0][0], sorted(kv[0][1]))):
        if (oid, removed) not in cache.reused or a.trajectory is None or int(a.label) == 0:
            continue
        c = MotionChecker(sc)
        for k, other in enumerate(sorted(removed)):
            adr = c._free[other]
            x, y = sc.slot(k) if k < len(sc.slots) else (-2.0 - k, 2.0)
            c.data.qpos[adr:adr + 3] = (x, y, sc.shelf.bottom_z if k < len(sc.slots) else 0.0)
        mujoco.mj_kinematics(c.model, c.data)
        rep.merge(c.check(a.trajectory, f"{oid}|{','.join(sorted(removed))}", picking=oid,
                          approach_from=dict(a.trajectory.phases)["approach"]))
        n += 1
    return {"reused_feasible": n, "reused_contacts": len(rep.contacts),
            "reused_why": "; ".join(map(str, rep.contacts[:3]))}


def latency(name: str, rounds: int) -> str:
    """A feasible answer's time during a uniform-cost solve, old and new alternated (the module docstring)."""
    from qtree_task_planner.search import exact
    from relocation_common.scenario import load_scenario
    from stpik_motion_planner.planning.params import PlannerParams
    from stpik_motion_planner.planning.planner import MotionPlanner

    sc = load_scenario(name)
    times: dict[str, list[float]] = {m: [] for m in MODES}
    unfeasible: dict[str, list[float]] = {m: [] for m in MODES}
    for _ in range(rounds):
        for mode in MODES:
            params = dataclasses.replace(PlannerParams.load(), certify_relocation=mode == "old", timeout=SAFETY_NET,
                                         carry_timeout=SAFETY_NET)
            answers = Answers(MotionPlanner(sc, params), certifying=False)
            exact.solve(sc, answers)
            times[mode] += [t for ok, t in answers.times if ok]
            unfeasible[mode] += [t for ok, t in answers.times if not ok]
    return "\n".join(f"{name} {mode}: feasible p50 {_pct(times[mode], 0.5)} ms, p95 {_pct(times[mode], 0.95)} ms "
                     f"({len(times[mode])} answers); unfeasible p50 {_pct(unfeasible[mode], 0.5)} ms "
                     f"({len(unfeasible[mode])})" for mode in MODES)


def answers_of(name: str) -> list[list]:
    """The lazy planner's answers during a uniform-cost solve of `name`, in order: [object, removed, label,
    planning time, digest of (attempts, message, trajectory)] (--baseline: one process per run)."""
    import hashlib

    from qtree_task_planner.search import exact
    from relocation_common.scenario import load_scenario
    from stpik_motion_planner.planning.params import PlannerParams
    from stpik_motion_planner.planning.planner import MotionPlanner

    sc = load_scenario(name)
    params = dataclasses.replace(PlannerParams.load(), certify_relocation=False, timeout=SAFETY_NET,
                                 carry_timeout=SAFETY_NET)
    planner, out = MotionPlanner(sc, params), []

    class Recorder(Answers):
        def feasibility(self, object_id: str, removed: frozenset[str]) -> Any:
            c0 = time.process_time()
            a = self.planner.feasibility(object_id, removed)
            cpu = time.process_time() - c0
            t = a.trajectory
            lanes = [(sorted(b.objects), b.certain, b.lane) for b in a.blockers]
            h = hashlib.sha256(repr((a.attempts, a.message, lanes, sorted(a.near or ()))).encode())
            m = hashlib.sha256()  # the motion alone
            if t is not None:
                motion = t.times.tobytes() + t.positions.tobytes() + t.velocities.tobytes() + repr(t.phases).encode()
                h.update(motion)
                m.update(motion)
            out.append([object_id, sorted(removed), int(a.label), a.planning_time, h.hexdigest()[:16],
                        m.hexdigest()[:16], a.message, cpu])
            return a

    exact.solve(sc, Recorder(planner, certifying=False))
    return out


def latency_baseline(name: str, rev: str, rounds: int) -> str:
    """REV's lazy planner against the working tree's, alternated in fresh processes (the module docstring)."""
    import subprocess

    from bench_motion_planner import export_package  # scripts/ is sys.path[0]: the sibling benchmark

    impls = ((rev, export_package(rev)), ("working tree", ""))
    runs: dict[str, list[list]] = {k: [] for k, _ in impls}
    for _ in range(rounds):
        for key, impl in impls:
            env = dict(os.environ, BENCH_IMPL_DIR=impl)
            res = subprocess.run([sys.executable, __file__, "--answers", name], env=env, capture_output=True,
                                 text=True, check=True)
            runs[key].append(json.loads(res.stdout.strip().splitlines()[-1]))
    ref = [(r[0], r[1], r[2], r[4]) for r in runs[rev][0]]
    same = all([(r[0], r[1], r[2], r[4]) for r in run] == ref for v in runs.values() for run in v)
    lines, stats = [f"{name}: uniform-cost solve, {rounds} runs of each planner alternated, {len(ref)} questions a "
                    f"run; same answers (label, attempts, message, trajectory bit for bit): {same}"], {}
    if not same:
        lines.append(answers_differ(runs[rev][0], runs["working tree"][0]))
    for key, rs in runs.items():
        f = [r[3] for run in rs for r in run if r[2] != 0]
        u = [r[3] for run in rs for r in run if r[2] == 0]
        stats[key] = (_pct(f, 0.5), _pct(f, 0.95), _pct(u, 0.5), _pct(u, 0.95))
        lines.append(f"  {key:14s} feasible p50 {stats[key][0]} ms, p95 {stats[key][1]} ms ({len(f)} answers); "
                     f"unfeasible p50 {stats[key][2]} ms, p95 {stats[key][3]} ms ({len(u)})")
        cf = [r[7] for run in rs for r in run if r[2] != 0]
        lines.append(f"  {'':14s} process time: feasible p50 {_pct(cf, 0.5)} ms, p95 {_pct(cf, 0.95)} ms (the "
                     f"question's CPU, which the machine's load moves less than its wall time)")
    b, w = stats[rev], stats["working tree"]
    lines.append(f"  ratio {rev} / working tree: feasible p50 {b[0] / w[0]:.2f}x, p95 {b[1] / w[1]:.2f}x; "
                 f"unfeasible p50 {b[2] / w[2]:.2f}x, p95 {b[3] / w[3]:.2f}x")
    return "\n".join(lines)


def answers_differ(old: list[list], new: list[list]) -> str:
    """How the working tree's answers differ from REV's, question by question: the questions asked, labels,
    motions (the trajectory bit for bit), and the answers that differ in attempts, message or blockers only."""
    if [r[:2] for r in old] != [r[:2] for r in new]:
        return "  the questions asked differ (the solve took another course)"
    labels = sum(o[2] != n[2] for o, n in zip(old, new))
    motions = sum(o[2] == n[2] and o[5] != n[5] for o, n in zip(old, new))
    rest = [(o, n) for o, n in zip(old, new) if o[2] == n[2] and o[5] == n[5] and o[4] != n[4]]
    shown = f"; e.g. {rest[0][0][0]}: '{rest[0][0][6]}' -> '{rest[0][1][6]}'" if rest else ""
    return (f"  labels changed: {labels}, motions changed: {motions}, answers changed in attempts, message or "
            f"blockers only: {len(rest)}{shown}")


def one(name: str, modes: tuple[str, ...]) -> list[dict]:
    """Both modes of a scene (a scene that does not load: one row saying why)."""
    rows = []
    for mode in modes:
        try:
            rows.append(run_mode(name, mode))
        except Exception as e:  # a scene that does not load or plan: said, the run goes on
            rows.append({"file": name, "scene": name, "mode": mode, "error": f"{type(e).__name__}: {e}"})
        print(json.dumps(rows[-1]), flush=True)
    return rows


def summary(rows: list[dict]) -> str:
    """The markdown table of a run: one line per scene, old | new."""
    by: dict[str, dict[str, dict]] = {}
    for r in rows:
        by.setdefault(r["scene"], {})[r["mode"]] = r
    head = ("| scene | calls old / new (+ cert) | reused | A* calls old / new | training s old / new | learned = "
            "optimum old / new | weight | feasible p50 / p95 ms old / new | executed contacts old / new | reused "
            "answers replayed: contacts |")
    lines = [head, "|" + "---|" * 10]
    tot = {"old_calls": 0, "new_calls": 0, "new_certs": 0, "old_s": 0.0, "new_s": 0.0}
    for scene, m in by.items():
        o, n = m.get("old", {}), m.get("new", {})
        if "error" in o or "error" in n or not o or not n:
            lines.append(f"| {scene} | {o.get('error') or n.get('error') or 'missing'} |" + " |" * 8)
            continue
        tot["old_calls"] += o["calls"]
        tot["new_calls"] += n["calls"]
        tot["new_certs"] += n["certs"]
        tot["old_s"] += o["train_s"]
        tot["new_s"] += n["train_s"]
        w = f"{n['learned_weight']:.2f}" if n["learned_weight"] is not None else "none"
        lines.append(
            f"| {scene} | {o['calls']} / {n['calls']} (+{n['certs']}) | {n['reused']} | "
            f"{o['astar_calls']} / {n['astar_calls']} (+{n['astar_certs']}) | "
            f"{o['train_s']:.1f} / {n['train_s']:.1f} | "
            f"{_yes(o)} / {_yes(n)} | {w} | {o['feasible_p50_ms']} / {o['feasible_p95_ms']} ; "
            f"{n['feasible_p50_ms']} / {n['feasible_p95_ms']} | {_contacts(o)} / {_contacts(n)} | "
            f"{n.get('reused_feasible', 0)}: {n.get('reused_contacts', 0)} |")
    lines.append(f"\nTotal real planner calls old {tot['old_calls']}, new {tot['new_calls']} picks + "
                 f"{tot['new_certs']} certifications; training wall time old {tot['old_s']:.0f} s, new "
                 f"{tot['new_s']:.0f} s.")
    return "\n".join(lines)


def _yes(r: dict) -> str:
    if not r["learned"]:
        return "none" if not r["optimum"] else "no sequence"
    return "yes" if r["learned_is_optimum"] else f"no ({r['learned_weight']:.2f} vs {r['optimal_weight']:.2f})"


def _contacts(r: dict) -> str:
    return str(r["contacts"]) if r["contacts"] is not None else r["why"][:60]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", nargs="*", help="scene names (default: every shipped scene)")
    ap.add_argument("--modes", nargs="*", default=list(MODES), choices=MODES)
    ap.add_argument("--out", help="JSON lines, one per scene and mode (resumable: scenes there are skipped)")
    ap.add_argument("--summary", help="print the table of a run's JSON lines and exit")
    ap.add_argument("--latency", metavar="SCENE", help="a feasible answer's time, old and new (module docstring)")
    ap.add_argument("--rounds", type=int, default=1, help="--latency: old and new alternated this many times")
    ap.add_argument("--baseline", metavar="REV", help="--latency: REV's lazy planner against the working tree's")
    ap.add_argument("--answers", metavar="SCENE", help=argparse.SUPPRESS)  # --baseline's one run, as JSON
    a = ap.parse_args()
    if a.answers:
        print(json.dumps(answers_of(a.answers)))
        return
    if a.latency:
        print(f"# {time.strftime('%Y-%m-%d %H:%M')}, load {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
        print(latency_baseline(a.latency, a.baseline, a.rounds) if a.baseline else latency(a.latency, a.rounds))
        print(f"# {time.strftime('%Y-%m-%d %H:%M')}, load at the end {os.getloadavg()[0]:.1f}")
        return
    if a.summary:
        print(summary([json.loads(x) for x in Path(a.summary).read_text().splitlines() if x.strip()]))
        return
    done: set[tuple[str, str]] = set()
    rows: list[dict] = []
    if a.out and Path(a.out).exists():
        rows = [json.loads(x) for x in Path(a.out).read_text().splitlines() if x.strip()]
        done = {(r["file"], r["mode"]) for r in rows}
    print(f"# {time.strftime('%Y-%m-%d %H:%M')}, load {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores", flush=True)
    for name in a.scenes or scenes():
        todo = tuple(m for m in a.modes if (name, m) not in done)
        got = one(name, todo) if todo else []
        rows += got
        if a.out:
            with open(a.out, "a") as f:
                f.writelines(json.dumps(r) + "\n" for r in got)
    print(summary(rows))


if __name__ == "__main__":
    main()
