"""Perception processes a frame only when one of its inputs changed (perception_aruco.pipeline.FrameInputs): a frame
of an unchanged scene with an unchanged memory gets the last result again, equal to what processing it would give;
a frame where a bottle moved by 1 mm in the simulator, where the arm's joint state changed or where the memory
changed is processed. The reference is a Perception that processes every frame (its last frame forgotten), fed as
the node feeds it (the fused prior, the scene memory updated with each result)."""
import mujoco
import numpy as np
import pytest

from jaco2_sim_driver.camera import CameraRenderer, Frame  # first: the package sets MUJOCO_GL before mujoco loads
from jaco2_sim_driver.params import CameraSpec
from jaco2_sim_driver.sim import Jaco2Sim
from perception_aruco.pipeline import FrameFusion, Perception, PerceptionResult, SceneMemory
from relocation_common.robot_description import Q_HOME
from relocation_common.scenario import load_scenario

SCENARIO = load_scenario("config/scenarios/scenario3_15.yaml")
Q = np.array([Q_HOME])


@pytest.fixture(scope="module")
def sim():
    s = Jaco2Sim(SCENARIO, camera=CameraSpec.configured())
    s.step(300)
    return s


def frame(sim: Jaco2Sim, renderer: CameraRenderer) -> Frame:
    data = mujoco.MjData(sim.model)
    data.qpos[:] = sim.data.qpos
    mujoco.mj_kinematics(sim.model, data)
    mujoco.mj_camlight(sim.model, data)
    return renderer.render(data)


class Fed:
    """A Perception fed as the node feeds it: the fused camera pose as the prior, the memory updated."""

    def __init__(self, every_frame: bool):
        self.perception, self.every_frame = Perception(SCENARIO), every_frame
        self.memory, self.fusion = SceneMemory(SCENARIO.ids, 3, 2), FrameFusion()

    def __call__(self, f: Frame, q: np.ndarray = Q) -> tuple[PerceptionResult, list]:
        if self.every_frame:
            self.perception._last = None
        r = self.perception.process(f.rgb, f.depth, f.K, self.fusion.fused, self.memory, q)
        assert self.fusion.update(r.T_base_camera) is None
        published, _, _ = self.memory.update(r.objects, r.uncounted, r.reached)
        return r, published


def same(a: tuple[PerceptionResult, list], b: tuple[PerceptionResult, list]) -> bool:
    (ra, pa), (rb, pb) = a, b
    return (ra.objects, ra.missing, ra.notes, ra.uncounted, ra.reached, pa) == \
        (rb.objects, rb.missing, rb.notes, rb.uncounted, rb.reached, pb) and \
        ra.T_base_camera.tobytes() == rb.T_base_camera.tobytes()


def test_an_unchanged_scene_gets_the_last_result_again_equal_to_processing_it(sim):
    renderer = CameraRenderer(sim.model, sim.camera.width, sim.camera.height)
    reusing, every = Fed(False), Fed(True)
    try:
        for k in range(5):
            f = frame(sim, renderer)
            a, b = reusing(f), every(f)
            assert same(a, b), f"frame {k}: the reused result differs from processing the frame"
            sim.step(100)
    finally:
        renderer.close()
    assert renderer.reused == 4 and every.perception.reused == 0 and every.perception.processed == 5
    # the first frame fills the memory (the objects seen, their tracks); from then on it is unchanged
    p = reusing.perception
    assert (p.processed, p.reused) == (2, 3), (p.processed, p.reused)


def test_a_frame_where_a_bottle_moved_1_mm_or_the_arm_state_changed_is_processed_anew(sim):
    m, oid = sim.model, SCENARIO.objects[0].id
    adr = m.jnt_qposadr[m.body_jntadr[m.body(oid).id]]
    renderer = CameraRenderer(sim.model, sim.camera.width, sim.camera.height)
    reusing, every = Fed(False), Fed(True)
    x0 = float(sim.data.qpos[adr])
    results = []
    try:
        for k in range(7):
            if k == 3:
                sim.data.qpos[adr] += 0.001   # the bottle moved 1 mm along x
            f = frame(sim, renderer)
            q = Q + 1e-3 * (k == 6)           # the last frame: the arm's joint state changed, the images did not
            results.append(reusing(f, q))
            assert same(results[-1], every(f, q)), f"frame {k}"
    finally:
        sim.data.qpos[adr] = x0
        renderer.close()
    reused = [results[k][0] is results[k - 1][0] for k in range(1, 7)]
    # frame 3: moved; 4: unchanged, but the memory changed with the moved bottle; 5 unchanged; 6: joint state changed
    assert reused[2:] == [False, False, True, False], reused
    assert results[3][0].objects[oid].x - results[2][0].objects[oid].x == pytest.approx(0.001, abs=5e-4)


def test_a_changed_memory_makes_the_same_frame_processed_anew(sim):
    renderer = CameraRenderer(sim.model, sim.camera.width, sim.camera.height)
    p = Perception(SCENARIO)
    try:
        f = frame(sim, renderer)
    finally:
        renderer.close()
    memory = SceneMemory(SCENARIO.ids, 3, 2)
    first = p.process(f.rgb, f.depth, f.K, None, memory, Q)
    assert p.process(f.rgb, f.depth, f.K, None, memory, Q) is first and (p.processed, p.reused) == (1, 1)
    memory.update(first.objects, first.uncounted, first.reached)
    second = p.process(f.rgb, f.depth, f.K, None, memory, Q)
    assert second is not first and (p.processed, p.reused) == (2, 1)


def test_a_resting_arm_s_joint_states_jittering_in_their_last_bits_are_the_same_pose(sim):
    """The simulator's resting joints differ from state to state in their last bits (1e-25 rad); with byte equality
    every frame of a scene at rest was processed (0.9 of a core at 2 frames/s). Within Q_SAME (1e-9 rad) the pose is
    the same and the frame reused, with the result processing it gives; beyond it, processed anew."""
    renderer = CameraRenderer(sim.model, sim.camera.width, sim.camera.height)
    reusing, every = Fed(False), Fed(True)
    f = frame(sim, renderer)
    renderer.close()
    poses = [Q, Q, np.nextafter(Q, np.inf), Q - 5e-10, Q + 3e-9]
    results = []
    for k, q in enumerate(poses):
        results.append(reusing(f, q))
        assert same(results[-1], every(f, q)), f"frame {k}"
    reused = [results[k][0] is results[k - 1][0] for k in range(2, 5)]   # frame 1 fills the memory (first test)
    assert reused == [True, True, False], reused
