"""Test session set-up shared by every test module."""
import os

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
