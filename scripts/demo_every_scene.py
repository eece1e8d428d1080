"""The demo (relocation_app.demo, the README's main job) on every shipped scene, one after the other: a table of
success, the learned and the exact optimum's weights, what was executed and the wall time (docs/benchmarks.md,
"The demo on every shipped scene"; runs in docs/bench/demo.md).

Each scene runs `python -m relocation_app.demo --scenario NAME --no-record --out OUT/NAME [EXTRA...]` in its own
process (a fresh node graph); its report.json is read back. The `blocking_*` scenes are left out: test doubles of
the lane screen, with no geometric retrieval. A scene whose OUT/NAME/report.json exists is not run again, so a
sweep cut short goes on where it stopped.

    nice -n 5 .venv/bin/python scripts/demo_every_scene.py --out /tmp/demos [--scenes scenario1_5 paper1_5]
        [-- --scene-source ground_truth]
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # this checkout's packages first

from relocation_common.paths import scenarios_dir

HEADER = ("| scene | result | learned (weight) | exact optimum (weight) | executed | target on the bottom shelf, "
          "arm home, gripper empty | wall s |\n|---|---|---|---|---|---|---|")


def shipped_scenes() -> list[str]:
    """Every scene under config/scenarios (sub-folders included) but the blocking_* test doubles, by name."""
    return sorted(p.stem for p in scenarios_dir().rglob("*.yaml") if not p.stem.startswith("blocking_"))


def row(name: str, report: dict) -> str:
    """One line of the table from a demo's report.json."""
    def seq(key: str) -> str:
        w = report.get(f"{key}_weight")
        return f"{' '.join(report.get(f'{key}_sequence') or []) or '-'} ({w:.2f})" if w is not None else "-"
    end = report.get("final_scene") or {}
    ends = all(end.get(k) for k in ("target_on_bottom_shelf", "arm_home", "gripper_empty"))
    return (f"| {name} | {'SUCCESS' if report.get('success') else 'FAILED: ' + report.get('message', '')} | "
            f"{seq('learned')} | {seq('optimal')} | {report.get('executed', '-')} | {'yes' if ends else 'no'} | "
            f"{report.get('wall_time_s', 0):.0f} |")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--scenes", nargs="+", help="default: every shipped scene but blocking_*")
    p.add_argument("extra", nargs="*", help="after --: more demo options (e.g. --scene-source ground_truth)")
    a = p.parse_args()
    lines = []
    for name in a.scenes or shipped_scenes():
        out = a.out / name
        report = out / "report.json"
        if not report.exists():
            cmd = [sys.executable, "-m", "relocation_app.demo", "--scenario", name, "--no-record", "--out", str(out),
                   *a.extra]
            print(f"[sweep] {name}: {' '.join(cmd[1:])}", flush=True)
            out.mkdir(parents=True, exist_ok=True)
            with open(out.with_suffix(".log"), "w") as log:
                subprocess.run(cmd, stdout=log, stderr=subprocess.STDOUT, check=False)
        if not report.exists():
            lines.append(f"| {name} | FAILED: no report.json (log: {out.with_suffix('.log')}) | | | | | |")
        else:
            lines.append(row(name, json.loads(report.read_text())))
        print(lines[-1], flush=True)
    print(HEADER)
    print("\n".join(lines))


if __name__ == "__main__":
    main()
