#!/usr/bin/env python3
"""Benchmark: how long a node takes to exit after SIGINT (docs/reliability.md, section 7), this checkout against the
relocation_common/ of another git revision, side by side. Not a timed test.

Each node of test/test_reliability_shutdown.py's NODES is started alone with its real parameter file on a private
ROS domain, waited for until its ready line, left running 1 s, then sent SIGINT. Measured from the signal to the
process's end: the wall time, and the CPU seconds the process used in it (its /proc stat before the signal against
wait4's rusage). The two codes alternate round by round, so that a change of the machine's load hits both;
`--load K` runs K busy loops beside them (the 2-core machines of CI are shared).

    .venv/bin/python scripts/bench_node_exit.py --baseline main --rounds 5
    .venv/bin/python scripts/bench_node_exit.py --baseline main --rounds 5 --load 4
"""
from __future__ import annotations

import argparse
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path[:0] = [str(ROOT), str(ROOT / "test")]

READY_TIMEOUT = 90.0  # s a node may take to start on a loaded machine


def export_common(rev: str) -> str:
    """relocation_common/ of git revision `rev` in a temporary directory, with this checkout's config/."""
    from bench_motion_planner import export_package  # scripts/ is sys.path[0]: the sibling benchmark
    d = export_package(rev, "relocation_common")
    for f in ("config", "package.xml"):  # relocation_common takes the directory beside itself for the checkout
        os.symlink(ROOT / f, Path(d) / f)
    return d


def cpu_seconds(pid: int) -> float:
    """User plus system CPU seconds of process `pid` so far (/proc/PID/stat)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def one_exit(name: str, common_dir: str, run_dir: Path, domain: int) -> tuple[float, float]:
    """(wall s, CPU s) from SIGINT to the end of node `name` whose relocation_common comes from `common_dir` ("" =
    this checkout's)."""
    from test_reliability_shutdown import NODES

    from relocation_app.graph import ros_env
    module, params, _extra, ready = NODES[name]
    env = ros_env(domain, run_dir)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [common_dir, str(ROOT)]))
    log = run_dir / f"{name}.log"
    with open(log, "wb") as out:
        p = subprocess.Popen([sys.executable, "-m", module, "--ros-args", "--params-file",
                              str(ROOT / "config" / params)], env=env, cwd=common_dir or ROOT, stdout=out,
                             stderr=subprocess.STDOUT, start_new_session=True)
    try:
        deadline = time.monotonic() + READY_TIMEOUT
        while ready not in log.read_text(errors="replace"):
            if p.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError(f"{name} did not start:\n{log.read_text(errors='replace')[-2000:]}")
            time.sleep(0.05)
        time.sleep(1.0)
        cpu0, t0 = cpu_seconds(p.pid), time.monotonic()
        p.send_signal(signal.SIGINT)
        _, status, usage = os.wait4(p.pid, 0)
        wall = time.monotonic() - t0
        p.returncode = os.waitstatus_to_exitcode(status)
        if p.returncode != 0:
            raise RuntimeError(f"{name} exited {p.returncode}:\n{log.read_text(errors='replace')[-2000:]}")
        return wall, usage.ru_utime + usage.ru_stime - cpu0
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--baseline", default="main", help="git revision whose relocation_common/ is the old code")
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--load", type=int, default=0, help="busy loops beside the nodes")
    ap.add_argument("--domain", type=int, default=94)
    ap.add_argument("--nodes", nargs="*", default=None)
    a = ap.parse_args()
    from test_reliability_shutdown import NODES
    base = export_common(a.baseline)
    hogs = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(a.load)]
    codes = ((a.baseline, base), ("working tree", ""))
    print(f"# {time.strftime('%Y-%m-%d %H:%M', time.gmtime())} UTC, load {os.getloadavg()[0]:.1f} on "
          f"{os.cpu_count()} cores, {a.load} busy loops beside")
    try:
        with tempfile.TemporaryDirectory(prefix="bench_exit_") as tmp:
            for name in a.nodes or list(NODES):
                res: dict[str, list[tuple[float, float]]] = {c: [] for c, _ in codes}
                for r in range(a.rounds):
                    for code, d in codes:
                        run_dir = Path(tmp) / f"{name}_{r}_{len(res[code])}_{code.replace(' ', '_')}"
                        run_dir.mkdir()
                        res[code].append(one_exit(name, d, run_dir, a.domain))
                for code, _ in codes:
                    walls, cpus = [w for w, _ in res[code]], [c for _, c in res[code]]
                    print(f"{name:16s} {code:14s} wall median {statistics.median(walls):.3f} s (max {max(walls):.3f}),"
                          f" CPU median {statistics.median(cpus):.3f} s (max {max(cpus):.3f}), {a.rounds} exits")
    finally:
        for h in hogs:
            h.kill()
        print(f"# load at the end {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
