"""Test session set-up shared by every test module."""
import os

import pytest

# MuJoCo picks its OpenGL platform when it is first imported; a test module that imports mujoco before
# jaco2_sim_driver would leave the whole pytest process unable to render (headless: EGL).
os.environ.setdefault("MUJOCO_GL", "egl")


def pytest_collection_modifyitems(config, items):
    """The files that hold a test marked `slow` run first (in their collected order; the rest after them): with the
    files spread over workers (`./run test`, --dist loadfile) the longest ones start at once instead of being
    handed out last to one worker while the other waits.

    Tests marked `extended` (the longer variants: the rest of a parametrized sweep, many-round loops) are skipped
    unless asked for: `-m extended` runs only them (pytest's own selection), QTREE_EXTENDED=1 runs them with the
    rest. The default run (`./run test`) keeps a small version of each check."""
    import pytest

    slow_files = {item.path for item in items if "slow" in item.keywords}
    items.sort(key=lambda item: item.path not in slow_files)  # stable: the order inside each group is kept
    expr = config.getoption("-m") or ""
    if ("extended" in expr and "not extended" not in expr) or os.environ.get("QTREE_EXTENDED") == "1":
        return
    skip = pytest.mark.skip(reason="extended: run with -m extended (or QTREE_EXTENDED=1)")
    for item in items:
        if "extended" in item.keywords:
            item.add_marker(skip)


def pytest_sessionfinish(session, exitstatus):
    """The node processes the tests SIGKILLed (chaos, respawn, stop timeouts) left their Fast DDS shared-memory files
    in /dev/shm: removed once the whole run is over, by the controller (graph.clean_shared_memory: only the files
    whose owner is gone)."""
    if not hasattr(session.config, "workerinput"):
        from relocation_app.graph import clean_shared_memory
        print(f"\n[shared memory] {clean_shared_memory()}")


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item, nextitem):
    """QTREE_TEST_CPU=FILE: a JSON line per test appended to FILE with its wall time and the CPU seconds of this
    process and of the processes it waited for (the node processes a test started and stopped), setup and teardown
    included (a module's fixtures count to its first and last test). What `./run test`'s time is spent on:
    docs/bench/test_time.md."""
    path = os.environ.get("QTREE_TEST_CPU")
    if not path:
        yield
        return
    import json
    import resource
    import time

    def cpu() -> float:
        own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
        return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime

    t0, c0 = time.monotonic(), cpu()
    yield
    with open(path, "a") as f:
        f.write(json.dumps({"test": item.nodeid, "wall": time.monotonic() - t0, "cpu": cpu() - c0}) + "\n")
