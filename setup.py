"""ament_python package qtree_relocation: a common bottom (relocation_common), four cores with their node shells,
and the application (relocation_app: graph launcher, demo, evaluation, qtree CLI)."""
from glob import glob

from setuptools import find_packages, setup

PACKAGE = "qtree_relocation"

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(include=["relocation_common*", "qtree_task_planner*", "stpik_motion_planner*",
                                    "jaco2_sim_driver*", "perception_aruco*", "relocation_app*"]),
    package_data={"qtree_task_planner.learning": ["_kernel.c"]},
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
        (f"share/{PACKAGE}/config", glob("config/*.yaml") + ["config/fastdds.xml"]),
        (f"share/{PACKAGE}/config/scenarios", glob("config/scenarios/*.yaml")),
        *[(f"share/{PACKAGE}/config/scenarios/{d}", glob(f"config/scenarios/{d}/*.yaml"))
          for d in ("random5", "paper_random5", "world")],  # Table 4's random cases, both sets; the shelf as it is
        (f"share/{PACKAGE}/launch", glob("launch/*.py")),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="qtree_relocation maintainers",
    maintainer_email="maintainers@qtree-relocation.invalid",
    description="Objects relocation in clutter via tree-based Q-learning on ROS 2 Jazzy",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "task_planner = qtree_task_planner.task_planner_node:main",
            "motion_planner = stpik_motion_planner.motion_planner_node:main",
            "jaco2_sim_driver = jaco2_sim_driver.driver_node:main",
            "perception = perception_aruco.perception_node:main",
            "qtree = relocation_app.cli:main",
        ],
    },
)
