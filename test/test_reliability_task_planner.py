"""Task planner reliability over real DDS (docs/reliability.md): a feasibility service that dies mid-training (the task
planner notices, keeps what it learned, waits, resumes; or aborts saying what to do and a restarted task planner resumes
from the checkpoint on disk), corrupt or mismatched checkpoints, stale or empty or bad scenes, bad goals.

The motion planner is played by a fake PlanFeasibility service in its own process (this file run as a script:
a BlockingOracle behind the service, optionally SIGKILLing itself when a given request arrives). Results are
compared with the core's uninterrupted training with the same seed."""
import argparse
import json
import os
import signal
import threading
import time
from pathlib import Path

import pytest
from ros_procs import REPO, NodeProcess, RosGraph, main_in_process

from qtree_task_planner.learning.params import TrainingParams
from qtree_task_planner.learning.training import train
from qtree_task_planner.oracles import BlockingOracle, CachedOracle
from qtree_task_planner.search import astar
from relocation_common.scenario import load_scenario

SCENARIO = REPO / "config" / "scenarios" / "blocking_10.yaml"
PARAMS_FILE = REPO / "config" / "task_planner.yaml"
MODULE = "qtree_task_planner.task_planner_node"
SEED = 4
SCENE_TOPIC = "/test/objects"


# ---------------------------------------------------------------------------------------------------------------
# the fake motion planner (this file run as a script)
def _serve(scenario: str, die_after: int, delay: float = 0.0, relocate: str = "none") -> None:
    """`delay` s before each answer; `relocate`: none (no action server), hang (accepts and never finishes)."""
    import rclpy
    from qtree_relocation_msgs.action import RelocateObject
    from qtree_relocation_msgs.srv import PlanFeasibility
    from rclpy.action import ActionServer, CancelResponse
    from rclpy.callback_groups import ReentrantCallbackGroup
    from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor

    from relocation_common.ros_conversions import blockers_to_msgs

    sc = load_scenario(scenario)
    oracle = BlockingOracle(sc)
    rclpy.init()
    node = rclpy.create_node("fake_motion_planner")
    answered = [0]

    def feasibility(req, resp):
        if req.object_id not in sc.ids:  # also the task planner's all_lanes question: this fake has no lanes
            resp.ok, resp.message = False, f"unknown object id {req.object_id!r}"
            return resp
        if 0 <= die_after <= answered[0]:
            print(f"dying with request {req.object_id} unanswered", flush=True)
            os.kill(os.getpid(), signal.SIGKILL)
        answered[0] += 1
        time.sleep(delay)
        print(f"Q {req.object_id} {','.join(req.removed_ids)}", flush=True)
        ans = oracle.feasibility(req.object_id, frozenset(req.removed_ids))
        resp.ok, resp.label, resp.blockers = True, int(ans.label), blockers_to_msgs(ans.blockers)  # as the planner
        return resp

    node.create_service(PlanFeasibility, "/motion_planner/plan_feasibility", feasibility)
    if relocate == "hang":
        def execute(handle):
            print(f"relocating {handle.request.object_id}", flush=True)
            while rclpy.ok() and not handle.is_cancel_requested:  # moving: feedback at 2 Hz, as a real one does
                handle.publish_feedback(RelocateObject.Feedback(phase="carry", progress=0.5))
                time.sleep(0.5)
            handle.canceled()
            return RelocateObject.Result(success=False, message="cancelled")

        ActionServer(node, RelocateObject, "/motion_planner/relocate", execute_callback=execute,
                     cancel_callback=lambda _: CancelResponse.ACCEPT, callback_group=ReentrantCallbackGroup())
    print("ready", flush=True)
    executor = MultiThreadedExecutor(4)
    executor.add_node(node)
    try:
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        rclpy.try_shutdown()


if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("--scenario", default=str(SCENARIO))
    ap.add_argument("--die-after", type=int, default=-1)
    ap.add_argument("--delay", type=float, default=0.0)
    ap.add_argument("--relocate", choices=("none", "hang"), default="none")
    a = ap.parse_args()
    _serve(a.scenario, a.die_after, a.delay, a.relocate)
    raise SystemExit(0)


# ---------------------------------------------------------------------------------------------------------------
pytestmark = pytest.mark.graph
# The test side's ROS imports, below the fake planner the subprocesses run (`__main__` above):
rclpy = pytest.importorskip("rclpy")
from qtree_relocation_msgs.action import TrainPlanner  # noqa: E402 -- after the fake planner's script part
from qtree_relocation_msgs.msg import ObjectArray  # noqa: E402 -- after the fake planner's script part
from rclpy.qos import DurabilityPolicy, QoSProfile  # noqa: E402 -- after the fake planner's script part

from qtree_task_planner.ros_clients import train_goal  # noqa: E402 -- after the fake planner's script part
from relocation_common.node import ActionClient  # noqa: E402 -- after the script part; has the rclpy#1123 fix
from relocation_common.ros_conversions import objects_to_msg  # noqa: E402 -- after the fake planner's script part

LATCHED = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
SC10 = load_scenario(SCENARIO)


@pytest.fixture(scope="module")
def reference():
    """The core's uninterrupted run: exact optimum then training, one shared cache (as the node does)."""
    params = TrainingParams.defaults().replace(seed=SEED)
    cache = CachedOracle(BlockingOracle(SC10))
    best = astar.solve(SC10, cache)
    r = train(SC10, cache, params, optimal_weight=best.total_weight)
    assert r.found and cache.calls > 300
    return r, best, len(cache.table)


class Env:
    def __init__(self, g: RosGraph):
        self.g, self.fakes = g, []
        self.scene_pub = g.probe.publisher(ObjectArray, SCENE_TOPIC, LATCHED)
        self.client = ActionClient(g.probe.node, TrainPlanner, "/task_planner/train")

    def task_planner(self, **params):
        base = {"scene_topic": SCENE_TOPIC, "feasibility_timeout": 1.0, "feasibility_margin": 0.5,
                "checkpoint_every": 25, "scenario": str(SCENARIO),  # its shelf and slots: closed-loop execution
                "reuse_answers": False}  # a plain cache, as the reference: every distinct question asked once
        return self.g.start(MODULE, params_file=PARAMS_FILE, params={**base, **params}, name="task_planner")

    def fake(self, die_after=-1, delay=0.0, relocate="none") -> NodeProcess:
        log = self.g.tmp / f"fake_{len(self.fakes)}.log"
        p = NodeProcess([self.g.python, __file__, "--die-after", str(die_after), "--delay", str(delay), "--relocate",
                         relocate], self.g.env, log)
        self.g.procs.append(p)
        self.fakes.append(p)
        _wait(lambda: "ready" in p.log(), 30, "fake planner never ready", p)
        return p

    def scene(self, msg=None):
        try:  # transient local reaches late joiners too; publishing after the match is just quicker to arrive
            self.g.probe.wait_for_subscribers(self.scene_pub, 1, timeout=10.0)
        except TimeoutError:
            pass
        self.scene_pub.publish(msg if msg is not None else objects_to_msg(SC10.objects))

    def goal(self, node: NodeProcess, timeout=120.0, **fields):
        """Send a TrainPlanner goal; returns (result or None if rejected, feedback list)."""
        _wait(lambda: self.client.wait_for_server(timeout_sec=0.2), 30, "train action never appeared", node)
        goal = train_goal(**{"seed": SEED, "execute": False, **fields})
        feedback = []
        handle = _result(self.client.send_goal_async(goal, feedback_callback=lambda f: feedback.append(f.feedback)),
                         30, node)
        if not handle.accepted:
            return None, feedback
        return _result(handle.get_result_async(), timeout, node).result, feedback

    def queries(self) -> list[str]:
        return [ln for p in self.fakes for ln in p.log().splitlines() if ln.startswith("Q ")]


def _wait(pred, timeout, what, proc=None):
    deadline = time.monotonic() + timeout
    while not pred():
        if proc is not None and not proc.alive() and not pred():
            raise AssertionError(f"{what}: process exited {proc.popen.returncode}\n{proc.log()[-3000:]}")
        if time.monotonic() > deadline:
            raise AssertionError(f"{what} within {timeout} s" + (f"\n{proc.log()[-3000:]}" if proc else ""))
        time.sleep(0.05)


def _result(fut, timeout, proc):
    done = threading.Event()
    fut.add_done_callback(lambda _: done.set())
    _wait(done.is_set, timeout, "no answer from the task planner", proc)
    return fut.result()


def _payload(path) -> dict:
    try:
        return json.loads(Path(path).read_text())["payload"]
    except (OSError, ValueError, KeyError):
        return {}


def _same_as_reference(res, reference):
    r, best, distinct = reference
    assert res.success, res.message
    assert tuple(res.sequence) == r.sequence and res.total_weight == pytest.approx(r.total_weight)
    assert (res.episodes, res.e_ss, res.mp_q, res.e_first) == (r.episodes, r.e_ss, r.mp_q, r.e_1st)
    assert list(res.q_sum_history) == r.q_sum_history  # bit for bit: the same training
    assert tuple(res.optimal_sequence) == best.sequence
    assert res.planner_calls == distinct


@pytest.fixture
def env(tmp_path):
    with RosGraph(tmp_path) as g:
        yield Env(g)


def test_planner_killed_mid_training_then_back_resumes_exactly(env, reference, tmp_path):
    ck = tmp_path / "qtree.ckpt"
    first = env.fake(die_after=200)
    tp = env.task_planner(checkpoint_path=str(ck), planner_wait=60.0)
    env.scene()  # answers 200 questions (82 for the exact optimum), then is SIGKILLed
    box = {}

    def run():
        try:
            box["res"], box["fb"] = env.goal(tp)
        except BaseException as e:  # reported by the main thread
            box["error"] = e

    t = threading.Thread(target=run, daemon=True)
    t.start()
    _wait(lambda: not first.alive(), 60, "fake planner did not die", tp)
    t_dead = time.monotonic()
    assert first.popen.returncode == -signal.SIGKILL
    # noticed within feasibility_timeout + margin (1.5 s): the interrupted episode's checkpoint holds all 200 answers
    _wait(lambda: len(_payload(ck).get("feasibility", ())) == 200, 30, "no checkpoint after the planner died", tp)
    print(f"\nplanner SIGKILLed -> checkpoint of the interrupted episode on disk: {time.monotonic() - t_dead:.2f} s")
    saved = _payload(ck)
    assert saved["reason"].startswith("interrupted") and saved["episode"] > 0
    # the log line may reach the log file after the checkpoint reached the disk (once in a full run)
    _wait(lambda: "motion planner lost" in tp.log(), 10, "the loss was not logged", tp)
    time.sleep(0.5)
    assert t.is_alive() and tp.alive()  # waiting, not aborted
    env.fake()
    t.join(120)
    assert "error" not in box, box["error"]
    res, fb = box["res"], box["fb"]
    _same_as_reference(res, reference)
    assert "waiting for planner" in {f.phase for f in fb}
    assert len(env.queries()) == reference[2]  # every question asked once: nothing learned was lost
    assert "is back: resuming" in tp.log()
    assert json.loads(ck.read_text())["payload"]["reason"] == "final"


@pytest.mark.slow
def test_planner_gone_aborts_with_advice_and_a_restarted_task_planner_resumes(env, reference, tmp_path):
    ck = tmp_path / "qtree.ckpt"
    env.fake(die_after=300)  # first, so that discovery has begun when the task planner starts
    tp = env.task_planner(checkpoint_path=str(ck), planner_wait=4.0)  # covers a slow first discovery too
    env.scene()
    res, _ = env.goal(tp)
    assert not res.success
    for words in ("planner_wait", str(ck), "Start (or restart) the motion_planner node", "send the same goal again"):
        assert words in res.message, res.message
    assert tp.alive()
    saved = _payload(ck)
    assert saved["reason"].startswith("interrupted") and len(saved["feasibility"]) == 300 and saved["episode"] > 0
    assert tp.stop(signal.SIGINT) == 0
    # a new task planner process, the planner back: the same goal resumes from the file
    env.fake()
    tp2 = env.task_planner(checkpoint_path=str(ck), planner_wait=4.0)
    res, _ = env.goal(tp2)
    _same_as_reference(res, reference)
    assert f"resuming from checkpoint {ck}: episode {saved['episode']}" in tp2.log()
    assert len(env.queries()) == reference[2]
    # another goal (other seed) meets the finished checkpoint: refused with the reason, the node keeps serving
    res, _ = env.goal(tp2, seed=SEED + 1)
    assert not res.success and "other training parameters" in res.message and "seed" in res.message
    # a corrupt checkpoint: refused, never silently reset
    ck.write_bytes(ck.read_bytes()[:-40])
    res, _ = env.goal(tp2)
    assert not res.success and "corrupt" in res.message and str(ck) in res.message
    assert ck.exists() and tp2.alive()


def test_no_planner_at_all_aborts_after_planner_wait(env):
    tp = env.task_planner(planner_wait=1.0)
    env.scene()
    res, _ = env.goal(tp)
    assert not res.success and "planner_wait" in res.message and "in memory" in res.message
    assert tp.alive()


# -- scene refusals ----------------------------------------------------------------------------------------------
def _scene(mutate=None, stamp=None):
    msg = objects_to_msg(SC10.objects, stamp=stamp)
    if mutate:
        mutate(msg)
    return msg


def _stamp_ago(seconds):
    from builtin_interfaces.msg import Time
    t = time.time() - seconds
    return Time(sec=int(t), nanosec=int((t % 1) * 1e9))


def test_stale_empty_or_bad_scenes_are_refused_and_the_node_keeps_serving(env):
    tp = env.task_planner(scene_max_age=1.0, planner_wait=10.0, scene_wait=0.2)
    cases = [
        (None, "no scene received"),
        (ObjectArray(), "empty"),
        (_scene(stamp=_stamp_ago(60.0)), "stale: stamped"),
        (_scene(lambda m: setattr(m.objects[1], "id", m.objects[0].id)), "duplicate id"),
        (_scene(lambda m: setattr(m.objects[2], "id", "")), "empty id"),
        (_scene(lambda m: setattr(m.objects[0].pose.position, "x", float("nan"))), "non-finite"),
        (_scene(lambda m: setattr(m.objects[0], "weight", float("inf"))), "non-finite"),
        (_scene(lambda m: [setattr(o, "is_target", False) for o in m.objects]), "exactly one target"),
    ]
    for msg, words in cases:
        if msg is not None:
            env.scene(msg)
            time.sleep(0.3)  # let it arrive (transient local, depth 1: the newest replaces the last)
        res, _ = env.goal(tp)
        assert res is not None and not res.success and words in res.message, (words, res and res.message)
    env.scene()
    time.sleep(1.3)  # older than scene_max_age by receive time
    res, _ = env.goal(tp)
    assert not res.success and "stale: received" in res.message, res.message
    assert env.queries() == []  # nothing reached a planner
    env.fake()
    from builtin_interfaces.msg import Time
    env.scene(_scene(stamp=Time(sec=100)))  # simulated time (a driver on use_sim_time): other clock, not stale
    time.sleep(0.3)
    res, _ = env.goal(tp, max_episodes=30)
    assert res.success or "did not find" in res.message, res.message
    assert res.episodes == 30 and tp.alive()


# -- bad goals and bad parameters ----------------------------------------------------------------------------------
BAD_GOALS = [{"alpha": 1.01}, {"gamma": 2.0}, {"gamma": float("inf")}, {"epsilon0": 0.0},
             {"epsilon_min": 0.9, "epsilon0": 0.5}, {"max_episodes": 0}, {"max_steps": 0}, {"quiet_episodes": 0},
             {"beta": float("nan")}, {"search": "sideways"}]


def test_out_of_range_goals_are_refused_with_the_reason_and_the_node_keeps_serving(env):
    """Accepted, then aborted with the reason naming the field (was: rejected, the reason only in the node's log)."""
    env.fake()
    tp = env.task_planner(planner_wait=10.0)
    env.scene()
    for fields in BAD_GOALS:
        res, _ = env.goal(tp, **fields)
        assert res is not None and not res.success and list(fields)[-1] in res.message, (fields, res)
    assert tp.alive()
    res, _ = env.goal(tp, max_episodes=5)
    assert res is not None and res.episodes == 5


BAD_STARTS = [
    (["-p", "alpha:=1.5"], "alpha must be in [0.0, 1.0]"),
    (["-p", "gamma:=abc"], "gamma"),
    (["-p", "max_episodes:=0"], "max_episodes must be >= 1"),
    (["-p", "checkpoint_every:=0"], "checkpoint_every"),
    (["-p", "planner_wait:=-1.0"], "planner_wait"),
    (["-p", "alhpa:=0.5"], "unknown parameter(s) alhpa"),
    (["-p", "scene_source:=camera"], "scene_source must be one of perception, sim"),
    (["--params-file", "MALFORMED"], "malformed YAML"),
    (["--params-file", "PARTIAL"], "expected '<node>: ros__parameters"),
    (["--params-file", "/nonexistent/task_planner.yaml"], "cannot read"),
]


def _bad_files(tmp_path) -> dict:
    (tmp_path / "malformed.yaml").write_text("task_planner:\n  ros__parameters:\n    alpha: [0.5\n")
    (tmp_path / "partial.yaml").write_text("task_planner:\n  alpha: 0.5\n")
    return {"MALFORMED": str(tmp_path / "malformed.yaml"), "PARTIAL": str(tmp_path / "partial.yaml")}


def test_bad_parameters_exit_2_with_one_line(tmp_path):
    """The first case as a process: status 2 and one line naming the problem, nothing else from its imports or rcl."""
    args, words = BAD_STARTS[0]
    with RosGraph(tmp_path) as g:
        p = g.start(MODULE, params_file=PARAMS_FILE, ros_args=tuple(args), name="bad")
        p.popen.wait(60)
        lines = [ln for ln in p.log().splitlines() if ln.strip()]
        assert p.popen.returncode == 2, (args, p.log())
        assert len(lines) == 1 and lines[0].startswith("task_planner: ") and words in lines[0], (args, lines)


@pytest.mark.parametrize("args, words", BAD_STARTS[1:], ids=[w for _, w in BAD_STARTS[1:]])
def test_the_other_bad_parameters_exit_2_with_one_line(args, words, tmp_path, capfd):
    """The node's main() in the test's process (ros_procs.main_in_process: the code after the imports)."""
    from qtree_task_planner.task_planner_node import main  # not at the top: this file is the fake planner's script
    subst = _bad_files(tmp_path)
    status, lines = main_in_process(main, ["--params-file", str(PARAMS_FILE), *(subst.get(a, a) for a in args)],
                                    capfd, tmp_path)
    assert status == 2, (args, lines)
    assert len(lines) == 1 and lines[0].startswith("task_planner: ") and words in lines[0], (args, lines)


# -- lifecycle (docs/reliability.md, section 9): nothing hangs ----------------------------------------------------
def _send_async(env, node, **fields):
    """Send a goal; returns (goal handle future, feedback list)."""
    _wait(lambda: env.client.wait_for_server(timeout_sec=0.2), 30, "train action never appeared", node)
    feedback = []
    fut = env.client.send_goal_async(train_goal(**{"seed": SEED, **fields}),
                                     feedback_callback=lambda f: feedback.append(f.feedback))
    return _result(fut, 30, node), feedback


def test_sigterm_while_executing_a_relocation_exits_at_once(env):
    """Old code: the execute callback sat in done.wait(relocate_timeout): exit after 177 s with a traceback."""
    fake = env.fake(relocate="hang")
    tp = env.task_planner(relocate_timeout=600.0)
    env.scene()
    handle, _ = _send_async(env, tp, execute=True, max_episodes=300)
    assert handle.accepted
    _wait(lambda: "relocating" in fake.log(), 120, "the relocation never started", tp)
    t0 = time.monotonic()
    code = tp.stop(signal.SIGTERM, timeout=30)
    took = time.monotonic() - t0
    print(f"\ntask planner exit on SIGTERM during a relocation: {took:.2f} s, status {code}")
    assert code == 0 and took < 10, tp.log()[-2000:]
    assert "Traceback" not in tp.log(), tp.log()[-3000:]


@pytest.mark.slow
def test_a_motion_planner_dying_mid_relocation_ends_the_goal(env):
    """Old code: the goal waited for relocate_timeout (180 s) for a result that never came."""
    fake = env.fake(relocate="hang")
    tp = env.task_planner(relocate_timeout=600.0, planner_wait=0.0)  # 0: no wait for a respawn (test_chaos_graph)
    env.scene()
    for _ in range(3):  # planner_wait 0 also means no wait at the goal's start: a fresh-clone run sent the goal
        # before the task planner had discovered the fake's service ("not available at the start of the goal")
        handle, _ = _send_async(env, tp, execute=True, max_episodes=300)
        result = handle.get_result_async()
        _wait(lambda: "relocating" in fake.log() or result.done(), 120, "the relocation never started", tp)
        if "relocating" in fake.log():
            break
        assert "is not available" in result.result().result.message, result.result().result.message
    t0 = time.monotonic()
    fake.send_signal(signal.SIGKILL)
    res = _result(result, 60, tp).result
    took = time.monotonic() - t0
    print(f"\ngoal ended {took:.1f} s after the motion planner died: {res.message}")
    # relocate_silence (10 s) to notice, then CANCEL_ACK_WAIT (3 s) for the cancel's acknowledgement (a starved
    # planner acknowledges and recovers; a dead one never does): far below relocate_timeout
    assert not res.success and "went away" in res.message and took < 15


def test_two_goals_back_to_back_one_is_rejected(env):
    """Old code: the busy check ran when execution started, so both goals were accepted and both trained."""
    env.fake()
    tp = env.task_planner()
    env.scene()
    _wait(lambda: env.client.wait_for_server(timeout_sec=0.2), 30, "train action never appeared", tp)
    futs = [env.client.send_goal_async(train_goal(seed=SEED, execute=False, max_episodes=50)) for _ in range(2)]
    handles = [_result(f, 30, tp) for f in futs]
    assert sorted(h.accepted for h in handles) == [False, True]
    done = next(h for h in handles if h.accepted)
    assert _result(done.get_result_async(), 120, tp).result.success


def test_cancel_during_the_exact_solve_ends_the_goal_with_progress_reported(env):
    """Old code: the exact solve (82 planner calls on this scene) sent no feedback and ignored cancel."""
    env.fake(delay=0.1)
    tp = env.task_planner()
    env.scene()
    handle, feedback = _send_async(env, tp, execute=False)
    _wait(lambda: any(f.phase == "exact optimum" for f in feedback), 30, "no feedback during the exact solve", tp)
    t0 = time.monotonic()
    _result(handle.cancel_goal_async(), 10, tp)
    res = _result(handle.get_result_async(), 30, tp).result
    took = time.monotonic() - t0
    calls = max(f.planner_calls for f in feedback if f.phase == "exact optimum")
    print(f"\ncancel during the exact solve: goal ended after {took:.2f} s ({calls} planner calls reported)")
    assert not res.success and "cancel" in res.message and took < 3


@pytest.mark.parametrize("where", ["fifo", "unwritable"])
def test_an_unusable_checkpoint_path_is_refused_at_start(env, tmp_path, where):
    """Old code: a FIFO blocked the goal forever (cancel and SIGINT ignored); an unwritable place was accepted and
    the abort claimed a checkpoint file that did not exist."""
    if where == "fifo":
        path = tmp_path / "ck.fifo"
        os.mkfifo(path)
    else:
        path = Path("/proc/qtree/ck.json")  # no file can be created there, not even by root
    tp = env.task_planner(checkpoint_path=str(path))
    _wait(lambda: not tp.alive(), 30, "the task planner kept running", None)
    assert tp.popen.returncode == 2
    assert "checkpoint_path" in tp.log() and "Traceback" not in tp.log()


def test_the_message_never_claims_a_checkpoint_that_was_not_written():
    """kept_where from what was really written (a full disk: the file holds an older episode than memory)."""
    from qtree_task_planner.executive.keeper import CheckpointKeeper

    k = CheckpointKeeper("/data/ck.json")
    k.memory = type("Ck", (), {"episode": 120})()
    k.written = (100, "No space left on device")
    said = k.kept_where()
    assert "checkpoint /data/ck.json at episode 100" in said and "in memory at episode 120" in said
    assert "No space left" in said
    k.written = None
    assert k.kept_where() == "in memory at episode 120"
