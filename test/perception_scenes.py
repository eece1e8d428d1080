"""Scenes for the perception tests: generated shelf layouts (seeded), rendered by the project's simulated camera
(jaco2_sim_driver's scene and camera) with, when a test needs them, objects the scenario perception gets does not
list (the simulator's `unlisted`: bottles, jars, boxes, lying cylinders), and the ground truth of what the camera
sees (MuJoCo's segmentation rendering)."""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from jaco2_sim_driver.camera import CameraRenderer, Frame  # first: the package sets MUJOCO_GL before mujoco loads
from jaco2_sim_driver.params import CameraSpec
from jaco2_sim_driver.scene import CAMERA_NAME, build_model
from jaco2_sim_driver.sensor_model import SensorModel
from perception_aruco.objects.model import CYLINDER, PerceivedObject
from relocation_common.robot_description import JOINT_NAMES, Q_HOME
from relocation_common.scenario import PALETTE, TARGET_COLOR, TARGET_RGB, Scenario, ShelfObject


def perceived(b: ShelfObject, x: float, y: float, z: float) -> PerceivedObject:
    """A listed standing cylinder as perception would return it (for the memory and identity tests)."""
    return PerceivedObject(b.id, b.label, b.rgb, b.weight, "", b.is_target, True, CYLINDER, x, y, z, b.radius,
                           b.height, (2 * b.radius, 2 * b.radius, b.height), 0.0, False, False, 0.0, 100, (0, 0))


def extra(base: Scenario, oid: str, shape: str, x: float, y: float, size: tuple[float, float, float], yaw: float,
          lying: bool, rgb: tuple[float, float, float], listed: bool = False) -> ShelfObject:
    """An object on the top board: a box of `size`, or a cylinder (size 2r, 2r, length) standing or lying along
    `yaw`; unlisted unless `listed` (weight 0.3: the simulator's mass, perception estimates its own)."""
    r = size[0] / 2 if shape == CYLINDER else 0.0
    return ShelfObject(oid, "", rgb, 0.3, x, y, r, size[2] if shape == CYLINDER else size[2], False, shape, size, yaw,
                       lying, listed, "", base.shelf.top_z)


def reach(o: ShelfObject) -> float:
    """Radius of an object's footprint's bounding circle."""
    if o.shape == CYLINDER and not o.lying:
        return o.radius
    return math.hypot(o.size[2] if o.shape == CYLINDER else o.size[0], o.size[1]) / 2


def with_objects(base: Scenario, objects, unlisted=()) -> Scenario:
    """The base scenario's shelf and markers with these objects (colours may repeat, any number) and, for the
    simulator only, the `unlisted` ones."""
    return replace(base, auto_slots=True, unlisted=tuple(unlisted), _by_id={}).with_objects(objects)


def generated_layout(base: Scenario, seed: int, n: int, min_gap: float = 0.015, radii=(0.025, 0.033, 0.04),
                     heights=(0.12, 0.16, 0.19), colours: list[str] | None = None, taken=()) -> list[ShelfObject]:
    """n bottles placed at random on the top board (seeded), at least min_gap apart and from `taken` (x, y, reach)
    objects; colours cycle through `colours` (default: the palette); the first one is the target T (green)."""
    rng = np.random.default_rng(seed)
    s = base.shelf
    names = colours or list(PALETTE)
    placed: list[tuple[float, float, float]] = list(taken)
    out: list[ShelfObject] = []
    for _ in range(20000):
        if len(out) == n:
            break
        r, h = float(rng.choice(radii)), float(rng.choice(heights))
        x = float(rng.uniform(s.x_front + r + 0.01, s.x_back - r - 0.01))
        y = float(rng.uniform(s.y_min + r + 0.01, s.y_max - r - 0.01))
        if any(math.hypot(x - px, y - py) < r + pr + min_gap for px, py, pr in placed):
            continue
        placed.append((x, y, r))
        i = len(out)
        if i == 0:
            out.append(ShelfObject("T", TARGET_COLOR, TARGET_RGB, 1.0, x, y, r, h, True, support_z=s.top_z))
        else:
            c = names[(i - 1) % len(names)]
            out.append(ShelfObject(f"o{i}", c, PALETTE[c], round(float(rng.uniform(0.1, 1.0)), 2), x, y, r, h,
                                   support_z=s.top_z))
    if len(out) < n:
        raise ValueError(f"only {len(out)} of {n} bottles fit (seed {seed})")
    return out


def render_scene(scenario: Scenario, q=Q_HOME, sensor: SensorModel = SensorModel(), seed: int = 0,
                 camera: CameraSpec | None = None) -> tuple[Frame, dict[str, int]]:
    """(frame, visible pixels of every object the simulator builds, by id) with the arm at q."""
    import mujoco
    camera = camera or CameraSpec.configured()
    model = build_model(scenario, camera)
    data = mujoco.MjData(model)
    for j, qj in zip(JOINT_NAMES, np.asarray(q, float)):
        data.qpos[model.joint(j).qposadr[0]] = qj
    mujoco.mj_forward(model, data)
    r = CameraRenderer(model, camera.width, camera.height, sensor=sensor, seed=seed)
    seg = mujoco.Renderer(model, camera.height, camera.width)
    try:
        frame = r.render(data)
        seg.enable_segmentation_rendering()
        seg.update_scene(data, camera=CAMERA_NAME)
        ids = seg.render()
    finally:
        r.close()
        seg.close()
    geoms = ids[:, :, 0][ids[:, :, 1] == int(mujoco.mjtObj.mjOBJ_GEOM)]
    return frame, {o.id: int(np.sum(geoms == model.geom(f"{o.id}_geom").id)) for o in scenario.world}
