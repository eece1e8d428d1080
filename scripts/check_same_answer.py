"""Same question, same answer, at scale (the long version of test/test_question_seeded.py; not a timed test).

N random feasibility questions (object, removed set) on shipped scenes and their perturbed layouts (scenes
jitter), asked by one planner in one order, by another in the reverse order and by a third process in a shuffled
order; prints the fraction of identical labels and trajectories (bit for bit) per comparison.

    .venv/bin/python scripts/check_same_answer.py [--queries 300] [--set seed_per_query=false]
"""
from __future__ import annotations

import argparse
import json
import random
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "test"), str(ROOT / "scripts")]

SCENES = (("paper_experiment_10", 0.0), ("scenario3_15", 0.0), ("paper3_15", 0.012), ("scenario3_15", 0.020))


def questions(n: int, tmp: str) -> list[tuple[str, str, list[str]]]:
    """n questions (scene file, object, removed) spread over SCENES, seeded."""
    from relocation_app.evaluation.scenes.jitter import make_jitter
    from relocation_common.paths import resolve_scenario
    from relocation_common.scenario import load_scenario
    rng, out = random.Random(0), []
    for k, (scene, amp) in enumerate(SCENES):
        path = make_jitter(scene, amp, [0], tmp)[0] if amp else resolve_scenario(scene)
        ids = [o.id for o in load_scenario(path).objects]
        for _ in range(n // len(SCENES) + (k < n % len(SCENES))):
            obj = rng.choice(ids)
            others = [i for i in ids if i != obj]
            out.append((str(path), obj, sorted(rng.sample(others, rng.randint(0, len(others) // 2)))))
    return out


def ask(qs, sets: list[str]) -> dict:
    """question -> label:trajectory digest, one planner per scene, in the order given."""
    from bench_perturbed_layouts import _params
    from test_question_seeded import digest

    from relocation_common.scenario import load_scenario
    from stpik_motion_planner.planning.planner import MotionPlanner
    planners: dict = {}
    out = {}
    for path, obj, removed in qs:
        if path not in planners:
            planners[path] = MotionPlanner(load_scenario(path), _params(sets))
        answer = planners[path].feasibility(obj, frozenset(removed))
        out[f"{Path(path).stem}|{obj}|{','.join(removed)}"] = digest(answer)
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--queries", type=int, default=300)
    ap.add_argument("--set", action="append", default=["seed_per_query=true"], help="planner parameter key=value")
    ap.add_argument("--child", default=None, help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.child:
        qs = json.loads(Path(a.child).read_text())
        random.Random(1).shuffle(qs)
        print(json.dumps(ask(qs, a.set)))
        return 0
    with tempfile.TemporaryDirectory() as tmp:
        qs = questions(a.queries, tmp)
        first = ask(qs, a.set)
        reverse = ask(qs[::-1], a.set)
        (Path(tmp) / "q.json").write_text(json.dumps(qs))
        cmd = [sys.executable, __file__, "--child", str(Path(tmp) / "q.json")] + [f"--set={s}" for s in a.set]
        other = json.loads(subprocess.run(cmd, capture_output=True, text=True, check=True).stdout.splitlines()[-1])
    n = len(first)
    feasible = sum(not d.startswith("0:") for d in first.values())
    print(f"{n} questions ({feasible} feasible), parameters {a.set}")
    for what, got in (("reverse order, same process", reverse), ("shuffled, another process", other)):
        same = sum(got[k] == v for k, v in first.items())
        print(f"  {what}: {same}/{n} identical ({100 * same / n:.1f} %)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
