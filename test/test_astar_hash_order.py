"""The blocker A*'s answer does not depend on the process's string-hash seed (Python iterates sets of names in hash
order): weights summed over a set in another order round differently, and a tie of equal weight (Eq. 8) then goes
to another optimum in another process."""
import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

# T is blocked by a, b and c together in one lane, by d alone in the other: 0.1 + 0.2 + 0.3 and 0.6 weigh the same,
# but 0.1 + 0.2 + 0.3 != 0.3 + 0.2 + 0.1 in floating point. The A* prefers the deeper of two equal sets.
SCRIPT = r"""
import json
from qtree_task_planner.search import astar
from qtree_task_planner.problem import RelocationProblem
from relocation_common.feasibility import FeasibilityAnswer, Label

LANES = {"T": [frozenset("abc"), frozenset("d")]}

class Oracle:
    def feasibility(self, o, removed):
        ok = any(b <= removed for b in LANES.get(o, [frozenset()]))
        return FeasibilityAnswer((Label.TARGET if o == "T" else Label.OBSTACLE) if ok else Label.UNFEASIBLE)

weights = {"a": 0.1, "b": 0.2, "c": 0.3, "d": 0.6, "e": 0.7, "f": 0.9}
problem = RelocationProblem(obstacles=tuple(weights), weights=weights, target="T")
r = astar.solve(problem, Oracle())
print(json.dumps(list(r.sequence)))
"""


def test_the_same_optimum_under_every_hash_seed():
    seen = {}
    for seed in range(12):
        env = dict(os.environ, PYTHONHASHSEED=str(seed), PYTHONPATH=str(ROOT))
        out = subprocess.run([sys.executable, "-c", SCRIPT], env=env, cwd=ROOT, capture_output=True, text=True,
                             check=True, timeout=60)
        seen.setdefault(tuple(json.loads(out.stdout)), []).append(seed)
    assert len(seen) == 1, f"optima by hash seed: {seen}"
