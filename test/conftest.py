"""Test session set-up shared by every test module."""
import os

# MuJoCo picks its OpenGL platform when it is first imported; a test module that imports mujoco before
# jaco2_sim_driver would leave the whole pytest process unable to render (headless: EGL).
os.environ.setdefault("MUJOCO_GL", "egl")


def pytest_collection_modifyitems(config, items):
    """Tests marked `extended` (the longer halves of parametrized sweeps) run only when selected with
    `-m extended` or QTREE_EXTENDED=1: the default run (`./run test`) keeps a small version of each."""
    import pytest

    expr = config.getoption("-m") or ""
    if ("extended" in expr and "not extended" not in expr) or os.environ.get("QTREE_EXTENDED") == "1":
        return
    skip = pytest.mark.skip(reason="extended: run with -m extended (or QTREE_EXTENDED=1)")
    for item in items:
        if "extended" in item.keywords:
            item.add_marker(skip)
