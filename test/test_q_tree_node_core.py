"""The task planner's ROS-free pieces that the node shell calls: scene checks, the relocation watchdog's
reasons, checkpoint bookkeeping (qtree_task_planner.executive.retrieval, .keeper, .problem)."""
import pytest

from qtree_task_planner.executive.keeper import CheckpointKeeper, check_checkpoint_path
from qtree_task_planner.executive.retrieval import check_scene, relocation_stop
from qtree_task_planner.executive.settings import check_node_parameters
from qtree_task_planner.learning.checkpoint import Checkpoint, CheckpointError
from qtree_task_planner.learning.params import TrainingParams
from qtree_task_planner.oracles import BlockingOracle, CachedOracle
from qtree_task_planner.problem import RelocationProblem
from relocation_common.config import ParameterError, node_section
from relocation_common.node import flat_parameters
from relocation_common.paths import config_file
from relocation_common.scenario import ScenarioError, load_scenario

SC = load_scenario("blocking_5")
PROBLEM = RelocationProblem.from_scenario(SC)
PARAMS = TrainingParams.defaults().replace(seed=1, max_episodes=50)


def test_scene_checks_in_order():
    with pytest.raises(ScenarioError, match="no scene received on /s"):
        check_scene("/s", 10.0, None, None, 0)
    with pytest.raises(ScenarioError, match="received 12.0 s ago > scene_max_age 10 s"):
        check_scene("/s", 10.0, 12.0, 1.0, 5)
    with pytest.raises(ScenarioError, match="stamped 11.0 s ago"):
        check_scene("/s", 10.0, 1.0, 11.0, 5)
    with pytest.raises(ScenarioError, match="is empty"):
        check_scene("/s", 10.0, 1.0, 1.0, 0)
    assert "use_sim_time" in check_scene("/s", 10.0, 1.0, 1e6, 5)  # another clock: receive time only
    assert check_scene("/s", 0.0, 1e6, 1e6, 5) is None  # max_age 0: no age check
    assert check_scene("/s", 10.0, 1.0, None, 5) is None


def test_problem_from_bottles_keeps_the_order_and_weights():
    assert RelocationProblem.from_bottles(SC.objects) == PROBLEM


@pytest.mark.parametrize("state,why", [
    (dict(shutting_down=True), "shutting down"),
    (dict(server_up=lambda: False), "relocate action server gone"),
    (dict(silent_s=11.0), "no feedback for 11 s > relocate_silence"),
    (dict(cancelled=True), "cancelled"),
    (dict(elapsed_s=181.0), "no result within 180 s (relocate_timeout)"),
    (dict(), None),
    (dict(shutting_down=True, server_up=lambda: 1 / 0), "shutting down"),  # the server is not asked then
])
def test_relocation_stop_reasons(state, why):
    args = dict(shutting_down=False, server_up=lambda: True, silent_s=0.5, silence=10.0, cancelled=False,
                elapsed_s=1.0, limit=180.0) | state
    got = relocation_stop(**args)
    assert got == why if why is None else why in got


def test_keeper_resumes_from_the_file_and_refuses_another_scene(tmp_path):
    path = tmp_path / "ck.json"
    k = CheckpointKeeper(str(path))
    assert k.resume_point(PROBLEM, PARAMS, CachedOracle(BlockingOracle(SC))) is None
    ck = Checkpoint.initial(PROBLEM, PARAMS, reason="periodic")
    k.keep(ck)
    assert path.is_file() and k.written == (0, "") and k.kept_where() == f"checkpoint {path} at episode 0"
    said = []
    k2 = CheckpointKeeper(str(path), info=said.append)
    assert k2.resume_point(PROBLEM, PARAMS, CachedOracle(BlockingOracle(SC))).episode == 0
    assert said and said[0].startswith(f"resuming from checkpoint {path}: episode 0")
    with pytest.raises(CheckpointError, match="other training parameters"):
        k2.resume_point(PROBLEM, PARAMS.replace(seed=2), CachedOracle(BlockingOracle(SC)))


def test_keeper_in_memory_only_an_interrupted_goal_resumes():
    k = CheckpointKeeper("")
    k.keep(Checkpoint.initial(PROBLEM, PARAMS, reason="final"))
    assert k.kept_where() == "in memory at episode 0 only (set checkpoint_path to keep it across restarts)"
    assert k.resume_point(PROBLEM, PARAMS, CachedOracle(BlockingOracle(SC))) is None
    k.keep(Checkpoint.initial(PROBLEM, PARAMS, reason="interrupted: gone"))
    assert k.resume_point(PROBLEM, PARAMS.replace(seed=9), CachedOracle(BlockingOracle(SC))) is None
    k.keep(Checkpoint.initial(PROBLEM, PARAMS, reason="interrupted: gone"))
    assert k.resume_point(PROBLEM, PARAMS, CachedOracle(BlockingOracle(SC))) is k.memory is not None


def test_keeper_a_failed_write_is_said_and_training_goes_on(tmp_path):
    errors = []
    k = CheckpointKeeper(str(tmp_path / "missing" / "x" / "ck.json"), error=errors.append)
    (tmp_path / "missing").write_text("a file where a directory should be")
    k.keep(Checkpoint.initial(PROBLEM, PARAMS))
    assert errors and k.written is not None and k.written[0] == -1 and k.memory is not None
    assert "in memory at episode 0 (writing" in k.kept_where()


def test_checkpoint_path_checks(tmp_path):
    check_checkpoint_path("")
    check_checkpoint_path(str(tmp_path / "new" / "ck.json"))
    with pytest.raises(ParameterError, match="is a directory"):
        check_checkpoint_path(str(tmp_path))


NODE_PARAMS = flat_parameters(node_section(config_file("task_planner.yaml"), "task_planner"))  # as the node declares


@pytest.mark.parametrize("name,value,words", [
    ("alpha", 1.5, "alpha"), ("scene_max_age", -1.0, "scene_max_age must be a finite number >= 0"),
    ("relocate_timeout", float("nan"), "relocate_timeout must be a finite number >= 0.001"),
    ("feasibility_timeout", True, "feasibility_timeout must be a finite number"),
    ("scene_source", "camera", "scene_source must be one of perception, sim"),
    ("replicas", 65, "replicas must be an integer in 1..64"), ("checkpoint_every", 0, "checkpoint_every must be"),
    ("checkpoint_path", "/", "is a directory"), ("action_cost.top_grasp", 0.0, r"action_cost.top_grasp must be"),
    ("action_cost.push", 11.0, r"action_cost.push must be a number in \(0, 10\]")])
def test_node_parameters_name_the_first_unusable_one(name, value, words):
    check_node_parameters(NODE_PARAMS.__getitem__)  # config/task_planner.yaml as it is: usable
    with pytest.raises(ParameterError, match=words):
        check_node_parameters({**NODE_PARAMS, name: value}.__getitem__)
