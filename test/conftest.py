"""Test session set-up shared by every test module."""
import os

# MuJoCo picks its OpenGL platform when it is first imported; a test module that imports mujoco before
# jaco2_sim_driver would leave the whole pytest process unable to render (headless: EGL).
os.environ.setdefault("MUJOCO_GL", "egl")
