"""The main job: the paper's real experiment (Sect. 5.2) through the whole node graph.

Starts the four nodes as separate processes on a private ROS domain (relocation_app.graph), asks the
task planner to train H-eG with depth search against the motion planner's feasibility service and to execute
the learned sequence on the MuJoCo Jaco2, and writes under out/: report.json, learning_curve.png and
retrieval_strip.png (camera frames of the retrieval); unless --no-record, also the run as a rosbag2 bag (MCAP) in
out/bag/ and the retrieval as out/retrieval.mp4 (relocation_app.recording).

Execution is closed-loop (docs/closed_loop.md: a check after every relocation, re-plans) unless --open-loop;
--disturb K applies K seeded disturbances (the driver's disturbance_plan, drawn with --seed) and report.json lists
them (`disturbances`) with the re-plans (`replans`); `success` is true only with the target on the bottom shelf.
"""
from __future__ import annotations

import argparse
import json
import os
import signal
import sys
import time
from pathlib import Path

import numpy as np

from qtree_task_planner.learning.params import POLICIES, SEARCHES, TrainingParams
from relocation_app.client import ClientError, RelocationClient
from relocation_app.final_state import final_state
from relocation_app.graph import Graph
from relocation_app.progress import Progress
from relocation_common.feasibility import default_replicas
from relocation_common.paths import default_scenario, resolve_scenario


def _args(argv):
    p = argparse.ArgumentParser(prog="qtree demo", description=__doc__.splitlines()[0])
    p.add_argument("--scenario", default=str(default_scenario()),
                   help="scenario YAML, or a name under config/scenarios (default: the paper's experiment)")
    p.add_argument("--scene-source", choices=("perception", "ground_truth"), default="perception")
    p.add_argument("--policy", choices=POLICIES, help="default: config/task_planner.yaml")
    p.add_argument("--search", choices=SEARCHES, help="default: config/task_planner.yaml")
    p.add_argument("--seed", type=int, help="default: config/task_planner.yaml")
    p.add_argument("--no-execute", action="store_true", help="train only, do not move the robot")
    p.add_argument("--execute-optimum", action="store_true",
                   help="relocate the exact optimum (blocker A*) instead of the Q-Tree's learned sequence")
    p.add_argument("--execute-learned", action="store_true",
                   help="relocate the learned sequence even when it weighs more than the exact optimum")
    p.add_argument("--replan-q-tree", action="store_true",
                   help="each re-plan also trains the Q-Tree on the remaining problem (default: the exact A* alone)")
    p.add_argument("--open-loop", action="store_true",
                   help="the paper's open-loop execution: no check of the scene between relocations, no re-plan")
    p.add_argument("--disturb", type=int, default=0, metavar="K",
                   help="K seeded disturbances (nudge, tip, move, drop; seed: --seed) during the execution")
    p.add_argument("--replicas", type=int, default=default_replicas(), choices=range(1, 9), metavar="N",
                   help="motion planner processes answering feasibility (1-8; the first also moves the arm; default: "
                   f"one per core, {default_replicas()} here)")
    p.add_argument("--camera-model", choices=("ideal", "realsense_d435"),
                   help="the simulated camera (driver parameter camera_model; default: config/jaco2_sim_driver.yaml)")
    p.add_argument("--out", default="out", help="output directory (default: ./out)")
    p.add_argument("--timeout", type=float, default=1800.0,
                   help="give up after this many seconds (training is kept: the same command resumes it)")
    p.add_argument("--no-record", action="store_true",
                   help="no rosbag2 bag (out/bag/) and no video (out/retrieval.mp4) of the run")
    return p.parse_args(argv)


class _Recorder:
    """Keeps a camera frame every `period` seconds while the robot executes."""

    def __init__(self, period: float = 1.5):
        self.period, self.last, self.active = period, 0.0, False
        self.frames: list[np.ndarray] = []

    def __call__(self, msg) -> None:
        now = time.monotonic()
        if not self.active or now - self.last < self.period:
            return
        self.last = now
        img = np.frombuffer(bytes(msg.data), np.uint8).reshape(msg.height, msg.width, -1)[:, :, :3]
        self.frames.append(img.copy())


def _strip(frames, path: Path, cols: int = 6) -> None:
    import cv2
    if not frames:
        return
    step = max(1, len(frames) // (cols * 2))
    frames = frames[::step][: cols * 2]
    h, w = frames[0].shape[:2]
    rows = [frames[i:i + cols] for i in range(0, len(frames), cols)]
    rows[-1] = rows[-1] + [np.zeros_like(frames[0])] * (cols - len(rows[-1]))
    sheet = np.vstack([np.hstack(r) for r in rows])
    scale = min(1.0, 1800 / sheet.shape[1])
    sheet = cv2.resize(sheet, (int(sheet.shape[1] * scale), int(sheet.shape[0] * scale)))
    cv2.imwrite(str(path), cv2.cvtColor(sheet, cv2.COLOR_RGB2BGR))


def _learning_curve(history, path: Path, title: str) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(7, 3.5))
    h = np.asarray(history, float)
    if h.size == 0:
        plt.close(fig)
        return
    ax.plot(np.arange(1, len(h) + 1), h / (np.abs(h).max() or 1.0))
    ax.set_xlabel("episode")
    ax.set_ylabel("normalised sum of edge values (Eq. 15)")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def _interrupt(signum, frame):
    raise KeyboardInterrupt  # SIGTERM (timeout, systemd, docker stop) stops the graph like Ctrl-C


def _start_graph(g: Graph, a, scene_topic: str) -> None:
    """The four nodes (perception only with --scene-source perception); the Q-Tree checkpointed in the run
    directory, so a training stopped by a signal or a time limit is resumed by the same command."""
    common = {"scenario": a.scenario}
    ckpt = _checkpoint(g.run_dir / "qtree.ckpt")
    print(f"[demo] starting the node graph on ROS_DOMAIN_ID={g.domain_id} (logs: {g.run_dir / 'logs'})")
    plan = _disturbance_plan(a)
    driver = dict(common, camera_model=a.camera_model) if a.camera_model else dict(common)
    g.start("jaco2_sim_driver", dict(driver, disturbance_plan=f"'{plan.to_json()}'") if plan else driver)
    if a.scene_source == "perception":
        g.start("perception", common)
    g.start_planners(a.replicas, dict(common, scene_topic=scene_topic))
    g.start("task_planner", dict(common, scene_topic=scene_topic, checkpoint_path=str(ckpt), replicas=a.replicas,
                                 closed_loop=not a.open_loop, execute_learned=a.execute_learned,
                                 replan_q_tree=a.replan_q_tree))


def _disturbance_plan(a):
    """--disturb K: K disturbances drawn with --seed (default 0) at moments of the first two relocations (the
    sequence is not known before training; every retrieval with an obstacle has two), or None."""
    if a.disturb <= 0:
        return None
    from jaco2_sim_driver.disturbance import DisturbancePlan
    return DisturbancePlan.draw(a.disturb, a.seed or 0, relocations=2)


def _checkpoint(path: Path) -> Path:
    """The demo's checkpoint: an unfinished one (stopped by a signal or the time limit) is resumed by the task
    planner; a finished or unreadable one is removed, so a rerun trains afresh."""
    from qtree_task_planner.learning.checkpoint import CheckpointError, load_checkpoint

    if path.exists():
        try:
            ck = load_checkpoint(path)
            if ck.reason != "final":  # periodic, cancelled (a signal), interrupted (planner lost)
                print(f"[demo] resuming the training stopped at episode {ck.episode} ({path})")
                return path
        except (CheckpointError, OSError, ValueError):
            pass
        path.unlink()
    return path


def _progress_bar(rec: "_Recorder"):
    """Progress fed by TrainPlanner feedback (relocation_app.progress: a bar on a terminal, a line every few seconds
    in a log): episodes, Eq. 15 sum, tree size, MP_q, planner calls."""
    bar = Progress("training", "ep")

    def on_feedback(f) -> None:
        if f.phase not in ("exact optimum", "training", "waiting for planner"):  # executing, checks, re-plans
            rec.active = True
            bar.update(desc=f.phase if len(f.phase) < 100 else f.phase[:97] + "...")
            return
        bar.update(f.episode, desc="exact optimum" if f.phase == "exact optimum" else "training",
                   postfix=f"q_sum={f.q_sum:.1f} nodes={f.tree_nodes} mp_q={f.mp_queries} calls={f.planner_calls}")

    return bar, on_feedback


def _train_and_watch(client, g: Graph, a, used, scene_topic: str, t0: float):
    """Wait for the graph and a scene, train (and execute) through the client; (result, before, after, frames)."""
    from qtree_relocation_msgs.msg import ObjectArray
    from rclpy.qos import QoSDurabilityPolicy, QoSProfile
    from sensor_msgs.msg import Image, JointState
    from std_msgs.msg import String

    latched = QoSProfile(depth=1, durability=QoSDurabilityPolicy.TRANSIENT_LOCAL)
    execution, disturbances = _Latest(), []
    client.node.create_subscription(String, "/task_planner/execution", execution, latched)
    client.node.create_subscription(String, "/sim/disturbances", lambda m: disturbances.append(json.loads(m.data)),
                                    QoSProfile(depth=100, durability=QoSDurabilityPolicy.TRANSIENT_LOCAL))
    client.wait_until_ready(120, check=g.check_alive)
    rec, truth, scene = _Recorder(), _Latest(), _Latest()
    client.node.create_subscription(Image, "/camera/color/image_raw", rec, 2)
    client.node.create_subscription(ObjectArray, "/sim/objects", truth, latched)
    client.node.create_subscription(ObjectArray, scene_topic, scene, latched)
    joints = _Latest()
    client.node.create_subscription(JointState, "/j2s7s300_driver/out/joint_state", joints, 10)
    _wait_for(lambda: scene.msg is not None and len(scene.msg.objects) > 0, 90, g, f"no scene on {scene_topic}")
    before = truth.positions()
    print(f"[demo] graph up in {time.monotonic() - t0:.1f} s; training {used.policy}/{used.search} "
          f"through the feasibility service")
    bar, on_feedback = _progress_bar(rec)
    try:
        client.train(on_feedback=on_feedback, check=g.check_alive, policy=used.policy, search=used.search,
                     seed=used.seed, execute=not a.no_execute, execute_optimum=a.execute_optimum)
        outcome = client.wait(a.timeout, check=g.check_alive)
    except ClientError as e:
        raise ClientError(f"{e}{_timeout_hint(str(e), g.run_dir / 'qtree.ckpt')}") from None
    finally:
        bar.close()
    if outcome.result is None:  # rejected: no Result to report
        raise ClientError(outcome.message)
    res = outcome.result
    time.sleep(1.0)  # the last bottle settles; ground truth at 10 Hz
    run = json.loads(execution.msg.data) if execution.msg is not None else {}
    return res, before, truth.positions(), rec.frames, {**run, "disturbances": list(disturbances),
                                                        "robot": final_state(joints.msg, truth.msg)}


def _start_recording(g: Graph, a, out: Path):
    """The bag of the whole run and the video of the retrieval (from the first 'executing' feedback)."""
    if a.no_record:
        return None
    from relocation_app.recording import RunRecorder
    return RunRecorder(out / "bag", video=out / "retrieval.mp4", domain_id=g.domain_id,
                       video_from_phase=None if a.no_execute else "executing").start()


def _stop_recording(rec) -> dict | None:
    if rec is None:
        return None
    s = rec.stop()
    b, v = s["bag"], s["video"]
    print(f"[demo] bag: {b['path']} ({b['messages']} messages on {len(b['topics'])} topics, "
          f"{b['bytes'] / 1e6:.1f} MB, {b['duration_s']:.0f} s)")
    if v and v["path"]:
        print(f"[demo] video: {v['path']} ({v['frames']} frames at {v['fps']:g} fps, {v['duration_s']:.1f} s)")
    return s


def _report(out: Path, a, used, res, before, after, frames, wall: float, run: dict,
            recording: dict | None = None) -> int:
    """report.json, learning_curve.png, retrieval_strip.png and the summary lines; the exit status. Success only
    with the target on the bottom shelf (when executed); no sentinel values: what is missing is said in words."""
    executed = run.get("sequence") or list(res.optimal_sequence if a.execute_optimum else res.sequence)
    fs = {**_check_scene(a.scenario, before, after, [] if a.no_execute else run.get("relocated", executed)),
          **run.get("robot", {})}  # arm_home, gripper_empty (relocation_app.final_state)
    success = bool(res.success and (a.no_execute or fs["target_on_bottom_shelf"]))
    learned_w = res.total_weight if res.sequence else None
    optimal_w = res.optimal_weight if res.optimal_sequence else None
    report = {
        "scenario": a.scenario, "policy": used.policy, "search": used.search, "seed": used.seed,
        "success": success, "message": res.message,
        "learned_sequence": list(res.sequence), "learned_weight": learned_w,
        "optimal_sequence": list(res.optimal_sequence), "optimal_weight": optimal_w,
        "episodes": res.episodes, "E_ss": res.e_ss, "MP_q": res.mp_q,
        "E_1st": res.e_first if res.e_first >= 0 and res.episodes else None,
        "planner_calls": res.planner_calls, "wall_time_s": round(wall, 1),
        "q_sum_history": list(res.q_sum_history),
        "executed": "optimum" if executed == list(res.optimal_sequence) and executed != list(res.sequence) else
        "learned", "executed_sequence": executed, "closed_loop": not a.open_loop,
        "disturbances": run.get("disturbances", []), "replans": run.get("replans", []), "steps": run.get("steps", []),
        "final_scene": fs, "recording": recording,
    }
    (out / "report.json").write_text(json.dumps(report, indent=2))
    _learning_curve(res.q_sum_history, out / "learning_curve.png", f"{used.policy} / {used.search}")
    _strip(frames, out / "retrieval_strip.png")
    if not a.no_execute:
        print(f"[demo] target on the bottom shelf: {fs['target_on_bottom_shelf']}; largest displacement of a "
              f"bottle not relocated: {fs['max_displacement_untouched_m'] * 100:.1f} cm; arm home: "
              f"{fs.get('arm_home')}; gripper empty: {fs.get('gripper_empty')}")
    print("[demo] learned sequence: " + (f"{' -> '.join(res.sequence)}  weight {learned_w:.2f}" if learned_w
                                         is not None else "none (training found no sequence to the target)"))
    print("[demo] exact optimum:    " + (f"{' -> '.join(res.optimal_sequence)}  weight {optimal_w:.2f}" if
                                         optimal_w is not None else "none (no feasible sequence)"))
    e_first = str(res.e_first) if res.e_first >= 0 and res.episodes else "not reached"
    print(f"[demo] E_ss={res.e_ss} MP_q={res.mp_q} E_1st={e_first} real planner calls={res.planner_calls}"
          if res.episodes else "[demo] training did not run an episode")
    for d in report["disturbances"]:
        print(f"[demo] disturbance {d.get('when', '')}: {d.get('kind', 'command')} {d.get('object', '')}"
              + (f" skipped: {d['skipped']}" if "skipped" in d else ""))
    for r in report["replans"]:
        print(f"[demo] re-plan: {r['reason']} -> " + (f"{' '.join(r['sequence'])} ({r['weight']:.2f})"
                                                      if r.get("sequence") else r.get("failure", ""))
              + (f"; {r['note']}" if r.get("note") else ""))
    message = res.message if success or not res.success else \
        f"{res.message}; but the simulator does not show the target on the bottom shelf"
    print(f"[demo] {'SUCCESS' if success else 'FAILED'}: {message}  ({wall:.0f} s); outputs in {out}/")
    if not success:
        print(f"[demo] next step: {_next_step(message, out)}")
    return 0 if success else 1


def _next_step(message: str, out: Path) -> str:
    """One line for the user after a failure: what to try, where to read."""
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
    if "on its side" in message:
        return ("a bottle lies on its side on the top shelf (the side grasp takes standing bottles only): stand it "
                "up by hand, then run the demo again; see docs/closed_loop.md")
    if "cannot be reached" in message or "no sequence remains" in message:
        return "no collision-free way to the target remains on this shelf: see docs/closed_loop.md"
    if "went away" in message:
        return (f"the motion planner stopped answering during a relocation (its log: {out}/run/logs); run again, or "
                "raise relocate_silence in config/task_planner.yaml on a loaded machine")
    if "off the shelf" in message:
        return "the target fell off the shelf: it cannot be retrieved; run the demo again (a fresh scene)"
    if "does not see the target" in message:
        return ("the target may lie on its side or have fallen (/perception/debug_image shows the shelf): stand it "
                f"up by hand and run the demo again; otherwise check the camera and perception (logs in "
                f"{out}/run/logs); see docs/perception.md")
    if "scene" in message:
        return f"check the camera and perception (logs in {out}/run/logs); see docs/perception.md"
    return f"read the task planner's and the motion planner's logs in {out}/run/logs; see docs/closed_loop.md"


def run(argv=None) -> int:
    """The demo (module docstring) for `argv`; 0 when the target was retrieved, else 1."""
    a = _args(argv)
    a.scenario = str(resolve_scenario(a.scenario).resolve())  # the nodes run in the output directory
    used = TrainingParams.defaults().replace(policy=a.policy, search=a.search, seed=a.seed)
    out = Path(a.out).resolve()
    out.mkdir(parents=True, exist_ok=True)

    t0 = time.monotonic()
    scene_topic = "/scene/objects" if a.scene_source == "perception" else "/sim/objects"
    with Graph(out / "run") as g:
        _start_graph(g, a, scene_topic)
        os.environ.update(g.env)
        rec = _start_recording(g, a, out)
        client = RelocationClient("qtree_demo")  # its own context, no signal handlers: the signals are ours
        try:
            res, before, after, frames, run = _train_and_watch(client, g, a, used, scene_topic, t0)
        finally:
            client.close()
            recording = _stop_recording(rec)  # also on an error or Ctrl-C: the bag so far is a valid bag
    return _report(out, a, used, res, before, after, frames, time.monotonic() - t0, run, recording)


class _Latest:
    """Keeps the last message of a topic."""

    def __init__(self):
        self.msg = None

    def __call__(self, msg) -> None:
        self.msg = msg

    def positions(self) -> dict:
        if self.msg is None:
            return {}
        from relocation_common.ros_conversions import msg_to_objects  # base centres, as the report has them
        return {o.id: [float(v) for v in o.base()] for o in msg_to_objects(self.msg, require_target=False)}


def _check_scene(scenario_path: str, before: dict, after: dict, relocated) -> dict:
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


def _timeout_hint(message: str, checkpoint: Path) -> str:
    """What to do when the goal had no result within --timeout (scenario3_15 with perception at load 7: "[demo]
    error: no result within 900 s" and nothing else): the node graph stops, and the task planner keeps its training
    in the checkpoint, which the same command resumes."""
    if not message.startswith("no result within"):
        return ""
    return (f" (--timeout). Training so far is kept in {checkpoint}: the same command resumes it; add --timeout N "
            "for more time (a 15-bottle scene trains for 700-1200 s on 2 cores)")


def _wait_for(predicate, timeout: float, graph: Graph, what: str) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        graph.check_alive()
        if time.monotonic() > deadline:
            raise TimeoutError(f"{what} after {timeout:.0f} s")
        time.sleep(0.05)


def main(argv=None) -> None:
    """Console entry point: `run`, with SIGTERM and Ctrl-C shutting the graph down and errors on one line."""
    signal.signal(signal.SIGTERM, _interrupt)
    try:
        sys.exit(run(argv))
    except KeyboardInterrupt:
        print("\n[demo] interrupted; the node graph was shut down", file=sys.stderr)
        sys.exit(130)
    except (RuntimeError, TimeoutError, ClientError) as e:
        print(f"[demo] error: {e}", file=sys.stderr)
        sys.exit(1)


if __name__ == "__main__":
    main()
