"""A node SIGKILLed in a graph leaves its Fast DDS shared-memory segment in /dev/shm: RAM nothing frees (about 600
such segments, 2.5 GB, after a day of test runs here). The graph launcher's stop now removes the files whose owner
is gone (graph.clean_shared_memory: Fast DDS's `fastdds shm clean`); a live process's files stay. The node is a
stand-in with a real DDS participant (test/fake_dds_node.py); its segments are the /dev/shm files it holds locked
(/proc/locks), each named once (its ports' files are not checked: another process may open the same port number).
On the old launcher the killed node's segments were still there after the stop."""
import fcntl
import os
import signal
import time
from pathlib import Path

import pytest

from relocation_app import graph
from relocation_app.graph import Graph

pytestmark = [pytest.mark.graph, pytest.mark.skipif(not Path("/proc/locks").exists(), reason="Linux only")]

TEST_DIR = Path(__file__).resolve().parent
SHM = Path("/dev/shm")


def locked_by(pid: int) -> set[Path]:
    """The /dev/shm files process `pid` holds a flock on (its Fast DDS segments' and ports' lock files)."""
    inodes = {int(f[5].split(":")[2]) for f in (line.split() for line in Path("/proc/locks").read_text().splitlines())
              if len(f) > 5 and f[1] == "FLOCK" and f[4] == str(pid)}
    return {p for p in SHM.iterdir() if p.name.startswith("fastrtps_") and p.stat().st_ino in inodes}


def test_a_killed_node_s_shared_memory_is_removed_at_the_stop_and_a_live_one_s_kept(tmp_path, monkeypatch):
    monkeypatch.setattr(graph, "NODES", {name: ("fake_dds_node", "perception.yaml") for name in graph.NODES})
    live = SHM / f"fastrtps_{os.getpid():016x}"  # a segment of a live process (this one): its lock file held
    live.write_bytes(b"")
    with open(f"{live}_el", "ab") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        try:
            g = Graph(tmp_path)
            g.env["PYTHONPATH"] = os.pathsep.join([str(TEST_DIR), g.env["PYTHONPATH"]])
            with g:
                p = g.start("perception")
                deadline = time.monotonic() + 60.0
                # its segments' lock files (a port's number is taken again by the next process that needs one)
                while not (held := {f for f in locked_by(p.pid) if f.name.endswith("_el") and "port" not in f.name}):
                    assert p.poll() is None and time.monotonic() < deadline, g.log("perception")[-2000:]
                    time.sleep(0.2)
                segments = {f.with_name(f.name[:-3]) for f in held}
                os.kill(p.pid, signal.SIGKILL)
                p.wait()
                assert all(f.exists() for f in held | segments)  # left behind by the killed process
            assert not any(f.exists() for f in held | segments), sorted(f.name for f in held | segments if f.exists())
            assert live.exists() and Path(f"{live}_el").exists()
        finally:
            live.unlink(missing_ok=True)
            Path(f"{live}_el").unlink(missing_ok=True)
