"""Bad input across the graph (docs/reliability.md, section 4): malformed or partial parameter and scenario files.

Nodes: the driver and perception exit with status 2 and one line naming the problem (the task planner's cases are
in test_reliability_task_planner.py). Core: PlannerParams (config/motion_planner.yaml) raises a clear error.
Covered elsewhere, not repeated here: scenario-file errors in the core (test_scenario.py: one clear line per bad
field, malformed YAML, missing file, NaN in scene messages), NaN/Inf and wrong-length velocity commands to the
driver (test_driver_node.py::test_bad_command_changes_nothing_and_node_keeps_running and
::test_nan_on_the_kinova_topic_is_rejected), training goals out of range and bad scenes
(test_reliability_task_planner.py)."""
import importlib
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from ros_procs import REPO, RosGraph, main_in_process

from stpik_motion_planner.planning.params import PlannerParams

DRIVER = ("jaco2_sim_driver.driver_node", REPO / "config" / "jaco2_sim_driver.yaml", "jaco2_sim_driver: ")
PERCEPTION = ("perception_aruco.perception_node", REPO / "config" / "perception.yaml", "perception: ")
PLANNER = ("stpik_motion_planner.motion_planner_node", REPO / "config" / "motion_planner.yaml", "motion_planner: ")


def _files(tmp: Path) -> dict:
    (tmp / "scenario_malformed.yaml").write_text("name: x\nobjects: [\n")
    (tmp / "scenario_partial.yaml").write_text("name: x\nshelf: {}\n")
    (tmp / "driver_malformed.yaml").write_text("jaco2_sim_driver:\n  ros__parameters:\n    camera_rate: [2.0\n")
    (tmp / "driver_partial.yaml").write_text("jaco2_sim_driver:\n  camera_rate: 2.0\n")
    return {k: str(tmp / f"{k}.yaml") for k in ("scenario_malformed", "scenario_partial", "driver_malformed",
                                                 "driver_partial")}


CASES = [  # (node, ros args, words of the one line)
    (DRIVER, ["-p", "scenario:=SCENARIO_MALFORMED"], "malformed YAML"),
    (DRIVER, ["-p", "scenario:=SCENARIO_PARTIAL"], "ScenarioError"),
    (DRIVER, ["-p", "scenario:=/nonexistent/scenario.yaml"], "cannot read scenario file"),
    (DRIVER, ["--params-file", "DRIVER_MALFORMED"], "malformed YAML"),
    (DRIVER, ["--params-file", "DRIVER_PARTIAL"], "ros__parameters"),
    (DRIVER, ["-p", "joint_state_rate:=0.0"], "joint_state_rate must be > 0"),
    (DRIVER, ["-p", "watchdog_timeout:=-0.05"], "watchdog_timeout must be > 0"),
    (DRIVER, ["-p", "qdot_max:=[0.8,0.8]"], "unknown parameter(s) qdot_max"),  # Table 7: the robot's, no parameter
    (DRIVER, ["-p", "real_time_factor:=fast"], "real_time_factor"),
    (PERCEPTION, ["-p", "scenario:=SCENARIO_MALFORMED"], "malformed YAML"),
    (PERCEPTION, ["-p", "process_rate:=0.0"], "process_rate must be > 0"),
    (PERCEPTION, ["-p", "sync_slop:=abc"], "sync_slop"),
    (PLANNER, ["-p", "timeout:=-1.0"], "timeout must be a finite number > 0"),
    (PLANNER, ["-p", "stpik.qdot_max:=[0.8,0.8]"], "unknown parameter(s) stpik.qdot_max"),
    (PLANNER, ["-p", "scenario:=SCENARIO_PARTIAL"], "ScenarioError"),
    (PLANNER, ["-p", "state_hold:=3.0"], "0 < state_hold < state_timeout"),
    (PLANNER, ["--params-file", "DRIVER_MALFORMED"], "malformed YAML"),
]


def _args(case: tuple, files: dict) -> tuple[str | None, list[str]]:
    """(the params file to add, or None; the case's ros args with the placeholders replaced by the files)."""
    (_, params_file, _), args, _ = case

    def subst(a):
        return next((files[k.lower()] for k in files if a.endswith(k.upper())), a)
    args = [a.split(":=")[0] + ":=" + subst(a.split(":=")[1]) if ":=" in a else subst(a) for a in args]
    return (None if "--params-file" in args else str(params_file)), args


# the first case of each node runs as a process; the others call its main() in the test's process (ros_procs.
# main_in_process: the same code after the imports, 1.5-1.9 s less CPU each)
PROCESS_CASES = [next(c for c in CASES if c[0] is node) for node in (DRIVER, PERCEPTION, PLANNER)]


def test_driver_perception_and_planner_refuse_bad_files_and_parameters_with_one_line(tmp_path):
    files = _files(tmp_path)
    with RosGraph(tmp_path) as g:
        procs = []
        for k, case in enumerate(PROCESS_CASES):
            pf, args = _args(case, files)
            module = case[0][0]
            procs.append(g.start(module, params_file=pf, params={"camera_rate": 0.0} if module == DRIVER[0] else {},
                                 ros_args=tuple(args), name=f"case{k}"))
        for p, ((_, _, prefix), args, words) in zip(procs, PROCESS_CASES):
            p.popen.wait(90)
            lines = [ln for ln in p.log().splitlines() if ln.strip()]
            assert p.popen.returncode == 2, (args, p.log()[-2000:])
            assert len(lines) == 1 and lines[0].startswith(prefix) and words in lines[0], (args, lines)


@pytest.mark.parametrize("case", [c for c in CASES if c not in PROCESS_CASES], ids=lambda c: f"{c[0][2][:-2]}-{c[2]}")
def test_the_other_bad_files_and_parameters_exit_2_with_one_line(case, tmp_path, capfd):
    files = _files(tmp_path)
    pf, args = _args(case, files)
    extra = ["-p", "camera_rate:=0.0"] if case[0] is DRIVER else []
    main = importlib.import_module(case[0][0]).main
    status, lines = main_in_process(main, (["--params-file", pf] if pf else []) + extra + args, capfd, tmp_path)
    prefix, words = case[0][2], case[2]
    assert status == 2, (args, lines)
    assert len(lines) == 1 and lines[0].startswith(prefix) and words in lines[0], (args, lines)


# -- the motion planner's parameters (core) ------------------------------------------------------------------------
def _mp(tmp_path, body: str) -> Path:
    f = tmp_path / "motion_planner.yaml"
    f.write_text(body)
    return f


def test_motion_planner_params_partial_or_unknown_key_is_a_clear_error(tmp_path):
    with pytest.raises(ValueError, match="expected 'motion_planner: ros__parameters"):
        PlannerParams.load(_mp(tmp_path, "motion_planner:\n  timeout: 0.5\n"))
    with pytest.raises(ValueError, match="'timeuot' is unknown"):
        PlannerParams.load(_mp(tmp_path, "motion_planner:\n  ros__parameters:\n    timeuot: 0.5\n"))
    assert PlannerParams.load(REPO / "config" / "motion_planner.yaml").timeout > 0


def test_motion_planner_params_malformed_yaml_is_a_clear_error(tmp_path):
    with pytest.raises(ValueError, match="malformed"):
        PlannerParams.load(_mp(tmp_path, "motion_planner:\n  ros__parameters:\n    timeout: [\n"))


@pytest.mark.parametrize("line", ["timeout: abc", "timeout: -1.0", "rrt_max_checks: .nan", "stpik.qdot_max: [1.0, 2.0]",
                                  "max_attempts: 0"])
def test_motion_planner_params_out_of_range_is_a_clear_error(tmp_path, line):
    with pytest.raises(ValueError, match=line.split(":")[0].split(".")[-1]):
        PlannerParams.load(_mp(tmp_path, f"motion_planner:\n  ros__parameters:\n    {line}\n"))


def test_params_file_precheck_names_the_file_and_line(tmp_path):
    from relocation_common.config import ParameterError, check_params_files
    f = tmp_path / "x.yaml"
    f.write_text("a:\n  ros__parameters:\n    b: [1,\n")
    with pytest.raises(ParameterError, match=r"x.yaml: malformed YAML at line \d"):
        check_params_files(["prog", "--ros-args", "--params-file", str(f)])
    f.write_text("a: 3\n")
    with pytest.raises(ParameterError, match="ros__parameters"):
        check_params_files(["--params-file", str(f)])
    f.write_text("a:\n  ros__parameters: {b: 1}\n")
    check_params_files(["--params-file", str(f), "-p", "x:=1"])
    f.write_text("/ns:\n  a:\n    ros__parameters: {b: 1}\n/**:\n  ros__parameters: {c: 2}\n")
    check_params_files(["--params-file", str(f)])  # namespaced and wildcard sections are fine
    f.write_text("a:\n  ros__parameters: 3\n")
    with pytest.raises(ParameterError, match="ros__parameters"):
        check_params_files(["--params-file", str(f)])
