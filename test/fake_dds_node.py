"""A stand-in node process with a real DDS participant (test_graph_shm.py): an rclpy node that publishes, so that Fast
DDS's shared-memory transport holds its segment, until a signal ends it."""
import signal
import sys

import rclpy
from std_msgs.msg import String

signal.signal(signal.SIGINT, lambda *_: sys.exit(0))
rclpy.init(args=sys.argv)
node = rclpy.create_node("fake_dds_node")
pub = node.create_publisher(String, "/fake_dds_node/beat", 10)
node.create_timer(0.1, lambda: pub.publish(String(data="beat")))
print("fake dds node up", flush=True)
rclpy.spin(node)
