"""The interfaces' Python classes and C libraries from one build (relocation_common.node.check_type_support): a
feasible pick answered through a node whose PlanFeasibility had lost `near_known` in its C library reused nothing
(the demo on scenario3_15: 2,369 planner calls where the same training through a sound install asks 574)."""
import re
import shutil
import time

import pytest
from ros_procs import REPO, RosGraph

pytest.importorskip("rclpy")
import qtree_relocation_msgs  # noqa: E402  (after the importorskip of rclpy)
from qtree_relocation_msgs.srv import PlanFeasibility  # noqa: E402  (after the importorskip of rclpy)

from relocation_common.node import check_type_support, lost_fields, sample  # noqa: E402  (after the importorskip of rclpy)

NEW_FIELD = "reach_known"


def test_the_installed_interfaces_keep_every_field():
    check_type_support()  # raises InterfaceMismatch naming the fields lost
    res, req = sample(PlanFeasibility.Response), sample(PlanFeasibility.Request)
    assert res.near_known and list(res.near_ids) and res.blockers[0].certain and res.lanes[0].lanes  # not defaults
    assert req.certify and req.label_only and list(req.removed_ids)
    assert lost_fields(PlanFeasibility.Response) == []


def newer_python_package(root):
    """A copy of the installed qtree_relocation_msgs whose PlanFeasibility response has one field more than its C
    libraries (as the Python package of a newer msg_defs/ on the C libraries of an older build): NEW_FIELD."""
    pkg = root / "qtree_relocation_msgs"
    shutil.copytree(list(qtree_relocation_msgs.__path__)[0], pkg, ignore=shutil.ignore_patterns("__pycache__"))
    src = pkg / "srv" / "_plan_feasibility.py"
    text = src.read_text()
    edits = [(r"(\n {8}'_lanes',\n)", rf"\1        '{NEW_FIELD}',\n"),  # a plain slot: no property needed
             (r"(\n {8}'lanes': 'sequence<qtree_relocation_msgs/LaneBlockers>',\n)",
              rf"\1        '{NEW_FIELD}': 'boolean',\n"),
             (r"(\n {8}rosidl_parser\.definition\.UnboundedSequence\(rosidl_parser\.definition\.NamespacedType\("
              r"\['qtree_relocation_msgs', 'msg'\], 'LaneBlockers'\)\),  # noqa: E501\n)",
              r"\1        rosidl_parser.definition.BasicType('boolean'),\n"),
             (r"(\n {8}self\.lanes = kwargs\.get\('lanes', \[\]\)\n)",
              rf"\1        self.{NEW_FIELD} = kwargs.get('{NEW_FIELD}', bool())\n")]
    for pattern, repl in edits:
        text, n = re.subn(pattern, repl, text)
        assert n == 1, f"the generated PlanFeasibility changed shape: {pattern!r} matched {n} times"
    src.write_text(text)
    return root


def test_a_node_on_an_interface_build_that_loses_a_field_refuses_to_start_and_names_it(tmp_path):
    """Old code: the node started and served every answer without the field (near_known false on every feasible
    pick: test/test_type_support.py's docstring); now: exit 2 at once, one line naming the field and what to do."""
    newer = newer_python_package(tmp_path / "newer")
    with RosGraph(tmp_path / "graph") as g:
        argv = [g.python, "-m", "stpik_motion_planner.motion_planner_node", "--ros-args", "--params-file",
                str(REPO / "config" / "motion_planner.yaml")]
        p = g.start_argv(argv, "motion_planner", env={"PYTHONPATH": f"{newer}:{g.env['PYTHONPATH']}"})
        deadline = time.monotonic() + 15
        while p.alive() and time.monotonic() < deadline:
            time.sleep(0.1)
        log = p.log()
        assert not p.alive(), "the node runs on an interface build that loses a field: " + log[-1500:]
        assert p.popen.returncode == 2, log[-1500:]
        assert f"srv/PlanFeasibility_Response: {NEW_FIELD}" in log and "different builds of msg_defs" in log, log
        assert "Traceback" not in log, log
