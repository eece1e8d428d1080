"""rclpy#1123 in the Jazzy wheels: an ActionClient spun by another thread drops a response that arrives before
send_goal_async (or get_result_async) has registered its request, and the future never completes. A fresh-clone CI
run hit it ("goal response never came", "Ignoring unexpected goal response"). The window is widened here as the
reproduction of rclpy#1123 does: the client's handle sleeps right after sending. relocation_common.node.ActionClient
(every action client of the project) completes; rclpy's own is shown to lose the response."""
import threading
import time

import pytest

pytest.importorskip("rclpy")
import rclpy
from qtree_relocation_msgs.action import RelocateObject
from rclpy.action import ActionClient as RclpyActionClient
from rclpy.action import ActionServer
from rclpy.executors import MultiThreadedExecutor
from ros_procs import reserve_domain_id

from relocation_common.node import ActionClient


class _SlowHandle:
    """The client's rcl handle, sleeping after each request is sent (before rclpy registers it)."""

    def __init__(self, handle, delay: float):
        self._h, self._delay = handle, delay

    def __getattr__(self, name):
        attr = getattr(self._h, name)
        if name in ("send_goal_request", "send_result_request", "send_cancel_request"):
            def slow(*args):
                n = attr(*args)
                time.sleep(self._delay)
                return n
            return slow
        return attr

    def __enter__(self):
        return self._h.__enter__()

    def __exit__(self, *exc):
        return self._h.__exit__(*exc)


def _round_trip(client_class) -> tuple[bool, bool]:
    """(goal response came, result came) for one goal to a server that answers at once."""
    domain, lock = reserve_domain_id()
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=domain)
    ex = None
    try:
        node = rclpy.create_node("race_probe", context=ctx, start_parameter_services=False)
        name = f"/race_probe_{client_class.__module__.replace('.', '_')}"

        def execute(gh):
            gh.succeed()
            return RelocateObject.Result(success=True, message="done")
        ActionServer(node, RelocateObject, name, execute_callback=execute)
        client = client_class(node, RelocateObject, name)
        ex = MultiThreadedExecutor(num_threads=2, context=ctx)
        ex.add_node(node)
        spin = threading.Thread(target=ex.spin, daemon=True)
        spin.start()
        assert client.wait_for_server(timeout_sec=10)
        client._client_handle = _SlowHandle(client._client_handle, 0.3)
        got = threading.Event()
        fut = client.send_goal_async(RelocateObject.Goal(object_id="o1"))
        fut.add_done_callback(lambda _: got.set())
        if not got.wait(5):
            return False, False
        res = threading.Event()
        fut.result().get_result_async().add_done_callback(lambda _: res.set())
        return True, res.wait(5)
    finally:
        if ex is not None:
            ex.shutdown(timeout_sec=1)
        rclpy.shutdown(context=ctx)
        lock.unlink(missing_ok=True)


def test_no_response_is_lost_when_the_server_answers_at_once():
    assert _round_trip(ActionClient) == (True, True)
    stock = _round_trip(RclpyActionClient)
    print(f"\nrclpy's ActionClient: goal response, result = {stock}")
    assert stock != (True, True), "rclpy fixed rclpy#1123: relocation_common.node.ActionClient can go"
