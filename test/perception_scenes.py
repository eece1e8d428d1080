"""Scenes for the perception tests: generated shelf layouts (seeded), rendered by the project's simulated camera
(jaco2_sim_driver's scene and camera) with, when a test needs them, objects only the simulator knows: boxes and
lying cylinders added to the MJCF by `render_scene` (a test-only helper until the scenario describes shapes), and
the ground truth of what the camera sees (MuJoCo's segmentation rendering)."""
from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass, replace

import numpy as np

from jaco2_sim_driver.camera import CameraRenderer, Frame  # first: the package sets MUJOCO_GL before mujoco loads
from jaco2_sim_driver.scene import CAMERA_NAME, CameraSpec, quat_wxyz, rpy_matrix, scene_assets, scene_xml
from jaco2_sim_driver.sensor_model import SensorModel
from perception_aruco.objects.model import CYLINDER, PerceivedObject
from relocation_common.robot_description import JOINT_NAMES, Q_HOME
from relocation_common.scenario import PALETTE, TARGET_COLOR, TARGET_RGB, Bottle, Scenario


@dataclass(frozen=True)
class Extra:
    """An object only the simulator builds: shape "box" (size sx, sy, sz) or "cylinder" (size 2r, 2r, length),
    lying (a cylinder on its side, axis along yaw) or standing, on the top board at (x, y)."""

    id: str
    shape: str
    x: float
    y: float
    size: tuple[float, float, float]
    yaw: float
    lying: bool
    rgb: tuple[float, float, float]

    @property
    def reach(self) -> float:
        """Radius of the footprint's bounding circle."""
        if self.shape == CYLINDER and not self.lying:
            return self.size[0] / 2
        return math.hypot(self.size[0] if self.shape != CYLINDER else self.size[2], self.size[1]) / 2


def perceived(b: Bottle, x: float, y: float, z: float) -> PerceivedObject:
    """A listed standing cylinder as perception would return it (for the memory and identity tests)."""
    return PerceivedObject(b.id, b.label, b.rgb, b.weight, "", b.is_target, True, CYLINDER, x, y, z, b.radius,
                           b.height, (2 * b.radius, 2 * b.radius, b.height), 0.0, False, False, 0.0, 100, (0, 0))


def with_objects(base: Scenario, bottles) -> Scenario:
    """The base scenario's shelf and markers with these bottles (colours may repeat, any number: the loader's
    limits are the scenario format's, not the simulator's)."""
    return replace(base, auto_slots=True, _by_id={}).with_objects(bottles)


def generated_layout(base: Scenario, seed: int, n: int, min_gap: float = 0.015, radii=(0.025, 0.033, 0.04),
                     heights=(0.12, 0.16, 0.19), colours: list[str] | None = None, taken=()) -> list[Bottle]:
    """n bottles placed at random on the top board (seeded), at least min_gap apart and from `taken` (x, y, reach)
    objects; colours cycle through `colours` (default: the palette); the first one is the target T (green)."""
    rng = np.random.default_rng(seed)
    s = base.shelf
    names = colours or list(PALETTE)
    placed: list[tuple[float, float, float]] = list(taken)
    out: list[Bottle] = []
    for k in range(20000):
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
            out.append(Bottle("T", TARGET_COLOR, TARGET_RGB, 1.0, x, y, r, h, True))
        else:
            c = names[(i - 1) % len(names)]
            out.append(Bottle(f"o{i}", c, PALETTE[c], round(float(rng.uniform(0.1, 1.0)), 2), x, y, r, h))
    if len(out) < n:
        raise ValueError(f"only {len(out)} of {n} bottles fit (seed {seed})")
    return out


def _add_extra(world: ET.Element, e: Extra, z: float) -> None:
    rot = rpy_matrix((0.0, math.pi / 2, e.yaw)) if e.shape == CYLINDER and e.lying else rpy_matrix((0, 0, e.yaw))
    half = e.size[0] / 2 if e.shape == CYLINDER and e.lying else e.size[2] / 2
    body = ET.SubElement(world, "body", name=e.id, pos=f"{e.x} {e.y} {z + half}",
                         quat=" ".join(f"{v:.6g}" for v in quat_wxyz(rot)))
    attrs = dict(name=f"{e.id}_geom", rgba=f"{e.rgb[0]} {e.rgb[1]} {e.rgb[2]} 1", contype="0", conaffinity="0")
    if e.shape == CYLINDER:
        attrs.update(type="cylinder", size=f"{e.size[0] / 2} {e.size[2] / 2}")
    else:
        attrs.update(type="box", size=" ".join(f"{v / 2}" for v in e.size))
    ET.SubElement(body, "geom", attrs)


def build(scenario: Scenario, extras=(), camera: CameraSpec = CameraSpec()):
    """The simulator's scene of `scenario` plus the extra objects (static: the frame is rendered, not simulated)."""
    import mujoco
    root = ET.fromstring(scene_xml(scenario, camera))
    world = root.find("worldbody")
    for e in extras:
        _add_extra(world, e, scenario.shelf.top_z)
    return mujoco.MjModel.from_xml_string(ET.tostring(root, encoding="unicode"), scene_assets(scenario))


def render_scene(scenario: Scenario, extras=(), q=Q_HOME, sensor: SensorModel = SensorModel(), seed: int = 0,
                 camera: CameraSpec = CameraSpec()) -> tuple[Frame, dict[str, int]]:
    """(frame, visible pixels of each object by id) of the scene with the arm at q."""
    import mujoco
    model = build(scenario, extras, camera)
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
    names = [b.id for b in scenario.objects] + [e.id for e in extras]
    return frame, {i: int(np.sum(geoms == model.geom(f"{i}_geom").id)) for i in names}
