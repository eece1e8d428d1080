import os

os.environ.setdefault("MUJOCO_GL", "egl")  # headless offscreen rendering; must be set before mujoco is imported
