"""The arm's interface in one place (config/arm_interface.yaml, relocation_common/arm_interface.py): both nodes read
it, a `-p` on one node still overrides it, and a mismatch is never silent - the graph launcher refuses it, and in a
graph started by hand the driver and the planner log it and a relocation aborts with it."""
import sys
import time
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from relocation_common.arm_interface import ArmInterface, mismatch
from relocation_common.config import ParameterError, node_section
from relocation_common.paths import config_file

KINOVA = ArmInterface.load()
ROS2_CONTROL = ArmInterface(**{**KINOVA.to_dict(), "command_interface": "ros2_control"})


def test_the_file_is_the_source_and_every_key_is_checked(tmp_path):
    assert KINOVA.command_interface == "kinova" and KINOVA.driver_prefix == "/j2s7s300_driver"
    assert KINOVA.velocity_topic == "/j2s7s300_driver/in/joint_velocity"
    assert ROS2_CONTROL.state_topic == "/joint_states"
    for node in ("jaco2_sim_driver", "motion_planner"):  # in one place: neither node's file repeats a key
        assert set(node_section(config_file(f"{node}.yaml"), node)) & set(ArmInterface.keys()) == set(), node
    f = tmp_path / "arm.yaml"
    f.write_text("/**:\n  ros__parameters:\n    command_interface: kinova\n")
    with pytest.raises(ParameterError, match="arm.yaml: missing arm interface parameter.*driver_prefix"):
        ArmInterface.load(f)
    f.write_text(config_file("arm_interface.yaml").read_text() + "    comand_interface: kinova\n")
    with pytest.raises(ParameterError, match="arm.yaml: unknown parameter.*comand_interface"):
        ArmInterface.load(f)
    assert ArmInterface(**{**KINOVA.to_dict(), "driver_prefix": "/j2s7s300_driver/"}) == KINOVA


def test_a_key_in_a_node_file_and_in_the_shared_file_is_refused(tmp_path, monkeypatch):
    import relocation_common.node as node

    (tmp_path / "x.yaml").write_text("x:\n  ros__parameters:\n    driver_prefix: /a\n    rate: 1.0\n")
    (tmp_path / "arm_interface.yaml").write_text(config_file("arm_interface.yaml").read_text())
    monkeypatch.setattr(node, "config_file", lambda name: tmp_path / name)

    class Named:
        def get_name(self):
            return "x"

    with pytest.raises(ParameterError, match="driver_prefix in both config/x.yaml and config/arm_interface.yaml"):
        node.declare_parameters(Named(), shared=("arm_interface.yaml",))


def test_mismatch_names_what_the_other_side_runs():
    # the planner reads joint states; the driver publishes them on another surface's topic
    found = mismatch(KINOVA, "planner", KINOVA.state_topic, {"/joint_states": 1, KINOVA.state_topic: 0})
    assert found is not None and "runs command_interface ros2_control" in found and "arm_interface.yaml" in found
    found = mismatch(ROS2_CONTROL, "planner", "/joint_states", {"/other_driver/out/joint_state": 1})
    assert found is not None and "command_interface kinova, driver_prefix /other_driver" in found
    found = mismatch(KINOVA, "driver", KINOVA.velocity_topic, {"/velocity_controller/commands": 1})
    assert found is not None and "the motion planner runs command_interface ros2_control" in found
    # the same surface, or nobody on any surface (the other side not up yet): nothing to say
    assert mismatch(KINOVA, "planner", KINOVA.state_topic, {KINOVA.state_topic: 1, "/joint_states": 1}) is None
    assert mismatch(KINOVA, "planner", KINOVA.state_topic, {"/joint_states": 0, "/tf": 3}) is None
    assert mismatch(ROS2_CONTROL, "driver", "/velocity_controller/commands", {}) is None


def test_the_launcher_refuses_a_planner_and_a_driver_on_different_surfaces(tmp_path):
    from relocation_app.graph import Graph

    with Graph(tmp_path) as g:
        g.start("jaco2_sim_driver", {"camera_rate": 0.0, "command_interface": "ros2_control"})
        with pytest.raises(ValueError, match="command_interface 'kinova' vs 'ros2_control'.*arm_interface.yaml"):
            g.start("motion_planner")
        with pytest.raises(ValueError, match="driver_prefix"):
            g.start("motion_planner", {"command_interface": "ros2_control", "driver_prefix": "/other"})
        assert "motion_planner" not in g.procs
        g.start("motion_planner", {"command_interface": "ros2_control"})  # the same surface: started
        assert g.arms["motion_planner"] == g.arms["jaco2_sim_driver"] == ROS2_CONTROL


@pytest.mark.graph
def test_nodes_started_by_hand_on_different_surfaces_say_so(tmp_path):
    """The driver on ros2_control (-p on it alone), the planner on the file's kinova: both log the mismatch naming
    the other side's surface, and a relocation aborts with it instead of waiting for joint states that never come."""
    from kinova_outsider import Client
    from qtree_relocation_msgs.action import RelocateObject
    from ros_procs import REPO, RosGraph

    with RosGraph(tmp_path) as g:
        driver = g.start("jaco2_sim_driver.driver_node", params_file=REPO / "config" / "jaco2_sim_driver.yaml",
                         params={"camera_rate": 0.0, "command_interface": "ros2_control"})
        planner = g.start("stpik_motion_planner.motion_planner_node",
                          params_file=REPO / "config" / "motion_planner.yaml")
        client = Client(g.domain_id, "mismatch_client")
        try:
            ac = client.action(RelocateObject, "/motion_planner/relocate", timeout=90)
            t0 = time.monotonic()
            _, result = client.goal(ac, RelocateObject.Goal(object_id="o2", removed_ids=[]), timeout=60)
            took = time.monotonic() - t0
        finally:
            client.close()
        deadline = time.monotonic() + 20
        while "arm interface mismatch" not in driver.log() and time.monotonic() < deadline:
            time.sleep(0.2)
        print(f"\nrelocation aborted after {took:.1f} s: {result.message if result else None!r}")
        assert result is not None and not result.success
        assert "arm interface mismatch" in result.message and "ros2_control" in result.message, result.message
        assert "the driver runs command_interface ros2_control" in planner.log(), planner.log()[-2000:]
        assert "the motion planner runs command_interface kinova, driver_prefix /j2s7s300_driver" in driver.log(), \
            driver.log()[-2000:]
