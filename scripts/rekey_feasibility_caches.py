"""Re-key the committed feasibility caches (data/feasibility/) after motion planner parameters were ADDED whose
defaults keep every answer (docs/motion_planner.md): the entries stay as they are, only the key (a hash of every
PlannerParams field, relocation_app/evaluation/feasibility_cache.py) and the file name change. It refuses a file
whose old key does not match its own content, or a changed (not added) parameter.

    .venv/bin/python scripts/rekey_feasibility_caches.py [--check]
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
        changed = {k for k in old if old[k] != new_planner.get(k)}
        if changed:
            raise SystemExit(f"{path}: parameters changed, not only added ({sorted(changed)}): recompute it instead")
        new_key = key(new_planner)
        target = path.with_name(f"{data['scenario']}-{new_key[:12]}.json")
        print(f"{path.name} -> {target.name} (added {sorted(set(new_planner) - set(old))})")
        if not a.check and target != path:
            data.update(key=new_key, planner=new_planner)
            target.write_text(json.dumps(data, separators=(",", ":")) + "\n")
            path.unlink()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
