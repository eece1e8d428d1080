"""Launch the retrieval graph on a machine with a full ROS 2 Jazzy install (launch_ros available).

    ros2 launch qtree_relocation retrieval.launch.py scenario:=/path/to/scenario.yaml scene_source:=perception \
        replicas:=2

This machine's PyPI-only ROS has no launch/launch_ros wheels, so this file cannot be exercised here: the
equivalent process harness is relocation_app/graph.py (used by `./run demo`), which tests start for real.
Set use_sim:=false and remap the driver topics to run against Kinova's kinova_driver instead of the simulator.
replicas:=N adds N-1 feasibility-only motion planners under /replica_<k> (docs/reliability.md, "Planner replicas").
A node that dies is restarted as config/graph.yaml says (launch_ros's respawn, respawn_delay; launch's
respawn_max_retries), the file the graph launcher reads too; the motion planner keeps its relocation journal in
journal_path (docs/reliability.md, "A node that dies").
"""
import os
import tempfile

import yaml
from ament_index_python.packages import get_package_share_directory
from launch.actions import DeclareLaunchArgument, OpaqueFunction, SetEnvironmentVariable
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from launch import LaunchDescription


def generate_launch_description():
    share = get_package_share_directory("qtree_relocation")
    cfg = os.path.join(share, "config")
    scenario = LaunchConfiguration("scenario")
    common = {"scenario": scenario}
    again = _respawn(cfg)
    # config/fastdds.xml unless the user has a Fast DDS profile: without its larger shared-memory segment most
    # best-effort camera images are lost (relocation_app/graph.py does the same)
    profile = [] if os.environ.get("FASTRTPS_DEFAULT_PROFILES_FILE") else [
        SetEnvironmentVariable("FASTRTPS_DEFAULT_PROFILES_FILE", os.path.join(cfg, "fastdds.xml"))]
    return LaunchDescription(profile + [
        DeclareLaunchArgument("scenario", default_value=os.path.join(cfg, "scenarios", "paper_experiment_10.yaml")),
        DeclareLaunchArgument("scene_source", default_value="perception"),
        DeclareLaunchArgument("use_sim", default_value="true"),
        Node(package="qtree_relocation", executable="jaco2_sim_driver", name="jaco2_sim_driver",
             parameters=[os.path.join(cfg, "jaco2_sim_driver.yaml"), common],
             condition=IfCondition(LaunchConfiguration("use_sim")), **again["jaco2_sim_driver"]),
        Node(package="qtree_relocation", executable="perception", name="perception",
             parameters=[os.path.join(cfg, "perception.yaml"), common], **again["perception"]),
        DeclareLaunchArgument("replicas", default_value="1"),
        OpaqueFunction(function=_planners, args=[cfg, common, again]),
    ])


def _respawn(cfg):
    """node -> launch_ros's respawn arguments, from config/graph.yaml (max_respawns as respawn_max_retries)."""
    with open(os.path.join(cfg, "graph.yaml")) as f:
        policies = yaml.safe_load(f)
    return {name: {"respawn": bool(p["respawn"]), "respawn_delay": float(p["respawn_delay"]),
                   "respawn_max_retries": int(p["max_respawns"])} for name, p in policies.items()}


def _planners(context, cfg, common, again):
    """The motion planner (its relocation journal in the temporary directory: a respawned one recovers from it),
    replicas - 1 feasibility-only replicas (namespaces replica_<k>), the task planner."""
    replicas = int(LaunchConfiguration("replicas").perform(context))
    planner = os.path.join(cfg, "motion_planner.yaml")
    journal = os.path.join(tempfile.mkdtemp(prefix="qtree_launch_"), "motion_planner.journal")
    nodes = [Node(package="qtree_relocation", executable="motion_planner", name="motion_planner",
                  parameters=[planner, common, {"journal_path": journal}], **again["motion_planner"])]
    nodes += [Node(package="qtree_relocation", executable="motion_planner", name="motion_planner",
                   namespace=f"replica_{k}", parameters=[planner, common, {"serve_relocation": False}],
                   **again["motion_planner"])
              for k in range(1, replicas)]
    nodes.append(Node(package="qtree_relocation", executable="task_planner", name="task_planner",
                      parameters=[os.path.join(cfg, "task_planner.yaml"), common,
                                  {"scene_source": LaunchConfiguration("scene_source"), "replicas": replicas}],
                      **again["task_planner"]))
    return nodes
