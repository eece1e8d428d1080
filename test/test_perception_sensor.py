"""The simulated camera's motion blur (sensor_model.SensorModel.exposure_s, camera.CameraRenderer.motion_blurred):
what moves during the exposure is smeared, what stands still is not, and perception still places the bottles."""
from __future__ import annotations

import math

import numpy as np

from jaco2_sim_driver.camera import CameraRenderer  # first: sets MUJOCO_GL before mujoco is imported
from jaco2_sim_driver.params import CameraSpec
from jaco2_sim_driver.scene import build_model
from jaco2_sim_driver.sensor_model import SensorModel
from perception_aruco.pipeline import Perception
from relocation_common.paths import resolve_scenario
from relocation_common.robot_description import JOINT_NAMES, Q_HOME
from relocation_common.scenario import load_scenario

import mujoco  # isort: skip  (after jaco2_sim_driver, which sets MUJOCO_GL)


def test_motion_blur_while_the_arm_moves():
    s = load_scenario(resolve_scenario("paper_experiment_10"))
    model = build_model(s, CameraSpec.configured())
    data = mujoco.MjData(model)
    adr = [model.joint(j).qposadr[0] for j in JOINT_NAMES]
    blurred = CameraRenderer(model, 640, 480, sensor=SensorModel(exposure_s=0.02))
    sharp = CameraRenderer(model, 640, 480)
    try:
        def frame(r, t, q):
            data.qpos[adr], data.time = q, t
            mujoco.mj_forward(model, data)
            return r.render(data)
        for r in (blurred, sharp):
            frame(r, 0.0, Q_HOME)
        still = frame(blurred, 0.5, Q_HOME)   # nothing moved: as rendered
        assert np.array_equal(still.rgb, frame(sharp, 0.5, Q_HOME).rgb)
        q = Q_HOME.copy()
        q[0] += 0.4                            # joint 1 at 0.8 rad/s over the last 0.5 s
        a, b = frame(blurred, 1.0, q), frame(sharp, 1.0, q)
        diff = np.abs(a.rgb.astype(int) - b.rgb.astype(int)).max(axis=2)
        moved = diff > 20
        print(f"{moved.sum()} pixels changed by > 20 by the motion blur")
        assert moved.sum() > 500                        # the arm is smeared ...
        assert not moved[:, 520:].any()                 # ... the right of the shelf (no arm there) is not
        res, ref = (Perception(s).process(f.rgb, f.depth, f.K) for f in (a, b))
        errs = [math.dist((d.x, d.y), (s.object(i).x, s.object(i).y)) for i, d in res.detections.items()]
        print(f"found {sorted(res.detections)} (sharp: {sorted(ref.detections)}), max error {max(errs) * 1000:.2f} mm")
        assert set(res.detections) == set(ref.detections) and max(errs) < 0.003
    finally:
        blurred.close()
        sharp.close()
