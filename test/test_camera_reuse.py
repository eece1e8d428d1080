"""The simulated camera renders a frame only when something it sees moved (jaco2_sim_driver.camera.CameraRenderer):
an unchanged scene's frame is the last render again, bit for bit what a render would give; a frame where a bottle
moved by 1 mm or a joint by 1e-4 rad is rendered anew. Each frame is checked against a renderer of its own that
has rendered nothing before (no cache to take from)."""
import mujoco
import numpy as np
import pytest

from jaco2_sim_driver.camera import CameraRenderer
from jaco2_sim_driver.params import CameraSpec
from jaco2_sim_driver.sensor_model import SensorModel
from jaco2_sim_driver.sim import Jaco2Sim
from relocation_common.paths import default_scenario
from relocation_common.scenario import load_scenario

SCENARIO = load_scenario(default_scenario())


@pytest.fixture(scope="module")
def sim():
    return Jaco2Sim(SCENARIO, camera=CameraSpec.configured())


@pytest.fixture
def fresh(sim):
    sim.reset()
    sim.step(300)   # the bottles settled: from here on they jitter in the last bits of their state only
    return sim


def posed(sim: Jaco2Sim) -> mujoco.MjData:
    """A copy of the simulation's positions, posed as the driver's camera loop poses it."""
    data = mujoco.MjData(sim.model)
    data.qpos[:] = sim.data.qpos
    data.time = sim.data.time
    mujoco.mj_kinematics(sim.model, data)
    mujoco.mj_camlight(sim.model, data)
    return data


def renderer(sim: Jaco2Sim, sensor: SensorModel = SensorModel()) -> CameraRenderer:
    return CameraRenderer(sim.model, sim.camera.width, sim.camera.height, sensor=sensor)


def rendered_anew(sim: Jaco2Sim, data: mujoco.MjData) -> tuple[np.ndarray, np.ndarray]:
    """(rgb, depth) of a renderer that never rendered before (the ideal camera)."""
    r = renderer(sim)
    try:
        f = r.render(data)
    finally:
        r.close()
    assert r.renders == 1 and r.reused == 0
    return f.rgb, f.depth


def same(a: tuple[np.ndarray, np.ndarray], b: tuple[np.ndarray, np.ndarray]) -> bool:
    return a[0].tobytes() == b[0].tobytes() and a[1].tobytes() == b[1].tobytes()


def test_an_unchanged_scene_is_not_rendered_again_and_its_frame_is_the_same(fresh):
    r = renderer(fresh)
    try:
        first = r.render(posed(fresh))
        q0 = fresh.data.qpos.copy()
        fresh.step(200)   # the physics runs on: nothing moves but the last bits of the resting bottles' state
        assert not np.array_equal(fresh.data.qpos, q0) and np.max(np.abs(fresh.data.qpos - q0)) < 1e-12
        data = posed(fresh)
        second = r.render(data)
    finally:
        r.close()
    assert (r.renders, r.reused) == (1, 1)
    assert second.stamp == pytest.approx(fresh.time) and second.stamp > first.stamp
    assert same((second.rgb, second.depth), (first.rgb, first.depth))
    assert same((second.rgb, second.depth), rendered_anew(fresh, data))


@pytest.mark.parametrize("what", ["bottle moved 1 mm", "joint turned 1e-4 rad"])
def test_a_frame_where_anything_moved_is_rendered_anew(fresh, what):
    m = fresh.model
    r = renderer(fresh)
    try:
        first = r.render(posed(fresh))
        if what.startswith("bottle"):
            body = m.body(SCENARIO.objects[0].id).id
            fresh.data.qpos[m.jnt_qposadr[m.body_jntadr[body]]] += 0.001   # x of its free joint
        else:
            fresh.data.qpos[fresh._qadr[5]] += 1e-4
        data = posed(fresh)
        second = r.render(data)
    finally:
        r.close()
    assert (r.renders, r.reused) == (2, 0), what
    assert not same((second.rgb, second.depth), (first.rgb, first.depth)), f"{what}: the frame did not change"
    assert same((second.rgb, second.depth), rendered_anew(fresh, data))


def test_the_realistic_camera_draws_its_noise_anew_on_a_reused_render(fresh):
    """camera_model realsense_d435: the noise, holes and drift of each frame are those a render every frame gave
    (same seed, same draws), different from frame to frame; the clean render under them is reused."""
    d435 = SensorModel.named("realsense_d435")
    reusing, every = renderer(fresh, d435), renderer(fresh, d435)
    frames = []
    try:
        for _ in range(3):
            data = posed(fresh)
            every._last = None   # the reference renders every frame
            frames.append((reusing.render(data), every.render(data)))
            fresh.step(100)
    finally:
        reusing.close()
        every.close()
    assert (reusing.renders, reusing.reused) == (1, 2) and (every.renders, every.reused) == (3, 0)
    for a, b in frames:
        assert same((a.rgb, a.depth), (b.rgb, b.depth))
    assert not same((frames[0][0].rgb, frames[0][0].depth), (frames[1][0].rgb, frames[1][0].depth))
