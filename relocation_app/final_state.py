"""Where a retrieval left the robot (the closed-loop benchmark's safety target: no run leaves the arm away from
home or a bottle in the gripper), from the simulator's last joint state and ground truth; used by the demo's
report, the closed-loop benchmark and its graph test."""
from __future__ import annotations

from typing import Mapping, Sequence

import numpy as np

from relocation_common import robot_description as rd
from relocation_common.config import node_section
from relocation_common.paths import config_file
from relocation_common.ros_conversions import msg_to_objects

# rad per joint: the motion planner's own home_tol, read from its parameters file (one source)
HOME_TOL = float(node_section(config_file("motion_planner.yaml"), "motion_planner")["home_tol"])
HAND_REACH = 0.1  # m: a bottle whose centre is this close to the tool is in (or at) the hand


def arm_home(names: Sequence[str], positions: Sequence[float], tol: float = HOME_TOL) -> bool:
    """Every arm joint within `tol` of Q_HOME (angles wrapped)."""
    q = dict(zip(names, positions))
    if any(n not in q for n in rd.JOINT_NAMES):
        return False
    d = np.array([q[n] for n in rd.JOINT_NAMES]) - rd.Q_HOME
    return bool(np.all(np.abs((d + np.pi) % (2 * np.pi) - np.pi) < tol))


def bottles_at_hand(names: Sequence[str], positions: Sequence[float],
                    bottles: Mapping[str, Sequence[float]]) -> list[str]:
    """Ids of the bottles ((x, y, z) of their centre) within HAND_REACH of the tool at this joint state."""
    q = dict(zip(names, positions))
    tool = rd.dh_fk(np.array([q.get(n, 0.0) for n in rd.JOINT_NAMES]))[-1][:3, 3]
    return sorted(i for i, p in bottles.items() if np.linalg.norm(np.asarray(p, float) - tool) < HAND_REACH)


def final_state(joint_state, objects) -> dict:
    """{'arm_home', 'gripper_empty', 'at_hand'} from a sensor_msgs/JointState and a qtree_relocation_msgs
    ObjectArray (either None: unknown, both False)."""
    if joint_state is None or objects is None:
        return {"arm_home": False, "gripper_empty": False, "at_hand": [], "unknown": True}
    names, pos = list(joint_state.name), list(joint_state.position)
    near = bottles_at_hand(names, pos, {o.id: tuple(o.centre()) for o in msg_to_objects(objects, require_target=False)})
    return {"arm_home": arm_home(names, pos), "gripper_empty": not near, "at_hand": near}
