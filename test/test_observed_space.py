"""The observed-space voxel map (perception_aruco/observed_space.py): a known occluder casts a known shadow."""
import math

import numpy as np

from perception_aruco.observed_space import FREE, OCCUPIED, UNOBSERVED, ObservedSpace

F, W = 200.0, 200           # pinhole focal length (px) and image side
PLATE, WALL = 0.5, 1.0      # m along the optical axis: an occluding square plate, the wall behind
HALF = 20                   # px: the plate's half side in the image (0.05 m at 0.5 m)
# the optical frame (z forward, x right, y down) looking along the base's +x from 10 cm above its origin
T_BASE_CAMERA = np.array([[0.0, 0.0, 1.0, 0.0], [-1.0, 0.0, 0.0, 0.0], [0.0, -1.0, 0.0, 0.1], [0.0, 0.0, 0.0, 1.0]])


def _frame() -> tuple[np.ndarray, np.ndarray]:
    K = np.array([[F, 0.0, (W - 1) / 2], [0.0, F, (W - 1) / 2], [0.0, 0.0, 1.0]])
    depth = np.full((W, W), WALL)
    c = (W - 1) / 2
    plate = slice(int(math.ceil(c - HALF)), int(math.floor(c + HALF)) + 1)
    depth[plate, plate] = PLATE
    depth[:5, :] = 0.0     # rows with no return: nothing observed through them
    return depth, K


def test_a_plate_casts_its_shadow_and_the_rest_is_seen():
    space = ObservedSpace(np.array([0.3, -0.2, -0.1]), np.array([1.1, 0.2, 0.3]), 0.02)
    depth, K = _frame()
    space.integrate(depth, K, T_BASE_CAMERA)
    state = space.state.reshape(-1)
    cam = (space.centres - T_BASE_CAMERA[:3, 3]) @ T_BASE_CAMERA[:3, :3]   # voxel centres in the optical frame
    x, y, z = cam[:, 0], cam[:, 1], cam[:, 2]
    spread = np.maximum(np.abs(x), np.abs(y)) / z                         # tan of the angle off the axis
    band = space.voxel * math.sqrt(3) / 2
    in_cone, off_cone = spread < 0.9 * HALF / F, spread > 1.1 * HALF / F
    in_view = (np.abs(x) / z < 0.45) & (np.abs(y) / z < 0.45)           # inside the image, off its top rows
    behind_plate = in_cone & (z > PLATE + band) & (z < WALL - band)
    assert behind_plate.sum() > 50
    assert np.all(state[behind_plate] == UNOBSERVED)                    # the shadow: never observed
    on_plate = in_cone & (np.abs(z - PLATE) < band)
    assert on_plate.sum() > 10
    assert np.all(state[on_plate] == OCCUPIED)                           # where the rays ended
    assert np.all(state[in_cone & (z < PLATE - band)] == FREE)          # in front of the plate: seen through
    beside = off_cone & in_view & (z < WALL - band)
    assert beside.sum() > 500
    assert np.all(state[beside] == FREE)                                 # beside the shadow: seen through
    assert np.all(state[in_view & (z > WALL + band)] == UNOBSERVED)      # behind the wall
    assert np.all(state[y / z < -0.55] == UNOBSERVED)                    # no return: not observed
    # the shadow's volume: the plate's pyramid from PLATE to WALL, within a voxel layer of its surface
    shadow = np.sum((state == UNOBSERVED) & (z < WALL - band) & (z > PLATE + band) & in_view) * space.voxel ** 3
    pyramid = (2 * HALF / F) ** 2 * ((WALL - band) ** 3 - (PLATE + band) ** 3) / 3
    assert abs(shadow - pyramid) < 0.35 * pyramid


def test_a_capsule_and_a_cylinder_cover_their_volume():
    space = ObservedSpace(np.zeros(3), np.full(3, 0.4), 0.005)
    caps = np.zeros(space.shape, bool)
    space.mark_capsules(caps, [(np.array([0.1, 0.2, 0.2]), np.array([0.3, 0.2, 0.2]), 0.04)])
    volume = math.pi * 0.04 ** 2 * 0.2 + 4 / 3 * math.pi * 0.04 ** 3
    assert abs(caps.sum() * space.voxel ** 3 - volume) < 0.05 * volume
    cyl = np.zeros(space.shape, bool)
    pose = np.eye(4)
    pose[:3, :3] = [[0, 0, 1], [0, 1, 0], [-1, 0, 0]]      # axis along the base's x: a lying cylinder
    pose[:3, 3] = (0.2, 0.1, 0.1)
    space.mark_primitive(cyl, pose, "cylinder", (0.06, 0.06, 0.2))
    assert abs(cyl.sum() * space.voxel ** 3 - math.pi * 0.03 ** 2 * 0.2) < 0.1 * math.pi * 0.03 ** 2 * 0.2
    xs = space.centres.reshape(*space.shape, 3)[cyl]
    assert np.ptp(xs[:, 0]) > 0.18 and np.ptp(xs[:, 2]) < 0.065


def test_a_rendered_bottle_shadows_the_space_behind_it():
    """The project's simulated camera (depth along the optical axis, OpenCV optical frame): one bottle on the top
    board; along the camera's ray through its axis, the space past its far side is never observed, its front face is
    occupied; as far from the camera beside it, the space is free."""
    from dataclasses import replace

    from perception_scenes import render_scene

    from relocation_common.paths import default_scenario
    from relocation_common.scenario import load_scenario
    base = load_scenario(default_scenario())
    s = base.shelf
    bottle = replace(base.objects[base.ids.index(base.target_id)], x=s.x_front + 0.12, y=s.y_center)
    frame, _ = render_scene(base.with_objects([bottle]))
    space = ObservedSpace.top_compartment(s, 0.01)
    space.integrate(frame.depth, frame.K, frame.T_base_camera)
    axis = np.array([bottle.x, bottle.y, s.top_z + 0.6 * bottle.height])
    ray = axis - frame.T_base_camera[:3, 3]
    ray /= np.linalg.norm(ray)
    side = np.cross(ray, [0.0, 0.0, 1.0])
    side /= np.linalg.norm(side)
    behind = axis + ray * (bottle.radius + np.array([0.03, 0.05, 0.07]))[:, None]
    beside = behind + side * (bottle.radius + 0.05)
    front = axis - ray * (bottle.radius - 0.003)
    assert np.all(space.state_at(behind) == UNOBSERVED)
    assert np.all(space.state_at(beside) == FREE)
    assert np.all(space.state_at(front) == OCCUPIED)
