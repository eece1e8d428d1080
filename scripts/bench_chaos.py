"""Chaos benchmark: the demo with one node SIGKILLed at a seeded moment (docs/reliability.md, "A node that dies").

For every node (jaco2_sim_driver, perception, motion_planner, task_planner) x moment (training: during the Q-Tree's
training; carry: during the carry of relocation k; between: after relocation k ended, before the next) x seed, the
demo (`python -m relocation_app.demo`, the user's command, its own graph with respawn) runs on a fresh private
domain while this process watches the graph (its own rclpy node on that domain: the training and relocation
feedback, the simulator's ground truth and joint states) and SIGKILLs the node at the moment the seed draws
(random.Random(seed): the delay into the training, the relocation k and how far into its carry, the delay after
its end). Seeds are fixed before any result (--seeds, default 0-4). Per run: the demo's exit code, report.json
(written? its end, success), the target retrieved by this process's own ground truth (a report of success the
simulator does not confirm is a false success), the report truthful (an end other than success never claims the
target; a success only with the target seen on the bottom shelf), the arm home within 0.03 rad and the gripper
empty (its own last joint state and ground truth: not for a killed driver, whose world is gone), and orphan
processes (any `--ros-args` process left on the run's domain 5 s after the demo exited; killed and counted).
Each run is appended to --out (JSON lines) as it ends; a spec already there is not run again, so the same command
goes on where it stopped; the table is printed at the end (--table FILE: only the table).

    nice -n 5 .venv/bin/python scripts/bench_chaos.py --out /tmp/chaos.jsonl [--nodes perception motion_planner]
        [--moments training carry between] [--seeds 0 1 2 3 4] [--scenario scenario1_5]
    .venv/bin/python scripts/bench_chaos.py --table /tmp/chaos.jsonl
"""
from __future__ import annotations

import argparse
import json
import os
import random
import signal
import subprocess
import sys
import threading
import time
from dataclasses import asdict, dataclass
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # this checkout's packages first

from relocation_app.final_state import arm_home, bottles_at_hand  # noqa: E402  (after the sys.path insert)
from relocation_app.graph import reserve_domain_id  # noqa: E402  (after the sys.path insert)
from relocation_common.paths import resolve_scenario  # noqa: E402  (after the sys.path insert)
from relocation_common.scenario import load_scenario  # noqa: E402  (after the sys.path insert)

REPO = Path(__file__).resolve().parent.parent
NODES = {"jaco2_sim_driver": "jaco2_sim_driver.driver_node", "perception": "perception_aruco.perception_node",
         "motion_planner": "stpik_motion_planner.motion_planner_node",
         "task_planner": "qtree_task_planner.task_planner_node"}
MOMENTS = ("training", "carry", "between")
HOME_TOL = 0.03  # rad: the bound (final_state.arm_home with it)


@dataclass(frozen=True)
class Spec:
    """One run: the node killed, the moment, the seed; what the seed draws."""

    node: str
    moment: str
    seed: int

    def draw(self, relocations: int) -> dict:
        """The kill's parameters from the seed alone: training delay (s after the first training feedback), the
        relocation k (1-based) and the carry's progress (0.45..0.70 is the carry: relocation.PHASES), the delay
        after relocation k ended."""
        rng = random.Random(f"{self.node}/{self.moment}/{self.seed}")
        return {"delay": rng.uniform(1.0, 12.0), "k": rng.randint(1, max(1, relocations)),
                "progress": rng.uniform(0.47, 0.66), "after": rng.uniform(0.0, 1.5)}

    def key(self) -> str:
        return f"{self.node}/{self.moment}/{self.seed}"


class Watch:
    """This process's view of the run's graph (its own context on the run's domain)."""

    def __init__(self, domain: int) -> None:
        import rclpy
        from qtree_relocation_msgs.action import RelocateObject, TrainPlanner
        from qtree_relocation_msgs.msg import ObjectArray
        from rclpy.context import Context
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.qos import QoSDurabilityPolicy, QoSProfile
        from rclpy.signals import SignalHandlerOptions
        from sensor_msgs.msg import JointState

        self.context = Context()
        rclpy.init(context=self.context, domain_id=domain, signal_handler_options=SignalHandlerOptions.NO)
        self.node = rclpy.create_node("chaos_watch", context=self.context)
        latched = QoSProfile(depth=1, durability=QoSDurabilityPolicy.TRANSIENT_LOCAL)
        self.train_phase, self.training_since, self.goals, self.truth, self.joints = "", None, [], None, None
        self.node.create_subscription(TrainPlanner.Impl.FeedbackMessage, "/task_planner/train/_action/feedback",
                                      self._on_train, 10)
        self.node.create_subscription(RelocateObject.Impl.FeedbackMessage, "/motion_planner/relocate/_action/feedback",
                                      self._on_relocate, 50)
        self.node.create_subscription(ObjectArray, "/sim/objects", self._on_truth, latched)
        self.node.create_subscription(JointState, "/j2s7s300_driver/out/joint_state", self._on_joints, 10)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.thread = threading.Thread(target=self._spin, daemon=True)
        self.thread.start()

    def _spin(self) -> None:
        try:
            self.executor.spin()
        except Exception:
            pass

    def _on_train(self, m) -> None:
        self.train_phase = m.feedback.phase
        if self.training_since is None and m.feedback.phase == "training":
            self.training_since = time.monotonic()

    def _on_relocate(self, m) -> None:
        gid = bytes(m.goal_id.uuid)
        if not self.goals or self.goals[-1]["id"] != gid:
            if any(g["id"] == gid for g in self.goals):
                g = next(g for g in self.goals if g["id"] == gid)
            else:
                self.goals.append(g := {"id": gid, "phase": "", "progress": 0.0, "done_at": None})
        else:
            g = self.goals[-1]
        g["phase"], g["progress"] = m.feedback.phase, m.feedback.progress
        if m.feedback.phase == "done" and g["done_at"] is None:
            g["done_at"] = time.monotonic()

    def _on_truth(self, m) -> None:
        self.truth = (m, time.monotonic())

    def _on_joints(self, m) -> None:
        self.joints = (m, time.monotonic())

    def moment_reached(self, spec: Spec, p: dict) -> str | None:
        """What is happening when the moment `spec` draws has come (a line for the record), else None."""
        if spec.moment == "training":  # only while the Q-Tree trains: a delay past the training's end kills nothing
            if (self.training_since is not None and self.train_phase == "training"
                    and time.monotonic() - self.training_since >= p["delay"]):
                return f"training ({self.train_phase}) {p['delay']:.1f} s in"
            return None
        goals = self.goals
        if len(goals) < p["k"]:
            return None
        g = goals[p["k"] - 1]
        if spec.moment == "carry" and g["phase"] == "carry" and g["progress"] >= p["progress"]:
            return f"relocation {p['k']} carrying at progress {g['progress']:.2f}"
        if spec.moment == "between" and g["done_at"] is not None and time.monotonic() - g["done_at"] >= p["after"]:
            return f"{p['after']:.1f} s after relocation {p['k']} ended"
        return None

    def final(self, scenario) -> dict:
        """The target on the bottom shelf, the arm home (0.03 rad), the gripper empty: from this process's own
        last ground truth and joint state."""
        from relocation_common.ros_conversions import msg_to_objects
        if self.truth is None:
            return {"target_on_bottom": None, "arm_home": None, "gripper_empty": None}
        objects = {o.id: o for o in msg_to_objects(self.truth[0], require_target=False)}
        t = objects.get(scenario.target_id)
        sh = scenario.shelf
        on_bottom = t is not None and abs(float(t.base()[2]) - sh.bottom_z) < 0.02 and sh.x_front < t.x < sh.x_back
        out = {"target_on_bottom": bool(on_bottom), "arm_home": None, "gripper_empty": None}
        if self.joints is not None:
            names, pos = list(self.joints[0].name), list(self.joints[0].position)
            out["arm_home"] = arm_home(names, pos, HOME_TOL)
            out["gripper_empty"] = not bottles_at_hand(names, pos, {i: tuple(o.centre()) for i, o in objects.items()})
            q = dict(zip(names, pos))
            import numpy as np

            from relocation_common import robot_description as rd
            d = np.array([q.get(n, 0.0) for n in rd.JOINT_NAMES]) - rd.Q_HOME
            out["home_off_rad"] = round(float(np.max(np.abs((d + np.pi) % (2 * np.pi) - np.pi))), 4)
        return out

    def close(self) -> None:
        import rclpy
        self.executor.shutdown(timeout_sec=1.0)
        self.thread.join(timeout=3.0)
        rclpy.try_shutdown(context=self.context)


def node_pid(demo_pid: int, node: str) -> int | None:
    """The pid of `node` among the demo's children (the motion planner: not a replica)."""
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            ppid = int((d / "stat").read_text().rsplit(")", 1)[1].split()[1])
            cmd = (d / "cmdline").read_bytes().split(b"\0")
        except (OSError, IndexError, ValueError):
            continue
        if ppid == demo_pid and NODES[node].encode() in cmd and not any(c.startswith(b"__ns:=") for c in cmd):
            return int(d.name)
    return None


def on_domain(domain: int) -> list[int]:
    """Processes with `--ros-args` on their command line running on ROS_DOMAIN_ID `domain` (orphans after a run)."""
    out = []
    for d in Path("/proc").iterdir():
        if not d.name.isdigit() or int(d.name) == os.getpid():
            continue
        try:
            if b"--ros-args" in (d / "cmdline").read_bytes().split(b"\0") and \
                    f"ROS_DOMAIN_ID={domain}".encode() in (d / "environ").read_bytes().split(b"\0"):
                out.append(int(d.name))
        except OSError:
            continue
    return out


def one_run(spec: Spec, scenario: str, out_dir: Path, timeout: float, extra: list[str]) -> dict:
    """The demo with spec's node killed at spec's moment; the record (module docstring)."""
    sc = load_scenario(resolve_scenario(scenario))
    p = spec.draw(relocations=2)
    domain, lock = reserve_domain_id()
    run_dir = out_dir / spec.key().replace("/", "_")
    run_dir.mkdir(parents=True, exist_ok=True)
    (run_dir / "report.json").unlink(missing_ok=True)
    rec: dict = {**asdict(spec), "draw": p, "killed": None, "killed_during": None}
    watch = Watch(domain)
    t0 = time.monotonic()
    try:
        with open(run_dir / "demo.log", "w") as log:
            demo = subprocess.Popen([sys.executable, "-m", "relocation_app.demo", "--scenario", scenario, "--no-record",
                                     "--out", str(run_dir), *extra], cwd=REPO, stdout=log, stderr=subprocess.STDOUT,
                                    env=dict(os.environ, QTREE_DOMAIN_ID=str(domain)), start_new_session=True)
        while demo.poll() is None and time.monotonic() - t0 < timeout:
            if rec["killed"] is None:
                during = watch.moment_reached(spec, p)
                pid = node_pid(demo.pid, spec.node) if during else None
                if pid is not None:
                    os.kill(pid, signal.SIGKILL)
                    rec.update(killed=round(time.monotonic() - t0, 1), killed_during=during)
                    print(f"[chaos] {spec.key()}: SIGKILL {spec.node} (pid {pid}) at {rec['killed']} s: {during}",
                          flush=True)
            time.sleep(0.05)
        final = watch.final(sc)  # before the demo's graph is gone: its last ground truth and joint state
        if demo.poll() is None:
            demo.send_signal(signal.SIGTERM)
            rec["timed_out"] = True
            try:
                demo.wait(60)
            except subprocess.TimeoutExpired:
                demo.kill()
                demo.wait()
    finally:
        watch.close()
        time.sleep(5.0)
        orphans = on_domain(domain)
        for pid in orphans:
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        lock.unlink(missing_ok=True)
    report_path = run_dir / "report.json"
    report = json.loads(report_path.read_text()) if report_path.exists() else None
    rec.update(exit=demo.returncode, wall_s=round(time.monotonic() - t0, 1), orphans=len(orphans), **final,
               report=report is not None)
    if report is not None:
        rec.update(end=report["end"]["kind"], report_exit=report["end"]["exit_code"], success=report["success"],
                   message=report["message"][:300], respawns=sum(e["event"] == "respawned" for e in report["respawns"]),
                   deaths=[e["code"] for e in report["respawns"] if e["event"] == "died"],
                   next_step=report.get("next_step", "")[:200])
    rec["false_success"] = bool(report and report["success"] and not final["target_on_bottom"])
    rec["truthful"] = bool(report and report["end"]["exit_code"] == demo.returncode and
                           (report["success"] == bool(final["target_on_bottom"]) or not report["success"]) and
                           (report["end"]["kind"] != "success" or report["success"]))
    return rec


def table(rows: list[dict]) -> str:
    """The summary per node and moment, then the totals."""
    lines = ["| node | moment | runs | killed | retrieved | ended safely, truthful report | false successes | "
             "no report | orphans | arm home (0.03 rad) + gripper empty |", "|" + "---|" * 10]
    groups: dict[tuple[str, str], list[dict]] = {}
    for r in rows:
        groups.setdefault((r["node"], r["moment"]), []).append(r)
    for (node, moment), rs in sorted(groups.items(), key=lambda kv: (list(NODES).index(kv[0][0]),
                                                                     MOMENTS.index(kv[0][1]))):
        lines.append(_row(node, moment, rs))
    lines.append(_row("all", "", rows))
    return "\n".join(lines)


def _row(node: str, moment: str, rs: list[dict]) -> str:
    n = len(rs)
    killed = sum(r["killed"] is not None for r in rs)
    retrieved = sum(bool(r.get("success")) and bool(r.get("target_on_bottom")) for r in rs)
    safe = sum(r["truthful"] and not r.get("success") for r in rs)
    home = [r for r in rs if r["node"] != "jaco2_sim_driver"]
    ok_home = sum(bool(r.get("arm_home")) and bool(r.get("gripper_empty")) for r in home)
    return (f"| {node} | {moment} | {n} | {killed} | {retrieved} | {safe} | {sum(r['false_success'] for r in rs)} | "
            f"{sum(not r['report'] for r in rs)} | {sum(r['orphans'] for r in rs)} | "
            f"{ok_home}/{len(home)}" + (" (driver runs: n/a)" if len(home) < n else "") + " |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("/tmp/chaos.jsonl"))
    ap.add_argument("--nodes", nargs="+", default=list(NODES), choices=list(NODES))
    ap.add_argument("--moments", nargs="+", default=list(MOMENTS), choices=MOMENTS)
    ap.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2, 3, 4])
    ap.add_argument("--scenario", default="scenario1_5")
    ap.add_argument("--timeout", type=float, default=900.0, help="s per run before the demo is stopped")
    ap.add_argument("--table", type=Path, help="print the table of this JSON-lines file and exit")
    ap.add_argument("extra", nargs="*", help="after --: more demo options")
    a = ap.parse_args()
    if a.table:
        print(table([json.loads(x) for x in a.table.read_text().splitlines() if x.strip()]))
        return
    done = {json.loads(x)["node"] + "/" + json.loads(x)["moment"] + "/" + str(json.loads(x)["seed"])
            for x in a.out.read_text().splitlines() if x.strip()} if a.out.exists() else set()
    runs_dir = a.out.with_suffix("")
    for node in a.nodes:
        for moment in a.moments:
            for seed in a.seeds:
                spec = Spec(node, moment, seed)
                if spec.key() in done:
                    continue
                rec = one_run(spec, a.scenario, runs_dir, a.timeout, a.extra)
                print(f"[chaos] {spec.key()}: exit {rec['exit']}, end {rec.get('end')}, success {rec.get('success')}, "
                      f"target on the bottom shelf {rec['target_on_bottom']}, orphans {rec['orphans']}, "
                      f"{rec['wall_s']:.0f} s: {rec.get('message', 'no report')[:160]}", flush=True)
                with open(a.out, "a") as f:
                    f.write(json.dumps(rec) + "\n")
    print(table([json.loads(x) for x in a.out.read_text().splitlines() if x.strip()]))


if __name__ == "__main__":
    main()
