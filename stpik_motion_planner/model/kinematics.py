"""Kinematics of the Jaco2 with Pinocchio: link placements, tool pose and point Jacobians (for Eq. 9-10).

The model is built from `robot_description.urdf()`, so joint angles are Kinova's physical angles Q.
Jacobians are LOCAL_WORLD_ALIGNED: the linear part is the velocity of the frame origin in the base frame.
"""
from __future__ import annotations

import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike

from relocation_common import robot_description as rd


class Kinematics:
    """One Pinocchio model and data; call `update(q)` before reading placements or Jacobians."""

    def __init__(self) -> None:
        self.model = pin.buildModelFromXML(rd.urdf())
        self.data = self.model.createData()
        names = (rd.BASE_LINK,) + rd.LINK_NAMES + (rd.EE_LINK,)
        self.fid = {n: self.model.getFrameId(n) for n in names}
        self.tool_fid = self.fid[rd.EE_LINK]
        self._jac_cache: dict[int, np.ndarray] = {}
        self.q: np.ndarray | None = None
        self._placed_data: object = None  # the pin.Data of _placements
        self._placements: dict[int, pin.SE3] = {}  # frame id -> placement_view

    def update(self, q: ArrayLike, jacobians: bool = True) -> None:
        """Forward kinematics at `q` (rad), with the joint Jacobians unless `jacobians` is False."""
        q = np.asarray(q, dtype=float)
        if jacobians:
            pin.computeJointJacobians(self.model, self.data, q)
            pin.updateFramePlacements(self.model, self.data)
        else:
            pin.framesForwardKinematics(self.model, self.data, q)
        self._jac_cache.clear()
        self.q = q
        if self._placed_data is not self.data:
            self._placed_data, self._placements = self.data, {}

    def placement_view(self, fid: int) -> pin.SE3:
        """pin's view of frame `fid`'s placement in this Data: it follows every update (copy what you keep)."""
        m = self._placements.get(fid)
        if m is None:
            m = self._placements[fid] = self.data.oMf[fid]
        return m

    def placement(self, fid: int) -> tuple[np.ndarray, np.ndarray]:
        """Rotation and translation of frame `fid` in the base frame, after update(q)."""
        m = self.placement_view(fid)
        return m.rotation.copy(), m.translation.copy()

    def tool_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """Rotation and translation of the tool frame in the base frame, after update(q)."""
        return self.placement(self.tool_fid)

    def frame_jacobian(self, fid: int) -> np.ndarray:
        """6 x 7 Jacobian of frame `fid` (linear rows first), after update(q, jacobians=True)."""
        j = self._jac_cache.get(fid)
        if j is None:
            j = pin.getFrameJacobian(self.model, self.data, fid, pin.LOCAL_WORLD_ALIGNED)
            self._jac_cache[fid] = j
        return j

    def point_jacobian(self, fid: int, p_world: np.ndarray) -> np.ndarray:
        """3 x 7 Jacobian of a point rigidly attached to frame `fid`, given in the base frame."""
        j = self.frame_jacobian(fid)
        r = p_world - self.placement_view(fid).translation
        # v_p = v_o + w x r = v_o - r x w
        return j[:3] + _skew_t(r) @ j[3:]


def _skew_t(r: np.ndarray) -> np.ndarray:
    """Matrix S with S @ w = w x r (= -[r]x w)."""
    x, y, z = r
    return np.array([[0.0, z, -y], [-z, 0.0, x], [y, -x, 0.0]])
