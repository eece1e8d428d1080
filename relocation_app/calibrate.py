"""`./run calibrate`: the camera's and the shelf marker's pose in the robot base frame, measured with the robot
(docs/perception.md, "Calibration to the robot"; the math is perception_aruco.calibration).

The arm carries the calibration marker on its hand (robot_description.T_TOOL_GRIPPER_MARKER) and is put at
CALIBRATION_POSES; at each the camera's image gives the marker's pose in the camera and the forward kinematics the
hand's pose in the base frame; the hand-eye solution gives the camera in the base frame, and the shelf markers
seen by the same camera then have their poses in the base frame. The result goes to a calibration file (default
out/calibration.yaml) that perception reads (its parameter `calibration_file`).

The arm is moved in the simulator core (jaco2_sim_driver: joint positions set, the scene rendered through the
driver's camera model), not through the node graph: the images and joint angles are those the driver would
publish at these poses, without the minutes of a graph run.
"""
from __future__ import annotations

import argparse
import math
import sys
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from jaco2_sim_driver.camera import CameraRenderer  # first: sets MUJOCO_GL before mujoco is imported
from jaco2_sim_driver.params import CameraSpec
from jaco2_sim_driver.scene import build_model, hand_marker
from jaco2_sim_driver.sensor_model import CAMERA_MODELS, SensorModel
from perception_aruco.aruco import MarkerLocalizer, MarkerParams, PerceptionError, marker_in_base
from perception_aruco.calibration import HandEye, marker_in_base_from, save_calibration, solve_hand_eye
from relocation_common.geometry import mean_pose, pose_error
from relocation_common.paths import default_scenario, resolve_scenario
from relocation_common.robot_description import BASE_LINK, JOINT_NAMES, dh_fk
from relocation_common.scenario import Marker, Scenario, load_scenario

import mujoco  # isort: skip  (after jaco2_sim_driver, which sets MUJOCO_GL)

# Joint angles Q (rad): the hand between the robot and the shelf, 0.2-0.5 m from the default camera, the marker
# facing it within 40 deg, rotations 26-43 deg apart from one another (hand-eye needs varied rotation axes); no
# contact with the shelf, bottles or floor in any shipped scene (checked by test/test_calibration.py).
CALIBRATION_POSES = (
    (3.37, 3.35, -0.50, 5.48, 3.17, 1.50, -1.05),
    (3.67, 3.40, -0.09, 5.40, 4.57, 1.89, 0.01),
    (2.89, 3.10, 0.18, 5.61, 3.85, 2.06, -1.30),
    (3.16, 3.57, -0.15, 5.75, 3.97, 2.44, -0.53),
    (3.52, 3.65, -0.16, 5.43, 3.69, 2.14, -1.33),
    (3.21, 3.22, -0.49, 5.68, 3.10, 2.23, -0.98),
    (3.48, 3.31, -0.09, 5.34, 3.75, 1.67, -1.33),
    (3.58, 3.46, -0.09, 5.18, 3.81, 2.05, -0.44),
    (3.20, 3.34, -0.50, 5.31, 4.07, 2.06, -1.05),
    (3.50, 3.38, 0.23, 5.70, 4.11, 2.02, -0.55),
    (3.09, 3.47, -0.15, 5.66, 4.49, 2.25, -0.77),
)


@dataclass(frozen=True)
class Calibration:
    """What `calibrate` measured: the shelf markers with their poses in the base frame (those seen), the hand-eye
    solution, the arm poses at which the hand's marker was not usable (index: reason) and how many arm poses
    showed each shelf marker (id: count)."""

    markers: tuple[Marker, ...]
    hand_eye: HandEye
    skipped: dict[int, str]
    shelf_views: dict[int, int]


class SimArm:
    """The simulator core's scene with the calibration marker on the hand: joint positions set, frames rendered
    through the camera model (the driver's camera, CameraSpec and SensorModel as in its parameters)."""

    def __init__(self, scenario: Scenario, camera: CameraSpec | None = None, sensor: SensorModel = SensorModel(),
                 seed: int = 0):
        camera = camera if camera is not None else CameraSpec.configured()
        self.model = build_model(scenario, camera, gripper_marker=True)
        self.data = mujoco.MjData(self.model)
        self._camera, self._sensor, self._seed = camera, sensor, seed
        self._renderer: CameraRenderer | None = None   # made by the first frame (in the thread that renders)
        self._adr = [self.model.joint(j).qposadr[0] for j in JOINT_NAMES]

    def move(self, q) -> list[str]:
        """Put the arm at q (forward kinematics only); the names of the geoms the arm then touches."""
        self.data.qpos[self._adr] = np.asarray(q, float)
        mujoco.mj_forward(self.model, self.data)
        m = self.model
        arm = m.body(BASE_LINK).id
        on_arm = [m.body_rootid[m.geom_bodyid[g]] == arm for g in range(m.ngeom)]
        return sorted({m.geom(g).name for c in self.data.contact[:self.data.ncon] if on_arm[c.geom1] or on_arm[c.geom2]
                       for g in (c.geom1, c.geom2)})

    def frame(self):
        """One RGB-D frame (jaco2_sim_driver.camera.Frame) at the current pose."""
        if self._renderer is None:
            c = self._camera
            self._renderer = CameraRenderer(self.model, c.width, c.height, sensor=self._sensor, seed=self._seed)
        return self._renderer.render(self.data)

    def close(self) -> None:
        """Release the renderer."""
        if self._renderer is not None:
            self._renderer.close()


def _observe(localizer: MarkerLocalizer, frames) -> np.ndarray | str:
    """The marker's mean pose in the camera over frames of one arm pose (depth-refined, no corner dropped), or
    why it is not usable."""
    seen = []
    for f in frames:
        try:
            obs = localizer.locate(f.rgb, f.K, f.depth)
        except PerceptionError as e:
            return str(e)
        if not obs.refined or obs.dropped:
            return "no depth on the marker, or a corner covered"
        seen.append(obs.T_camera_marker)
    return mean_pose(seen)


def calibrate(scenario: Scenario, arm: SimArm, poses=CALIBRATION_POSES, frames_per_pose: int = 3) -> Calibration:
    """Observe the hand's marker at `poses` (the mean over `frames_per_pose` frames at each) and the shelf markers
    in the same frames; solve (module docstring). Raises perception_aruco.calibration.CalibrationError (too few
    poses seen, observations that disagree, the main shelf marker never seen; a further one never seen keeps its
    scenario pose)."""
    contour = MarkerParams(corner_refinement="contour")  # the marker's in-plane rotation to 0.05 deg (aruco.py)
    hand = MarkerLocalizer(hand_marker(), params=contour)
    shelf = [MarkerLocalizer(m, params=contour) for m in scenario.markers]
    gripper, seen, skipped = [], [], {}
    shelf_seen: list[list[np.ndarray]] = [[] for _ in shelf]
    for i, q in enumerate(poses):
        touching = arm.move(q)
        if touching:
            skipped[i] = f"the arm would touch {', '.join(touching)}"
            continue
        frames = [arm.frame() for _ in range(frames_per_pose)]
        obs = _observe(hand, frames)
        if isinstance(obs, str):
            skipped[i] = obs
            continue
        gripper.append(dh_fk(q)[-1])  # the tool frame: the hand pose the robot reports
        seen.append(obs)
        for loc, views in zip(shelf, shelf_seen):
            obs = _observe(loc, frames)
            if not isinstance(obs, str):  # else the arm covers this marker here: the other poses show it
                views.append(obs)
    hand_eye = solve_hand_eye(gripper, seen)
    markers = tuple(marker_in_base_from(hand_eye, m, views) for k, (m, views) in enumerate(zip(scenario.markers,
                                                                                           shelf_seen))
                    if k == 0 or views)
    return Calibration(markers, hand_eye, skipped, {m.id: len(v) for m, v in zip(scenario.markers, shelf_seen)})


def _args(argv):
    p = argparse.ArgumentParser(prog="./run calibrate", description=__doc__.splitlines()[0])
    p.add_argument("--scenario", default=str(default_scenario()),
                   help="scenario YAML, or a name under config/scenarios (the scene the simulator renders)")
    p.add_argument("--camera-model", choices=CAMERA_MODELS, default="ideal",
                   help="the simulated camera (the driver's camera_model)")
    p.add_argument("--frames", type=int, default=3, help="frames averaged at each arm pose (default 3)")
    p.add_argument("--out", default="out/calibration.yaml", help="calibration file to write")
    return p.parse_args(argv)


def run(argv=None) -> int:
    """Calibrate, write the file, print what was measured; 0 on success, 1 with the reason on failure."""
    a = _args(argv)
    path = resolve_scenario(a.scenario)
    scenario = load_scenario(path)
    arm = SimArm(scenario, sensor=SensorModel.named(a.camera_model))
    try:
        cal = calibrate(scenario, arm, frames_per_pose=max(1, a.frames))
    except PerceptionError as e:
        print(f"[calibrate] {e}", file=sys.stderr)
        return 1
    finally:
        arm.close()
    he = cal.hand_eye
    for i, why in cal.skipped.items():
        print(f"[calibrate] pose {i} not used: {why}")
    print(f"[calibrate] {he.poses} arm poses, hand-eye residual {he.residual_mm:.2f} mm, {he.residual_deg:.3f} deg "
          f"rms; shelf markers seen at {cal.shelf_views} arm poses (id: count)")
    for m, given in zip(cal.markers, [s for s in scenario.markers if s.id in {c.id for c in cal.markers}]):
        dt, dr = pose_error(marker_in_base(m), marker_in_base(given))
        print(f"[calibrate] shelf marker id {m.id} at {np.round(m.position, 4).tolist()} m: {dt * 1000:.1f} mm, "
              f"{math.degrees(dr):.2f} deg from the scenario's pose")
    out = Path(a.out)
    note = (f"./run calibrate --scenario {path.name} --camera-model {a.camera_model} --frames {a.frames}, "
            f"{datetime.now(timezone.utc):%Y-%m-%d %H:%M} UTC")
    save_calibration(out, cal.markers, he, note)
    print(f"[calibrate] wrote {out} (perception: -p calibration_file:={out.resolve()})")
    return 0


def main(argv=None) -> None:
    """Console entry point."""
    sys.exit(run(argv))


if __name__ == "__main__":
    main()
