"""The simulated Kinova Jaco2 in MuJoCo: scene, physics core, camera and the driver node (docs/sim_driver.md)."""
import os

os.environ.setdefault("MUJOCO_GL", "egl")  # headless offscreen rendering; must be set before mujoco is imported
