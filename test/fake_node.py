"""A stand-in node process for the graph launcher's tests (test_graph_respawn.py): prints its respawn count, then
sleeps until a signal ends it."""
import os
import signal
import sys
import time

signal.signal(signal.SIGINT, lambda *_: sys.exit(0))
signal.signal(signal.SIGTERM, lambda *_: sys.exit(0))
print(f"fake node pid {os.getpid()} respawn {os.environ.get('QTREE_RESPAWN', '0')}", flush=True)
while True:
    time.sleep(1.0)
