"""main() of every node: spin a node on a multi-threaded executor and exit 0 on SIGINT or SIGTERM.

rclpy turns both signals into a shutdown of the context; spin then raises KeyboardInterrupt or
ExternalShutdownException (or RCLError "context is invalid" when the signal lands mid-call), all of which
are a clean exit here. Anything else is re-raised while rclpy is still ok.
"""
from __future__ import annotations

import rclpy
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor


def run_node(node_factory, args=None, threads: int = 4) -> None:
    rclpy.init(args=args)
    node = None
    executor = MultiThreadedExecutor(num_threads=threads)
    try:
        node = node_factory()
        executor.add_node(node)
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except Exception:
        if rclpy.ok():
            raise
    finally:
        executor.shutdown(timeout_sec=1.0)
        if node is not None:
            close = getattr(node, "close", None)
            if close is not None:
                close()
            node.destroy_node()
        rclpy.try_shutdown()
