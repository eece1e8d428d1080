"""Re-key the committed feasibility caches (data/feasibility/) after motion planner parameters were ADDED whose
defaults keep every answer (docs/motion_planner.md): the entries stay as they are, only the key (a hash of every
PlannerParams field, relocation_app/evaluation/feasibility_cache.py) and the file name change. It refuses a file
whose old key does not match its own content, or a changed (not added) parameter.

`--reask`: for an added parameter that can only turn an answer the planner attempted and refused into a feasible
one (a tolerance such as stpik.grasp_yaw_tol, which changes nothing on a path that converged), those entries
(UNFEASIBLE with attempts > 0) are asked again with the new parameters and replaced; answers screened out without
an attempt and feasible ones stay. Then `./run evaluate fill` asks the sets the new answers make reachable.

    .venv/bin/python scripts/rekey_feasibility_caches.py [--check] [--reask]
"""
from __future__ import annotations

import argparse
import hashlib
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def main() -> int:
    from relocation_app.evaluation.__main__ import planner_params
    from relocation_app.evaluation.feasibility_cache import CACHE_VERSION, DATA_DIR, planner_content, scenario_content
    from relocation_common.paths import scenarios_dir
    from relocation_common.scenario import load_scenario
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true", help="only say what would change")
    ap.add_argument("--reask", action="store_true", help="ask the attempted UNFEASIBLE entries again (docstring)")
    a = ap.parse_args()
    new_planner = planner_content(planner_params())
    scenes = {p.stem: p for p in scenarios_dir().rglob("*.yaml")}
    for path in sorted(Path(DATA_DIR).glob("*.json")):
        data = json.loads(path.read_text())
        sc = load_scenario(scenes[data["scenario"]])

        def key(planner: dict) -> str:
            blob = json.dumps({"version": CACHE_VERSION, "scenario": scenario_content(sc), "planner": planner},
                              sort_keys=True, separators=(",", ":"))
            return hashlib.sha256(blob.encode()).hexdigest()
        old = data["planner"]
        if key(old) != data["key"]:
            raise SystemExit(f"{path}: its key does not match its own content; not touched")
        changed = {k for k in old if old[k] != new_planner.get(k) and not _added_only(old[k], new_planner.get(k))}
        if changed:
            raise SystemExit(f"{path}: parameters changed, not only added ({sorted(changed)}): recompute it instead")
        new_key = key(new_planner)
        target = path.with_name(f"{data['scenario']}-{new_key[:12]}.json")
        print(f"{path.name} -> {target.name} (added {sorted(set(new_planner) - set(old))})")
        if a.reask and not a.check:
            print(f"  {reask(data, sc)}", flush=True)
        if not a.check and (target != path or a.reask):
            data.update(key=new_key, planner=new_planner)
            target.write_text(json.dumps(data, separators=(",", ":")) + "\n")
            if target != path:
                path.unlink()
    return 0


def _added_only(old, new) -> bool:
    """A nested group of parameters (stpik.*) that only gained keys."""
    return isinstance(old, dict) and isinstance(new, dict) and all(new.get(k) == v for k, v in old.items())


def reask(data: dict, scenario) -> str:
    """Ask the entries the planner attempted and refused (label UNFEASIBLE, attempts > 0) again with the
    configured parameters, in place; what changed, in one line."""
    from relocation_app.evaluation.__main__ import planner_params
    from relocation_app.evaluation.feasibility_cache import worker_planner
    cols = data["columns"]
    i_label, i_time, i_att = cols.index("label"), cols.index("planning_time_s"), cols.index("attempts")
    todo = [e for e in data["entries"] if e[i_label] == 0 and e[i_att] > 0]
    if not todo:
        return "nothing to ask again"
    mp = worker_planner(scenario, planner_params())
    flipped = 0
    for e in todo:
        ans = mp.feasibility(e[0], frozenset(e[1]))
        flipped += int(ans.label) != 0
        e[i_label], e[i_time], e[i_att] = int(ans.label), round(ans.planning_time, 6), ans.attempts
    return f"asked {len(todo)} refused answers again: {flipped} became feasible"


if __name__ == "__main__":
    raise SystemExit(main())
