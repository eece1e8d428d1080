"""The main job: the paper's real experiment (Sect. 5.2) through the whole node graph.

Starts the four nodes as separate processes on a private ROS domain (relocation_app.graph), asks the
task planner to train H-eG with depth search against the motion planner's feasibility service and to execute
the learned sequence on the MuJoCo Jaco2, and writes under out/: report.json, learning_curve.png and
retrieval_strip.png (camera frames of the retrieval); unless --no-record, also the run as a rosbag2 bag (MCAP) in
out/bag/ and the retrieval as out/retrieval.mp4 (relocation_app.recording).

Execution is closed-loop (docs/closed_loop.md: a check after every relocation, re-plans) unless --open-loop;
--disturb K applies K seeded disturbances (the driver's disturbance_plan, drawn with --seed) and report.json lists
them (`disturbances`) with the re-plans (`replans`); `success` is true only with the target on the bottom shelf.

A node that dies is respawned as config/graph.yaml says (docs/reliability.md, "A node that dies"): perception and
the motion planner come back and the run goes on; the task planner comes back and, during the training, the goal is
sent again (the training resumes from its checkpoint); during the execution the demo waits until the motion
planner's relocation in flight has ended (the arm home), then sends the goal again: the new task planner starts
from the world as it is (qtree_task_planner.executive.resume: the relocations done before it, the top shelf's
problem, trained afresh) and report.json's `resumed` says what was done before. The driver is not
respawned: its death stops the run (the arm's state is unknown). However the run ends, report.json is written and
the exit code says how it ended (relocation_app.run_report).
"""
from __future__ import annotations

import argparse
import json
import os
import signal
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from qtree_task_planner.learning.params import POLICIES, SEARCHES, TrainingParams
from qtree_task_planner.ros_clients import GOAL_STATUS, MOTION_WAIT, SCENE_NONE
from relocation_app import run_report
from relocation_app.client import ClientError, RelocationClient
from relocation_app.final_state import final_state
from relocation_app.graph import Graph, NodeDied
from relocation_app.progress import Progress
from relocation_app.run_report import End
from relocation_common.feasibility import default_replicas
from relocation_common.paths import default_scenario, resolve_scenario

TRAINING = ("exact optimum", "training", "waiting for planner", MOTION_WAIT)  # the feedback phases before the execution
SETTLE_WAIT = 200.0  # s the demo waits for the motion planner's relocation in flight when the task planner died
RESTART_WAIT = 120.0  # s for a respawned task planner to say it is up (its /diagnostics status with its new pid)
DISCOVERY_SETTLE = 3.0  # s after that before the goal is sent again
GOAL_RESPONSE_WAIT = 15.0  # s for the respawned task planner's goal response before the goal is sent once more


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


class _Latest:
    """Keeps the last message of a topic and when it came."""

    def __init__(self):
        self.msg, self.at = None, None

    def __call__(self, msg) -> None:
        self.msg, self.at = msg, time.monotonic()

    def positions(self) -> dict:
        if self.msg is None:
            return {}
        from relocation_common.ros_conversions import msg_to_objects  # base centres, as the report has them
        return {o.id: [float(v) for v in o.base()] for o in msg_to_objects(self.msg, require_target=False)}


class _Watch:
    """What the demo watches of the running graph, on the client's node: the execution so far (latched, after each
    step), the disturbances, ground truth, the scene, the joint states, the object being relocated, the motion
    planner's relocate goals (action status), the nodes' /diagnostics, the training feedback's phase."""

    def __init__(self, node, scene_topic: str) -> None:
        from action_msgs.msg import GoalStatusArray
        from diagnostic_msgs.msg import DiagnosticArray
        from qtree_relocation_msgs.msg import ObjectArray
        from rclpy.qos import QoSDurabilityPolicy, QoSProfile
        from sensor_msgs.msg import Image, JointState
        from std_msgs.msg import String

        latched = QoSProfile(depth=1, durability=QoSDurabilityPolicy.TRANSIENT_LOCAL)
        self.scene_topic = scene_topic
        self.execution, self.truth, self.scene, self.joints, self.status = (_Latest() for _ in range(5))
        self.rec = _Recorder()
        self.disturbances: list[dict[str, Any]] = []  # /sim/disturbances, as they come
        self.relocating: list[str] = []  # /task_planner/relocating, as they come
        self.pids: dict[str, str] = {}  # /diagnostics status name -> the pid it last gave
        self.phase, self.executing = "", False
        self.planner_scene = SCENE_NONE  # the task planner's latest scene, as its /diagnostics say (goal_health)
        self.before: dict[str, Any] = {}  # the ground truth when the execution started
        self.resumed: list[dict[str, Any]] = []  # each goal sent again after a task planner died in the execution
        node.create_subscription(String, "/task_planner/execution", self.execution, latched)
        node.create_subscription(String, "/sim/disturbances", lambda m: self.disturbances.append(json.loads(m.data)),
                                 QoSProfile(depth=100, durability=QoSDurabilityPolicy.TRANSIENT_LOCAL))
        node.create_subscription(Image, "/camera/color/image_raw", self.rec, 2)
        node.create_subscription(ObjectArray, "/sim/objects", self.truth, latched)
        node.create_subscription(ObjectArray, scene_topic, self.scene, latched)
        node.create_subscription(JointState, "/j2s7s300_driver/out/joint_state", self.joints, 10)
        node.create_subscription(String, "/task_planner/relocating", lambda m: self.relocating.append(m.data), latched)
        node.create_subscription(GoalStatusArray, "/motion_planner/relocate/_action/status", self.status, latched)
        node.create_subscription(DiagnosticArray, "/diagnostics", self._on_health, 50)

    def _on_health(self, msg) -> None:
        for st in msg.status:
            self.pids[st.name] = next((kv.value for kv in st.values if kv.key == "pid"), "")
            if st.name == GOAL_STATUS:
                self.planner_scene = next((kv.value for kv in st.values if kv.key == "scene"), SCENE_NONE)

    def on_feedback(self, phase: str) -> None:
        self.phase = phase
        if phase not in TRAINING:
            self.executing = self.rec.active = True

    def relocation_in_flight(self) -> bool:
        """The motion planner runs a relocate goal (accepted, executing or canceling)."""
        return self.status.msg is not None and any(st.status in (1, 2, 3) for st in self.status.msg.status_list)

    def run(self) -> dict:
        """The execution so far (the task planner's ~/execution), {} before any."""
        return json.loads(self.execution.msg.data) if self.execution.msg is not None else {}


def _start_graph(g: Graph, a, scene_topic: str) -> None:
    """The four nodes (perception only with --scene-source perception); the Q-Tree checkpointed in the run
    directory, so a training stopped by a signal or a time limit is resumed by the same command; the motion
    planner's relocation journal there too, emptied first (a fresh simulated world: a respawned planner reads it)."""
    common = {"scenario": a.scenario}
    ckpt = _checkpoint(g.run_dir / "qtree.ckpt")
    journal = g.run_dir / "motion_planner.journal"
    journal.unlink(missing_ok=True)
    print(f"[demo] starting the node graph on ROS_DOMAIN_ID={g.domain_id} (logs: {g.run_dir / 'logs'})")
    plan = _disturbance_plan(a)
    driver = dict(common, camera_model=a.camera_model) if a.camera_model else dict(common)
    g.start("jaco2_sim_driver", dict(driver, disturbance_plan=f"'{plan.to_json()}'") if plan else driver)
    if a.scene_source == "perception":  # it reads the arm's joint states where config/arm_interface.yaml says
        g.start("perception", dict(common))
    g.start_planners(a.replicas, dict(common, scene_topic=scene_topic, journal_path=str(journal)))
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


def _progress_bar(w: _Watch):
    """Progress fed by TrainPlanner feedback (relocation_app.progress: a bar on a terminal, a line every few seconds
    in a log): episodes, Eq. 15 sum, tree size, MP_q, planner calls."""
    bar = Progress("training", "ep")

    def on_feedback(f) -> None:
        w.on_feedback(f.phase)
        if f.phase not in TRAINING:  # executing, checks, re-plans
            bar.update(desc=f.phase if len(f.phase) < 100 else f.phase[:97] + "...")
            return
        bar.update(f.episode, desc="exact optimum" if f.phase == "exact optimum" else "training",
                   postfix=f"q_sum={f.q_sum:.1f} nodes={f.tree_nodes} mp_q={f.mp_queries} calls={f.planner_calls}")

    return bar, on_feedback


class _TaskPlannerLost(Exception):
    """The task planner died (and is respawned): its goal is gone."""


def _watching(g: Graph, seen: int):
    """A check for the client's waits: the graph's (a node gone for good raises NodeDied), and the task planner's
    death since event `seen` (_TaskPlannerLost)."""
    def check() -> None:
        g.check_alive()
        for e in g.events[seen:]:
            if e["node"] == "task_planner" and e["event"] == "died":
                raise _TaskPlannerLost(f"exit {e['code']}")
    return check


def _lost_in_execution(g: Graph, w: _Watch, why: str, t: float) -> None:
    """The task planner died during the execution: what it had done is noted (`w.resumed`, report.json's
    `resumed`), the motion planner's relocation in flight is waited for (`_settle`: it goes on to its end, the arm
    home, and no second motion may start meanwhile), then the goal is sent again as for a death in training; the new
    task planner starts from the world as it is (executive.resume)."""
    run, flight = w.run(), (w.relocating[-1] if w.relocation_in_flight() and w.relocating else None)
    print(f"[demo] the task planner died during the execution ({why}; phase: {w.phase}; relocated so far: "
          f"{' '.join(run.get('relocated', [])) or 'none'}) and is respawned"
          + (f"; waiting for the motion planner to end the relocation of {flight} in flight" if flight else ""))
    _settle(w, g)
    left = w.relocation_in_flight()
    w.resumed.append({"t": round(t, 1), "phase": w.phase, "relocated_before": list(run.get("relocated", [])),
                      "in_flight": flight, "in_flight_ended": not left, "steps_before": run.get("steps", []),
                      "replans_before": run.get("replans", []), "sequence_before": run.get("sequence", [])})
    if left:
        raise TimeoutError(f"the motion planner's relocation of {flight} did not end within {SETTLE_WAIT:g} s "
                           "after the task planner died: not sending the goal again while the arm moves")
    print("[demo] sending the goal again: the respawned task planner re-plans from the world as it is "
          "(the relocations done, the top shelf as perceived now)")
    w.executing = w.rec.active = False
    w.planner_scene = SCENE_NONE  # the new process's first scene (its /diagnostics) before the goal


def _restarted(g: Graph, w: _Watch) -> None:
    """Wait until the respawned task planner is up: its /diagnostics status comes from its new process and says it
    has a scene (after a death in the execution: `_lost_in_execution` forgot the old one); then
    DISCOVERY_SETTLE s more (its action's endpoints are matched after its diagnostics: a goal sent at once was
    lost, 'no goal response within 30 s')."""
    deadline = time.monotonic() + RESTART_WAIT
    while True:
        g.check_alive()
        p = g.procs.get("task_planner")
        if p is not None and w.pids.get(GOAL_STATUS) == str(p.pid) and w.planner_scene != SCENE_NONE:
            time.sleep(DISCOVERY_SETTLE)
            return
        if time.monotonic() > deadline:
            raise TimeoutError(f"the respawned task planner did not come up within {RESTART_WAIT:g} s")
        time.sleep(0.2)


def _send(client, on_feedback, check, goal: dict, again: bool) -> None:
    """Send the training goal; `again` (to a respawned task planner): a goal whose response does not come within
    GOAL_RESPONSE_WAIT s is sent once more (a request sent while discovery was still matching is lost)."""
    for attempt in range(2 if again else 1):
        try:
            client.train(on_feedback=on_feedback, check=check, timeout=GOAL_RESPONSE_WAIT if again else 30.0, **goal)
            return
        except ClientError as e:
            if not again or attempt == 1 or not str(e).startswith("no goal response"):
                raise
            print("[demo] no goal response from the respawned task planner: sending the goal once more")


def _train_and_watch(client, g: Graph, a, used, w: _Watch, t0: float) -> tuple[End | None, Any]:
    """Wait for the graph and a scene, train (and execute) through the client; (an End when the run ended
    otherwise than with the goal's result, the TrainPlanner result or None). A task planner that died during
    the training is waited for and the goal sent again (its checkpoint); during the execution too, once the motion
    planner's relocation in flight has ended (`_lost_in_execution`)."""
    client.wait_until_ready(120, check=g.check_alive)
    _wait_for(lambda: w.scene.msg is not None and len(w.scene.msg.objects) > 0, 90, g, f"no scene on {w.scene_topic}")
    # the task planner's own first scene: its discovery of the scene's publisher took longer than its scene_wait at a
    # load of 27, and a goal sent when the demo's subscription had one was refused "no scene received"
    _wait_for(lambda: w.planner_scene != SCENE_NONE, 90, g, f"the task planner received no scene on {w.scene_topic}")
    w.before = w.truth.positions()
    print(f"[demo] graph up in {time.monotonic() - t0:.1f} s; training {used.policy}/{used.search} "
          f"through the feasibility service")
    bar, on_feedback = _progress_bar(w)
    goal = dict(policy=used.policy, search=used.search, seed=used.seed, execute=not a.no_execute,
                execute_optimum=a.execute_optimum)
    deadline, again = time.monotonic() + a.timeout, False
    try:
        while True:
            check = _watching(g, len(g.events))
            _send(client, on_feedback, check, goal, again)
            try:
                outcome = client.wait(max(1.0, deadline - time.monotonic()), check=check)
                break
            except _TaskPlannerLost as e:
                client.abandon()
                if w.executing:
                    _lost_in_execution(g, w, str(e), time.monotonic() - t0)
                else:
                    print(f"[demo] the task planner died ({e}) and is respawned: sending the goal again (the "
                          "training resumes from its checkpoint)")
                _restarted(g, w)
                again = True
    except ClientError as e:
        if str(e).startswith("no result within"):
            return End("timeout", f"{e}{run_report.timeout_hint(str(e), g.run_dir / 'qtree.ckpt')}"), None
        raise
    finally:
        bar.close()
    if outcome.result is None:  # rejected: no Result to report
        return End("error", outcome.message), None
    return None, outcome.result


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


def _interrupted(signum: int) -> End:
    name = signal.Signals(signum).name
    return End("interrupted", f"stopped by {name}: the node graph was shut down", signum)


def _died(e: NodeDied, w: _Watch | None) -> End:
    """The End of a run whose node `e.name` died for good (the driver: the arm's state is unknown)."""
    flight = w.relocating[-1] if w is not None and w.relocation_in_flight() and w.relocating else None
    phase = (f" (phase: {w.phase or 'starting'}" + (f"; the motion planner relocating {flight}" if flight else "")
             + ")") if w is not None else ""
    if e.name == "jaco2_sim_driver":
        return End("node_died", f"the driver (jaco2_sim_driver) died with exit {e.code}{phase}: the arm's state is "
                                "unknown, so the run stopped safely (the goal cancelled, the arm not moved again)")
    return End("node_died", f"node {e.name} died with exit {e.code}{phase} and was not restarted (config/graph.yaml)")


def _settle(w: _Watch, g: Graph) -> None:
    """After the task planner's death: wait for the motion planner's relocation in flight to end (up to
    SETTLE_WAIT s), so the report says where it left the arm and the bottle."""
    deadline = time.monotonic() + SETTLE_WAIT
    while w.relocation_in_flight() and time.monotonic() < deadline and not g.dead():
        time.sleep(0.2)


def _final(w: _Watch | None, end: End | None, a) -> dict:
    """Where the run left things: the ground truth (last known), the robot (final_state), the interruption."""
    if w is None:
        return {"before": {}, "after": {}, "robot": {"unknown": True}, "age": None, "interrupted": None}
    time.sleep(1.0)  # the last bottle settles; ground truth at 10 Hz
    robot = final_state(w.joints.msg, w.truth.msg)
    if end is not None and "jaco2_sim_driver" in end.message:
        robot = {**robot, "arm_home": None, "gripper_empty": None, "unknown": True,
                 "note": "the driver died: the last joint state is from before its death"}
    age = time.monotonic() - w.truth.at if w.truth.at is not None else None
    interrupted = None
    if end is not None and end.kind != "failed":
        flight = w.relocating[-1] if w.relocation_in_flight() and w.relocating else None
        what = (f"relocating {flight}" if flight else f"phase {w.phase or 'start-up'}") + f" ({end.kind})"
        interrupted = {"phase": w.phase, "relocating": flight, "what": what}
    return {"before": w.before, "after": w.truth.positions(), "robot": robot, "age": age,
            "interrupted": interrupted}


def run(argv=None) -> int:
    """The demo (module docstring): report.json however the run ends; the exit code (run_report.END)."""
    a = _args(argv)
    a.scenario = str(resolve_scenario(a.scenario).resolve())  # the nodes run in the output directory
    used = TrainingParams.defaults().replace(policy=a.policy, search=a.search, seed=a.seed)
    out = Path(a.out).resolve()
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.monotonic()
    scene_topic = "/scene/objects" if a.scene_source == "perception" else "/sim/objects"
    end: End | None = End("error", "the node graph did not start")
    res, w, events, recording, final = None, None, [], None, None
    try:
        with Graph(out / "run", respawn=True) as g:
            events = g.events
            _start_graph(g, a, scene_topic)
            os.environ.update(g.env)
            rec = _start_recording(g, a, out)
            client = RelocationClient("qtree_demo")  # its own context, no signal handlers: the signals are ours
            try:
                w = _Watch(client.node, scene_topic)
                end, res = _train_and_watch(client, g, a, used, w, t0)
            except _Interrupted as e:
                end = _interrupted(e.signum)
            except NodeDied as e:
                end = _died(e, w)
            except (RuntimeError, TimeoutError, ClientError) as e:
                end = End("error", str(e))
            finally:
                with _signals_held():
                    if w is not None and end is not None and "task_planner" in end.message:
                        _settle(w, g)
                    final = _final(w, end, a)
                    client.close()
                    recording = _stop_recording(rec)  # also on an error or a signal: the bag so far is valid
    except _Interrupted as e:
        end = _interrupted(e.signum)
    except (RuntimeError, ValueError) as e:  # the graph could not start (a node's arm interface, no domain)
        end = End("error", str(e))
    with _signals_held():
        return _report(out, a, used, res, end, final, w, events, time.monotonic() - t0, recording)


def _report(out: Path, a, used, res, end: End | None, final: dict | None, w: _Watch | None, events: list,
            wall: float, recording: dict | None) -> int:
    """report.json (run_report), the plots and the summary lines; the exit status."""
    final = final or _final(None, end, a)
    run = w.run() if w is not None else {}
    executed = run.get("sequence") or ([] if res is None else list(res.optimal_sequence if a.execute_optimum
                                                                      else res.sequence))
    fs = {**run_report.check_scene(a.scenario, final["before"], final["after"],
                                   [] if a.no_execute else run.get("relocated", executed)), **final["robot"]}
    if end is None:  # the goal's result
        ok = bool(res.success and (a.no_execute or fs["target_on_bottom_shelf"]))
        message = res.message if ok or not res.success else \
            f"{res.message}; but the simulator does not show the target on the bottom shelf"
        n = len(w.resumed) if w is not None else 0
        again = f" (the task planner was respawned during the execution {n} time{'s' * (n > 1)}: the goal sent " \
            "again and re-planned from the world as it was)" if n else ""
        end = End("success" if ok else "failed", message + again)
    report = {"scenario": a.scenario, "policy": used.policy, "search": used.search, "seed": used.seed,
              "success": end.kind == "success", "message": end.message, "out": str(out),
              "end": {"kind": end.kind, "exit_code": end.exit_code},
              "next_step": "" if end.kind == "success" else run_report.next_step(end.message, out, end.kind),
              **run_report.training_fields(res), "wall_time_s": round(wall, 1),
              "executed": "optimum" if res is not None and executed == list(res.optimal_sequence)
              and executed != list(res.sequence) else "learned", "executed_sequence": executed,
              "closed_loop": not a.open_loop, "done": {"relocated": run.get("relocated", []),
                                                       "running": bool(run.get("running"))},
              "interrupted": final["interrupted"], "respawns": list(events),
              "resumed": list(w.resumed) if w is not None else [],
              "last_known": run_report.where(a.scenario, final["after"], final["age"], fs.get("at_hand", [])),
              "disturbances": list(w.disturbances) if w is not None else [], "replans": run.get("replans", []),
              "pushes": run.get("pushes", []), "steps": run.get("steps", []), "final_scene": fs, "recording": recording}
    run_report.write(out, report)
    if res is not None:
        run_report.learning_curve(res.q_sum_history, out / "learning_curve.png", f"{used.policy} / {used.search}")
    run_report.strip(w.rec.frames if w is not None else [], out / "retrieval_strip.png")
    for line in run_report.summary(report):
        print(f"[demo] {line}")
    return end.exit_code


class _Interrupted(Exception):
    """SIGINT or SIGTERM: the run stops, the report is still written."""

    def __init__(self, signum: int) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


_HELD: list[int] = []  # signals that came while the report was being written


def _interrupt(signum, frame):
    """SIGTERM (timeout, systemd, docker stop) and Ctrl-C stop the graph; a second one while the run is being
    wound up and reported is noted, not raised (the report is written in seconds)."""
    if _HELD and _HELD[0] < 0:
        _HELD.append(signum)
        return
    raise _Interrupted(signum)


class _signals_held:
    """Inside: SIGINT and SIGTERM are noted, not raised (winding up and writing the report)."""

    def __enter__(self):
        _HELD[:] = [-1]

    def __exit__(self, *exc):
        _HELD.clear()
        return False


def _wait_for(predicate, timeout: float, graph: Graph, what: str) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        graph.check_alive()
        if time.monotonic() > deadline:
            raise TimeoutError(f"{what} after {timeout:.0f} s")
        time.sleep(0.05)


def main(argv=None) -> None:
    """Console entry point: `run`, with SIGTERM and Ctrl-C winding the run up (report.json written); the exit code
    says how the run ended (run_report.END)."""
    signal.signal(signal.SIGTERM, _interrupt)
    signal.signal(signal.SIGINT, _interrupt)
    sys.exit(run(argv))


if __name__ == "__main__":
    main()
