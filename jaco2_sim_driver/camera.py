"""Offscreen RGB-D camera of the scene (no ROS): images, pinhole intrinsics and the camera pose in the base frame.

Rendering is headless with MUJOCO_GL=egl (set by the package's __init__ before mujoco is imported). An OpenGL
context belongs to the thread that made it: create a CameraRenderer in the thread that renders.
Depth is the planar (z) distance in metres along the optical axis, as a RealSense publishes it; pixels with no
surface within the far plane are 0 (invalid).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco  # MUJOCO_GL (headless rendering) is set by the package's __init__, imported first
import numpy as np
from numpy.typing import ArrayLike

from relocation_common.robot_description import JOINT_NAMES, Q_HOME
from relocation_common.scenario import Scenario

from .params import CameraSpec
from .scene import CAMERA_NAME, build_model
from .sensor_model import SensorModel, SensorSimulator

# MuJoCo camera frame (x right, y up, looking along -z) -> OpenCV optical frame (x right, y down, z forward)
MJ_TO_OPTICAL = np.diag([1.0, -1.0, -1.0])
# what OpenGL draws of an mjvScene (its geoms, lights and cameras): `scene_key`
_GEOM_FIELDS = ("type", "dataid", "objtype", "objid", "category", "matid", "texcoord", "segid", "size", "pos", "mat",
                "rgba", "emission", "specular", "shininess", "reflectance", "transparent", "camdist", "modelrbound")
_LIGHT_FIELDS = ("type", "texid", "headlight", "castshadow", "pos", "dir", "attenuation", "cutoff", "exponent",
                 "ambient", "diffuse", "specular", "bulbradius", "intensity", "range")
_CAMERA_FIELDS = ("pos", "forward", "up", "frustum_center", "frustum_width", "frustum_bottom", "frustum_top",
                  "frustum_near", "frustum_far", "orthographic")


def scene_key(scene: mujoco.MjvScene) -> bytes:
    """The inputs of an OpenGL render of `scene` (mjv_updateScene's output: every geom's, light's and camera's
    single-precision values) as bytes: two scenes with the same key render the same pixels (same model, renderer
    and options). The simulation's resting bodies jitter in the last bits of their double-precision state (1e-25 of
    a quaternion component): below what mjv_updateScene's floats keep. Under 1 ms for the 40 geoms of a scene."""
    parts = [np.array([scene.ngeom, scene.nlight], np.float64)]
    for items, fields in ((scene.geoms[:scene.ngeom], _GEOM_FIELDS), (scene.lights[:scene.nlight], _LIGHT_FIELDS),
                          (scene.camera, _CAMERA_FIELDS)):
        parts += [np.asarray(getattr(item, f), np.float64).ravel() for item in items for f in fields]
    return np.concatenate(parts).tobytes()


@dataclass(frozen=True)
class Frame:
    """One RGB-D frame. rgb: HxWx3 uint8; depth: HxW float32 metres (0 = no return); K: 3x3 pinhole matrix;
    T_base_camera: 4x4 pose of the optical frame (OpenCV: z forward, x right, y down) in the base frame;
    stamp: simulated time (s); wall: the wall-clock time (s, time.time()) of the state it shows (None: not known)."""

    rgb: np.ndarray
    depth: np.ndarray
    K: np.ndarray
    T_base_camera: np.ndarray
    stamp: float = 0.0
    wall: float | None = None

    @property
    def width(self) -> int:
        """Image width (px)."""
        return int(self.rgb.shape[1])

    @property
    def height(self) -> int:
        """Image height (px)."""
        return int(self.rgb.shape[0])

    @property
    def fx(self) -> float:
        """Focal length x (px)."""
        return float(self.K[0, 0])

    @property
    def fy(self) -> float:
        """Focal length y (px)."""
        return float(self.K[1, 1])

    @property
    def cx(self) -> float:
        """Principal point x (px)."""
        return float(self.K[0, 2])

    @property
    def cy(self) -> float:
        """Principal point y (px)."""
        return float(self.K[1, 2])


def intrinsics(fovy_deg: float, width: int, height: int) -> np.ndarray:
    """Pinhole matrix of a MuJoCo camera: square pixels, fy = (h/2) / tan(fovy/2), principal point at the image
    centre in OpenCV pixel coordinates (pixel centres at integers)."""
    f = 0.5 * height / math.tan(math.radians(fovy_deg) / 2)
    return np.array([[f, 0.0, (width - 1) / 2], [0.0, f, (height - 1) / 2], [0.0, 0.0, 1.0]])


class CameraRenderer:
    """Renders the named camera of a model from an MjData (its own GL context; use from one thread). `sensor`: what
    the images go through after rendering (sensor_model.SensorModel, e.g. `SensorModel.named("realsense_d435")`;
    default: none, the ideal camera); `seed` seeds its noise. A frame whose scene renders as the last one did (same
    `scene_key`: nothing the camera sees moved) is not rendered again: the last render's images are taken (`reused`
    counts them; `renders` the frames rendered) and go through the sensor model as a new render would, its noise
    drawn anew for each frame as before."""

    def __init__(self, model: mujoco.MjModel, width: int, height: int, camera: str = CAMERA_NAME,
                 sensor: SensorModel = SensorModel(), seed: int = 0):
        self.model, self.camera = model, camera
        self.sensor = SensorSimulator(sensor, seed)
        self._cam = model.camera(camera).id
        self._renderer = mujoco.Renderer(model, height, width)
        self.K = intrinsics(float(model.cam_fovy[self._cam]), width, height)
        self.zfar = float(model.vis.map.zfar * model.stat.extent)
        self._previous: tuple[float, np.ndarray] | None = None   # (time, qpos) of the last frame: motion blur
        self._scratch = mujoco.MjData(model)
        self._last: tuple[bytes, np.ndarray, np.ndarray] | None = None  # (scene_key, rgb, depth) of the last render
        self.renders = self.reused = 0

    def camera_pose(self, data: mujoco.MjData) -> np.ndarray:
        """T_base_camera: the optical frame (OpenCV) in the base frame."""
        t = np.eye(4)
        t[:3, :3] = data.cam_xmat[self._cam].reshape(3, 3) @ MJ_TO_OPTICAL
        t[:3, 3] = data.cam_xpos[self._cam]
        return t

    def motion_blurred(self, data: mujoco.MjData, rgb: np.ndarray, subframes: int = 3) -> np.ndarray:
        """The colour image as a camera exposing for `exposure_s` sees it while things move: the mean of sub-frames
        rendered back over the exposure, the velocities taken from the previous frame's positions (the driver
        copies positions only); unchanged when nothing moved faster than 0.02 rad/s or m/s. Costs subframes - 1
        extra renders per frame while something moves (the driver renders in software, about 75 ms each)."""
        exposure, previous = self.sensor.model.exposure_s, self._previous
        self._previous = (float(data.time), data.qpos.copy())
        if exposure <= 0 or previous is None or not data.time > previous[0]:
            return rgb
        qvel = np.zeros(self.model.nv)
        mujoco.mj_differentiatePos(self.model, qvel, float(data.time) - previous[0], previous[1], data.qpos)
        if np.max(np.abs(qvel)) < 0.02:
            return rgb
        acc, s = rgb.astype(np.float32), self._scratch
        for k in range(1, subframes):
            s.qpos[:] = data.qpos
            mujoco.mj_integratePos(self.model, s.qpos, qvel, -exposure * k / (subframes - 1))
            mujoco.mj_kinematics(self.model, s)
            mujoco.mj_camlight(self.model, s)
            self._renderer.update_scene(s, camera=self.camera)
            acc += self._renderer.render()
        return np.round(acc / subframes).astype(np.uint8)

    def render(self, data: mujoco.MjData) -> Frame:
        """One frame of `data` (through the sensor model); the last render's images again when its scene is the
        same (class docstring)."""
        rgb, depth = self._clean(data)
        rgb, depth = self.sensor.apply(self.motion_blurred(data, rgb), depth)
        return Frame(rgb, depth, self.K.copy(), self.camera_pose(data), float(data.time))

    def _clean(self, data: mujoco.MjData) -> tuple[np.ndarray, np.ndarray]:
        """(rgb, depth) as rendered, before the sensor model: copies of the last render's when the scene's key is
        unchanged."""
        r = self._renderer
        r.update_scene(data, camera=self.camera)
        key = scene_key(r.scene)
        if self._last is not None and self._last[0] == key:
            self.reused += 1
            return self._last[1].copy(), self._last[2].copy()
        rgb = r.render().copy()
        r.enable_depth_rendering()
        try:
            depth = r.render().astype(np.float32)
        finally:
            r.disable_depth_rendering()
        depth[depth >= 0.999 * self.zfar] = 0.0
        self._last = (key, rgb.copy(), depth.copy())
        self.renders += 1
        return rgb, depth

    def close(self) -> None:
        """Release the GL context."""
        self._renderer.close()


def _posed(scenario: Scenario, q: ArrayLike, camera: CameraSpec) -> tuple[mujoco.MjModel, mujoco.MjData]:
    """The scenario's world at its initial state with the arm at q (forward kinematics only)."""
    model = build_model(scenario, camera)
    data = mujoco.MjData(model)
    for j, qj in zip(JOINT_NAMES, np.asarray(q, float)):
        data.qpos[model.joint(j).qposadr[0]] = qj
    mujoco.mj_forward(model, data)
    return model, data


def render_frame(scenario: Scenario, q: ArrayLike = Q_HOME, camera: CameraSpec | None = None,
                 sensor: SensorModel = SensorModel(), seed: int = 0) -> Frame:
    """One frame of a scenario at its initial state with the arm at q (no simulation, no ROS): for perception;
    `camera` None: the driver's (CameraSpec.configured()); `sensor` / `seed` as in CameraRenderer."""
    camera = camera if camera is not None else CameraSpec.configured()
    model, data = _posed(scenario, q, camera)
    r = CameraRenderer(model, camera.width, camera.height, sensor=sensor, seed=seed)
    try:
        return r.render(data)
    finally:
        r.close()


def visible_pixels(scenario: Scenario, q: ArrayLike = Q_HOME, camera: CameraSpec | None = None) -> dict[str, int]:
    """Pixels of each object of the scenario's world (listed and unlisted) in the camera's image at its initial
    state with the arm at q (MuJoCo's segmentation rendering): 0 for an object the camera cannot see."""
    camera = camera if camera is not None else CameraSpec.configured()
    model, data = _posed(scenario, q, camera)
    r = mujoco.Renderer(model, camera.height, camera.width)
    try:
        r.enable_segmentation_rendering()
        r.update_scene(data, camera=CAMERA_NAME)
        seg = r.render()
    finally:
        r.close()
    geoms = np.where(seg[:, :, 1] == int(mujoco.mjtObj.mjOBJ_GEOM), seg[:, :, 0], -1)
    return {o.id: int((geoms == model.geom(f"{o.id}_geom").id).sum()) for o in scenario.world}
