"""The chaos benchmark's moments (scripts/bench_chaos.py, Watch.moment_reached), without a graph: a kill drawn for
the training moment happens only while the Q-Tree trains. The old code killed `delay` s after the first training
feedback whatever the phase: on scenario1_5 the training ends within 3-10 s, so all 10 runs of perception and the
motion planner "at the training moment" under load were killed during the execution ("training (executing) 10.7 s
in")."""
import time

from ros_procs import load_script


def _bench():
    return load_script("bench_chaos")


def test_a_training_kill_happens_only_while_the_q_tree_trains():
    bench = _bench()
    watch = bench.Watch.__new__(bench.Watch)  # its state only: no rclpy context
    watch.goals, watch.training_since = [], time.monotonic() - 5.0
    spec, draw = bench.Spec("perception", "training", 0), {"delay": 2.0, "k": 1, "progress": 0.5, "after": 0.0}
    watch.train_phase = "executing"
    assert watch.moment_reached(spec, draw) is None, "killed during the execution, not the training"
    watch.train_phase = "training"
    assert watch.moment_reached(spec, draw) == "training (training) 2.0 s in"
    watch.training_since = time.monotonic()
    assert watch.moment_reached(spec, draw) is None  # the delay has not passed
