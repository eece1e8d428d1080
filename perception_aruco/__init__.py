"""ArUco + colour/depth perception of the shelf (docs/perception.md).

numpy's OpenBLAS runs single-threaded here unless the environment says otherwise (set before numpy is imported,
as jaco2_sim_driver sets MUJOCO_GL): on the shared 2-core machine its threads made a frame 1.6x slower (4.4 vs 6.9
frames/s, docs/bench/perception.md)."""
import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
