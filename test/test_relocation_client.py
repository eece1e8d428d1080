"""RelocationClient against a small fake graph in this process: a feasibility service and the two actions served
by a node in a private Context, on a reserved ROS domain. The fake TrainPlanner server acts by the goal's `policy`:
"succeed", "abort", "reject" (refused at the goal request) or "wait" (runs until canceled). Covered: the four
statuses with their messages, feedback (latest and callback), and what the with-block shuts down (its node, its
own context, a goal still in flight; never rclpy's global context nor a context given to it)."""
import threading
import time

import pytest
import rclpy
from qtree_relocation_msgs.action import RelocateObject, TrainPlanner
from qtree_relocation_msgs.srv import PlanFeasibility
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import ReentrantCallbackGroup
from ros_procs import reserve_domain_id

from relocation_app.client import FEASIBILITY, RELOCATE, TRAIN, ClientError, RelocationClient, TaskResult
from relocation_common.feasibility import Label
from relocation_common.node import SideNode


class FakeGraph:
    """The servers the client talks to, in their own Context; `canceled` lists the goals canceled (by policy)."""

    def __init__(self, domain: int):
        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=domain)
        self.side = SideNode("fake_graph", context=self.context, threads=4)
        node, group = self.side.node, ReentrantCallbackGroup()
        self.canceled: list[str] = []
        node.create_service(PlanFeasibility, FEASIBILITY, self._feasibility, callback_group=group)
        self._servers = [
            ActionServer(node, TrainPlanner, TRAIN, execute_callback=self._train, callback_group=group,
                         goal_callback=lambda g: GoalResponse.REJECT if g.policy == "reject" else GoalResponse.ACCEPT,
                         cancel_callback=lambda _: CancelResponse.ACCEPT),
            ActionServer(node, RelocateObject, RELOCATE, execute_callback=self._relocate, callback_group=group)]

    @staticmethod
    def _feasibility(req, res):
        res.ok = req.object_id != "bad"
        res.label, res.message = PlanFeasibility.Response.TARGET, "" if res.ok else "unknown object 'bad'"
        return res

    def _train(self, goal_handle):
        policy = goal_handle.request.policy
        deadline = time.monotonic() + 5.0  # the client's feedback subscription matched: no feedback lost
        while self.side.node.count_subscribers(f"{TRAIN}/_action/feedback") < 1 and time.monotonic() < deadline:
            time.sleep(0.02)
        for episode in (1, 2, 3):
            goal_handle.publish_feedback(TrainPlanner.Feedback(episode=episode, phase="training"))
        while policy == "wait" and not goal_handle.is_cancel_requested:
            time.sleep(0.02)
        if policy == "wait":
            self.canceled.append(policy)
            goal_handle.canceled()
            return TrainPlanner.Result(message="training canceled after 3 episodes")
        if policy == "abort":
            goal_handle.abort()
            return TrainPlanner.Result(success=False, message="no scene on /scene/objects")
        goal_handle.succeed()
        return TrainPlanner.Result(success=True, message="learned o1", sequence=["o1"], episodes=3)

    @staticmethod
    def _relocate(goal_handle):
        goal_handle.succeed()
        return RelocateObject.Result(success=True, message="")

    def node_names(self) -> list[str]:
        return self.side.node.get_node_names()

    def close(self) -> None:
        self.side.close()
        rclpy.shutdown(context=self.context)


@pytest.fixture(scope="module")
def graph():
    domain, lock = reserve_domain_id()
    g = FakeGraph(domain)
    g.domain = domain
    try:
        yield g
    finally:
        g.close()
        lock.unlink(missing_ok=True)


@pytest.fixture
def client(graph):
    with RelocationClient("client_under_test", domain_id=graph.domain) as c:
        c.wait_until_ready(timeout=20)
        yield c


def _until(predicate, timeout: float = 5.0) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        assert time.monotonic() < deadline, "condition not met in time"
        time.sleep(0.02)


def test_a_succeeded_goal_with_its_feedback_and_result(client):
    label, res = client.plan_feasibility("o1")
    assert label == Label.TARGET and res.ok
    with pytest.raises(ClientError, match="feasibility request refused: unknown object 'bad'"):
        client.plan_feasibility("bad")
    episodes: list[int] = []
    assert client.train(policy="succeed", on_feedback=lambda f: episodes.append(f.episode))
    result = client.wait(10)
    assert result.status is TaskResult.SUCCEEDED and result.succeeded
    assert result.message == "learned o1" and list(result.result.sequence) == ["o1"]
    _until(lambda: client.feedback() is not None and client.feedback().episode == 3)
    assert episodes == [1, 2, 3]
    assert client.is_done() and client.result() == result


def test_an_aborted_goal_says_why(client):
    assert client.train(policy="abort")
    result = client.wait(10)
    assert result.status is TaskResult.ABORTED and not result.succeeded
    assert result.message == "no scene on /scene/objects" and result.result.success is False


def test_a_rejected_goal_is_a_status_not_an_exception(client):
    assert client.train(policy="reject") is False
    assert client.is_done()
    result = client.wait(1)
    assert result.status is TaskResult.REJECTED and result.result is None
    assert result.message.startswith(f"{TRAIN}: goal rejected")
    assert client.relocate("o1") and client.wait(10).status is TaskResult.SUCCEEDED  # the next goal goes through


def test_a_canceled_goal(client):
    assert client.train(policy="wait")
    _until(lambda: client.feedback() is not None)
    assert not client.is_done() and client.result() is None
    assert client.cancel()
    result = client.wait(10)
    assert result.status is TaskResult.CANCELED and result.message == "training canceled after 3 episodes"
    assert client.cancel() is False  # nothing in flight


def test_the_with_block_shuts_down_what_it_started(graph):
    global_ok = rclpy.ok()
    canceled = len(graph.canceled)
    with RelocationClient("client_in_a_block", domain_id=graph.domain) as c:
        c.wait_until_ready(timeout=20)
        _until(lambda: "client_in_a_block" in graph.node_names())
        assert c.train(policy="wait")
        _until(lambda: c.feedback() is not None)
    assert not c.context.ok()  # its own context, shut down
    assert len(graph.canceled) == canceled + 1  # the goal left in flight was canceled
    assert not any(t.name == "client_in_a_block" for t in threading.enumerate())  # no spin thread left
    _until(lambda: "client_in_a_block" not in graph.node_names())  # the node is gone from the graph
    assert rclpy.ok() == global_ok  # rclpy's global context: neither initialised nor shut down
    c.close()  # twice: nothing happens


def test_a_context_given_is_used_and_left_running(graph):
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=graph.domain)
    try:
        with RelocationClient("client_on_my_context", context=ctx) as c:
            assert c.node.context is ctx
            c.wait_until_ready(timeout=20)
            assert c.relocate("o1") and c.wait(10).succeeded
        assert ctx.ok()
    finally:
        rclpy.shutdown(context=ctx)
    with pytest.raises(ValueError, match="domain_id"):
        RelocationClient(context=ctx, domain_id=graph.domain)
