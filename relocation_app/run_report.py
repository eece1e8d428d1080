"""The demo's report: report.json however the run ends, its summary lines, the one next step, the exit code.

A run ends one way of END (the exit code says which; README.md "Options", docs/reliability.md "A node that
dies"): the target retrieved (0), the retrieval failed with a reason (1), a node died and did not come back (3:
the driver, whose death leaves the arm's state unknown; the task planner during the execution; a node past its
max_respawns), out of time (4: --timeout), another error (5: the graph did not come up, no scene), or stopped by a
signal (130 SIGINT, 143 SIGTERM). Whatever the end, report.json says what was done (the relocations checked, the
re-plans: the task planner's ~/execution, published after each step), what was interrupted (the phase, the
relocation in flight), where each object was last known (the simulator's ground truth, /sim/objects, and how old
it is), the nodes that died and were respawned, and one next step. Success only with the target on the bottom
shelf by the ground truth; no sentinel values: what is missing is said in words.
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

END = {"success": 0, "failed": 1, "node_died": 3, "timeout": 4, "error": 5, "interrupted": 130}  # kind -> exit code
SIGTERM_EXIT = 143  # "interrupted" by SIGTERM (128 + 15), as shells report it


@dataclass(frozen=True)
class End:
    """How the run ended: a kind of END, one line, and the signal for "interrupted" (15: SIGTERM)."""

    kind: str
    message: str
    signal: int = 2

    @property
    def exit_code(self) -> int:
        """The demo's exit status (the module docstring)."""
        return SIGTERM_EXIT if self.kind == "interrupted" and self.signal == 15 else END[self.kind]


def check_scene(scenario_path: str, before: dict, after: dict, relocated) -> dict:
    """Where the bottles ended (simulator ground truth): the target on the bottom shelf, the others unmoved."""
    from relocation_common.scenario import load_scenario
    s = load_scenario(scenario_path)
    z_bottom = s.shelf.bottom_z
    on_bottom = {i: abs(p[2] - z_bottom) < 0.02 and s.shelf.x_front < p[0] < s.shelf.x_back
                 for i, p in after.items()}
    untouched = [i for i in after if i not in relocated and i in before]
    moved = [float(np.linalg.norm(np.subtract(after[i], before[i]))) for i in untouched]
    return {"target_on_bottom_shelf": bool(on_bottom.get(s.target_id, False)),
            "relocated_on_bottom_shelf": {i: bool(on_bottom.get(i, False)) for i in relocated},
            "max_displacement_untouched_m": max(moved, default=0.0), "positions_after": after}


def where(scenario_path: str, positions: dict, age_s: float | None, at_hand: list) -> dict:
    """Each object's last known place: its base centre, 'top shelf', 'bottom shelf', 'in the hand' or 'elsewhere
    (off the shelf)', from the ground truth received `age_s` s before the end (None: never)."""
    from relocation_common.scenario import load_scenario
    sh = load_scenario(scenario_path).shelf
    out = {}
    for i, p in positions.items():
        inside = sh.x_front - 0.05 < p[0] < sh.x_back + 0.05 and sh.y_min - 0.05 < p[1] < sh.y_max + 0.05
        board = "top shelf" if inside and abs(p[2] - sh.top_z) < 0.02 else \
            "bottom shelf" if inside and abs(p[2] - sh.bottom_z) < 0.02 else None
        out[i] = {"base": [round(v, 4) for v in p], "where": "in the hand" if i in at_hand else
                  board or "elsewhere (off the shelf, or lifted)"}
    return {"source": "simulator ground truth (/sim/objects)", "age_s": None if age_s is None else round(age_s, 1),
            "objects": out}


def training_fields(res: Any) -> dict:
    """The TrainPlanner result's numbers, or None for each when the goal had no result (the run ended first)."""
    if res is None:
        return {k: None for k in ("learned_sequence", "learned_weight", "optimal_sequence", "optimal_weight",
                                  "episodes", "E_ss", "MP_q", "E_1st", "planner_calls")} | {"q_sum_history": []}
    return {"learned_sequence": list(res.sequence), "learned_weight": res.total_weight if res.sequence else None,
            "optimal_sequence": list(res.optimal_sequence),
            "optimal_weight": res.optimal_weight if res.optimal_sequence else None,
            "episodes": res.episodes, "E_ss": res.e_ss, "MP_q": res.mp_q,
            "E_1st": res.e_first if res.e_first >= 0 and res.episodes else None,
            "planner_calls": res.planner_calls, "q_sum_history": list(res.q_sum_history)}


def write(out: Path, report: dict) -> None:
    """report.json, written whole (a temporary file renamed: a run killed meanwhile leaves the old or the new)."""
    tmp = out / "report.json.tmp"
    tmp.write_text(json.dumps(report, indent=2))
    tmp.replace(out / "report.json")


def summary(report: dict) -> list[str]:
    """The demo's closing lines from its report."""
    lines = []
    fs, tr = report.get("final_scene") or {}, report
    if fs and "target_on_bottom_shelf" in fs:
        lines.append(f"target on the bottom shelf: {fs['target_on_bottom_shelf']}; largest displacement of a bottle "
                     f"not relocated: {fs.get('max_displacement_untouched_m', 0.0) * 100:.1f} cm; arm home: "
                     f"{fs.get('arm_home')}; gripper empty: {fs.get('gripper_empty')}")
    if tr["learned_sequence"] is not None:
        lw, ow = tr["learned_weight"], tr["optimal_weight"]
        lines.append("learned sequence: " + (f"{' -> '.join(tr['learned_sequence'])}  weight {lw:.2f}" if lw is not None
                                             else "none (training found no sequence to the target)"))
        lines.append("exact optimum:    " + (f"{' -> '.join(tr['optimal_sequence'])}  weight {ow:.2f}" if ow is not None
                                             else "none (no feasible sequence)"))
        e_first = str(tr["E_1st"]) if tr["E_1st"] is not None else "not reached"
        lines.append(f"E_ss={tr['E_ss']} MP_q={tr['MP_q']} E_1st={e_first} real planner calls={tr['planner_calls']}"
                     if tr["episodes"] else "training did not run an episode")
    for d in report["disturbances"]:
        lines.append(f"disturbance {d.get('when', '')}: {d.get('kind', 'command')} {d.get('object', '')}"
                     + (f" skipped: {d['skipped']}" if "skipped" in d else ""))
    for r in report["replans"]:
        lines.append(f"re-plan: {r['reason']} -> " + (f"{' '.join(r['sequence'])} ({r['weight']:.2f})"
                                                      if r.get("sequence") else r.get("failure", ""))
                     + (f"; {r['note']}" if r.get("note") else ""))
    for p in report.get("pushes", []):
        lines.append(p["line"])
    for e in report["respawns"]:
        lines.append(f"node {e['node']} {e['event']} at {e['t']:.0f} s" + (f" (exit {e['code']})" if e["code"]
                                                                          is not None else "") + f": {e['note']}")
    for r in report.get("resumed", []):
        flight = f"; {r['in_flight']} in flight, " + ("ended" if r["in_flight_ended"] else "still moving") \
            if r.get("in_flight") else ""
        lines.append(f"task planner died during the execution at {r['t']:.0f} s (phase: {r['phase'][:80]}); relocated "
                     f"before: {' '.join(r['relocated_before']) or 'none'}{flight}; the goal sent again")
    if report.get("interrupted"):
        lines.append(f"interrupted: {report['interrupted']['what']}")
    end = report["end"]
    lines.append(f"{'SUCCESS' if report['success'] else end['kind'].upper().replace('_', ' ')}: {report['message']}"
                 f"  ({report['wall_time_s']:.0f} s; exit {end['exit_code']}); outputs in {report['out']}/")
    if not report["success"]:
        lines.append(f"next step: {report['next_step']}")
    return lines


def next_step(message: str, out: Path, end: str = "failed") -> str:
    """One line for the user after a run that did not retrieve the target: what to try, where to read."""
    logs = f"{out}/run/logs"
    if end == "node_died":
        return node_died_step(message, out)
    if end == "timeout":
        return (f"out of time (--timeout): the training is kept in {out}/run/qtree.ckpt and the same command "
                "resumes it; add --timeout N for more time")
    if end == "interrupted":
        return f"the same command resumes the training from its checkpoint ({out}/run/qtree.ckpt)"
    if end == "error":
        return f"read the error above and the nodes' logs in {logs}; see docs/reliability.md"
    return failed_step(message, out)


def node_died_step(message: str, out: Path) -> str:
    """The next step after a node died for good (message: which and when)."""
    ckpt = f"{out}/run/qtree.ckpt"
    if "jaco2_sim_driver" in message:
        return (f"the driver died: its log is {out}/run/logs/jaco2_sim_driver.log; on a real arm check where it "
                f"stopped and what it holds before moving it; then run the same command (a fresh simulated world; "
                f"the training resumes from {ckpt})")
    if "task_planner" in message or "task planner died during the execution" in message:  # the demo's words
        return (f"the task planner died during the execution (its log: {out}/run/logs/task_planner.log); run the "
                f"same command: the training resumes from {ckpt}, the execution starts on a fresh simulated shelf")
    return (f"a node kept dying (max_respawns in config/graph.yaml): read its log in {out}/run/logs, then run the "
            f"same command (the training resumes from {ckpt})")


def failed_step(message: str, out: Path) -> str:
    """The next step after the retrieval failed with a reason (the task planner's message)."""
    if "did not find a sequence" in message:
        return ("the Q-Tree stopped before reaching the target: rerun with --execute-optimum (the proven optimum), "
                "or raise max_episodes in config/task_planner.yaml; see docs/qtree.md")
    if "safety net" in message:
        return ("the motion planner ran out of time planning (its wall-clock safety net, carry_timeout in "
                "config/motion_planner.yaml) on a loaded machine: run again when it is quieter, or raise "
                "carry_timeout; see docs/closed_loop.md")
    if message.startswith("the target cannot be retrieved"):
        return ("no relocation sequence frees the target on this shelf (the reason above, from the exact solver); "
                "move the bottles named there by hand or check the layout; see docs/motion_planner.md")
    if "of headroom; a grasp from above needs" in message or " leans: " in message:
        return ("a bottle lies on the top shelf where the hand cannot take it (too little headroom under the board "
                "above for the grasp from above, or leaning): stand it up by hand, then run the demo again; see "
                "docs/closed_loop.md")
    if "cannot be reached" in message or "no sequence remains" in message:
        return "no collision-free way to the target remains on this shelf: see docs/closed_loop.md"
    if "went away" in message:
        return (f"the motion planner stopped answering during a relocation and did not come back (its log: "
                f"{out}/run/logs); run again, or raise relocate_silence in config/task_planner.yaml on a loaded "
                "machine")
    if "off the shelf" in message:
        return "the target fell off the shelf: it cannot be retrieved; run the demo again (a fresh scene)"
    if "does not see the target" in message:
        return ("the target may lie on its side or have fallen (/perception/debug_image shows the shelf): stand it "
                f"up by hand and run the demo again; otherwise check the camera and perception (logs in "
                f"{out}/run/logs); see docs/perception.md")
    if "scene" in message:
        return f"check the camera and perception (logs in {out}/run/logs); see docs/perception.md"
    return f"read the task planner's and the motion planner's logs in {out}/run/logs; see docs/closed_loop.md"


def timeout_hint(message: str, checkpoint: Path) -> str:
    """What to do when the goal had no result within --timeout (scenario3_15 with perception at load 7: "[demo]
    error: no result within 900 s" and nothing else): the node graph stops, and the task planner keeps its training
    in the checkpoint, which the same command resumes."""
    if not message.startswith("no result within"):
        return ""
    return (f" (--timeout). Training so far is kept in {checkpoint}: the same command resumes it; add --timeout N "
            "for more time (a 15-bottle scene trains for 700-1200 s on 2 cores)")


def learning_curve(history, path: Path, title: str) -> None:
    """learning_curve.png: the normalised Eq. 15 sum per episode (nothing without episodes)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    h = np.asarray(history, float)
    if h.size == 0:
        return
    fig, ax = plt.subplots(figsize=(7, 3.5))
    ax.plot(np.arange(1, len(h) + 1), h / (np.abs(h).max() or 1.0))
    ax.set_xlabel("episode")
    ax.set_ylabel("normalised sum of edge values (Eq. 15)")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def strip(frames, path: Path, cols: int = 6) -> None:
    """retrieval_strip.png: up to two rows of camera frames of the execution (nothing without frames)."""
    import cv2
    if not frames:
        return
    step = max(1, len(frames) // (cols * 2))
    frames = frames[::step][: cols * 2]
    rows = [frames[i:i + cols] for i in range(0, len(frames), cols)]
    rows[-1] = rows[-1] + [np.zeros_like(frames[0])] * (cols - len(rows[-1]))
    sheet = np.vstack([np.hstack(r) for r in rows])
    scale = min(1.0, 1800 / sheet.shape[1])
    sheet = cv2.resize(sheet, (int(sheet.shape[1] * scale), int(sheet.shape[0] * scale)))
    cv2.imwrite(str(path), cv2.cvtColor(sheet, cv2.COLOR_RGB2BGR))
