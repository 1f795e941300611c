"""The cell's fixed camera and the lines of sight of a bimanual grasp: the camera calibrated from the board on the table
(never told where it is), looked through only for the links the head camera missed (each link said by which camera),
a link no camera sees left unseen; the robot's model of what its arms would hide; and a random bimanual task whose
held pose hid links from the head camera done by the robot alone to the goal."""
import math

import numpy as np
import pybullet
import pytest
from pybullet_utils.bullet_client import BulletClient

from planhrc.robot_sim.acting import measured_pose
from planhrc.robot_sim.bimanual import plan_station
from planhrc.robot_sim.camera import SIM_BOARD, CameraPose
from planhrc.robot_sim.cell_camera import CELL, HEAD, CellCamera, CellCameraSpec, TwoCameras
from planhrc.robot_sim.errors import SimError
from planhrc.robot_sim.perception import CameraPerception, angle_difference_deg
from planhrc.robot_sim.scene import ARMS, HOME_POSE, SceneSpec, build_scene, hold_arm, set_arm_joints
from planhrc.robot_sim.sightlines import SightCamera, Sightlines, Window, gl_matrices
from planhrc.robot_sim.skills import Robot, RotationAction

pytestmark = pytest.mark.sim

STRAIGHT = SceneSpec(n_links=5, board=SIM_BOARD, base_point_xy=(0.6, 0.3875))  # the demo's straight start


@pytest.fixture(scope="module")
def cell():
    client = BulletClient(connection_mode=pybullet.DIRECT)
    scene = build_scene(client, STRAIGHT)
    try:
        head = CameraPerception(client, scene)
        camera = CellCamera(client, scene)
        camera.calibrate()
        yield scene, Robot(scene), head, camera
    finally:
        scene.close()
        client.disconnect()


def _hold(scene, postures):
    for arm in ARMS:
        set_arm_joints(scene, arm, postures[arm])
        hold_arm(scene, arm, postures[arm])


def test_the_cell_camera_finds_where_it_is_from_the_board_and_reads_every_link(cell):
    scene, _, _, camera = cell
    calibration = camera.calibration
    mount = np.asarray(CellCameraSpec().eye)
    assert calibration is not None and len(calibration.markers_used) >= 4
    assert calibration.reprojection_rms_px < 1.0
    assert np.linalg.norm(calibration.pose.position - mount) < 0.01  # found from the board, never told
    seen = camera.perceive()
    assert seen.complete and set(seen.sources) == {CELL}
    errors = [abs(angle_difference_deg(a, b)) for a, b in zip(seen.link_orientations_deg, scene.link_orientations_deg())]
    assert max(errors) < 2.0
    assert math.dist(seen.base_point_xy, scene.base_point()) < 0.01


def test_the_board_leaves_the_table_once_the_camera_is_calibrated_for_a_link_on_it_loses_its_marker():
    client = BulletClient(connection_mode=pybullet.DIRECT)
    # l1 lies across the board's marker at (0.34, 0): the black square around it takes its marker's white border
    scene = build_scene(client, SceneSpec(n_links=5, board=SIM_BOARD, base_point_xy=(0.353, 0.07),
                                          initial_orientations_deg=(90.0, 0.0, 90.0, 90.0, 45.0)))
    try:
        camera = CellCamera(client, scene)
        camera.calibrate()
        assert camera.perceive().missing_links == (1,)
        scene.take_board_away()
        assert not scene.board_bodies and camera.perceive().complete  # the calibration stays
    finally:
        scene.close()
        client.disconnect()


def test_a_cell_camera_without_a_board_on_the_table_is_refused():
    client = BulletClient(connection_mode=pybullet.DIRECT)
    scene = build_scene(client, SceneSpec(n_links=3, load_robot=False))
    try:
        with pytest.raises(SimError, match="board"):
            CellCamera(client, scene)
    finally:
        scene.close()
        client.disconnect()


def test_the_cell_camera_reads_only_the_links_the_head_missed_and_a_link_nobody_sees_stays_unseen(cell):
    scene, robot, head, camera = cell
    # both hands on l4 and l5 where the robot took them before it looked for lines of sight: the arms stand
    # between the head camera and most markers
    station = plan_station(scene, robot, RotationAction(5, 4, 0.0, name="grasplinks"), ("right", "left"))
    _hold(scene, station.down)
    try:
        alone = head.perceive()
        assert not alone.complete  # the held pose hides links from the head
        both = TwoCameras(head, camera)
        seen = both.look()
        assert seen.complete and seen.looks == 2 and both.last_cell_frame is not None
        assert [s for s, v in zip(seen.sources, alone.link_orientations_deg) if v is not None] == \
            [HEAD] * sum(v is not None for v in alone.link_orientations_deg)  # the head's links stay the head's
        assert {seen.sources[k - 1] for k in alone.missing_links} == {CELL}
        errors = [abs(angle_difference_deg(a, b)) for a, b in zip(seen.link_orientations_deg,
                                                                 scene.link_orientations_deg())]
        assert max(errors) < 2.0
        scene.client.changeVisualShape(scene.marker_bodies[1], -1, rgbaColor=[1, 1, 1, 0])  # l2's marker painted over
        try:
            painted = both.look()
        finally:
            scene.client.changeVisualShape(scene.marker_bodies[1], -1, rgbaColor=[1, 1, 1, 1])
        assert painted.missing_links == (2,) and painted.sources[1] is None  # nothing fills it in
        assert painted.looks == 2 + len(head.camera.look_again_pans_rad)  # the head turned to look again too
    finally:
        _hold(scene, HOME_POSE)


def test_a_window_of_a_camera_draws_the_same_pixels_as_the_whole_image(cell):
    scene, _, _, camera = cell
    whole = camera.render().astype(float)
    pose = CameraPose.from_gl_view(camera._view)  # the mount's truth: the image was drawn from there
    window = Window(500.0, 380.0, 200, 120, 1)
    view, projection = gl_matrices(pose, camera.intrinsics, window)
    _, _, rgba, _, _ = scene.client.getCameraImage(window.width, window.height, view, projection,
                                                   renderer=pybullet.ER_TINY_RENDERER)
    part = np.reshape(np.asarray(rgba, dtype=np.uint8), (120, 200, 4))[:, :, :3].astype(float)
    crop = whole[380:500, 500:700]
    assert np.abs(part - crop).mean() < 0.5  # pixel for pixel
    assert np.abs(np.roll(part, 1, axis=1) - crop).mean() > 1.0  # and a pixel off shows


def test_the_robots_model_of_its_lines_of_sight_matches_what_the_cameras_read(cell):
    scene, robot, head, camera = cell
    sight = Sightlines(scene, [SightCamera(HEAD, head.pose, head.intrinsics)])
    pose = measured_pose(scene, scene.link_orientations_deg(), scene.base_point())
    at_home = sight.cover({}, pose)
    assert at_home == (0.0,) * 5 and all(v is not None for v in head.perceive().link_orientations_deg)
    station = plan_station(scene, robot, RotationAction(5, 4, 0.0, name="grasplinks"), ("right", "left"))
    covered = sight.cover(station.down, pose)
    _hold(scene, station.down)
    try:
        read = head.perceive().link_orientations_deg
    finally:
        _hold(scene, HOME_POSE)
    hidden = [k for k, share in enumerate(covered, start=1) if share > 0.3]
    assert hidden and all(read[k - 1] is None for k in hidden)  # what the model says the arms hide, they hide
    assert all(v is not None for v, share in zip(read, covered) if share == 0.0)  # and what it says is clear is read


def test_with_lines_of_sight_the_robot_takes_the_links_where_a_camera_sees_every_marker(cell):
    scene, robot, head, camera = cell
    sight = Sightlines(scene, [SightCamera(HEAD, head.pose, head.intrinsics),
                               SightCamera(CELL, camera.pose, camera.intrinsics)])
    pose = measured_pose(scene, scene.link_orientations_deg(), scene.base_point())
    action = RotationAction(5, 4, 0.0, name="grasplinks")
    station = plan_station(scene, robot, action, ("right", "left"), sight, pose, RotationAction(5, 4, 135.0))
    assert sight.cover(station.down, pose) == (0.0,) * 5
    _hold(scene, station.down)
    try:
        seen = TwoCameras(head, camera).look()
    finally:
        _hold(scene, HOME_POSE)
    assert seen.complete


def test_a_random_bimanual_task_is_done_by_the_robot_alone_with_the_cell_camera(tmp_path):
    from planhrc.robot_sim.demo import DemoScenario, kb_service, run_episode

    # random task 1003 of the demo's generator, kept here with its numbers: without the cell camera and the
    # grasps chosen by lines of sight the held pose hid every marker from the head camera (help: unseen_links)
    scenario = DemoScenario("random-1003", "bimanual", 8, (90.0,) * 5, (90.0, 90.0, 45.0, 135.0, 270.0), "none",
                            "random start and goal, no human", base_point_xy=(0.6, 0.3875))
    with kb_service(tmp_path, "t0ken") as url:
        result = run_episode(url, "t0ken", scenario, tmp_path / "episode", False, "camera", 40, 1003)
    assert result["reached_goal"] and not result["help_reasons"], result["decisions"]
    assert result["unseen_links"] == 0 and result["links_seen_by"].get(CELL, 0) > 0  # the cell camera was needed
    assert set(result["links_seen_by"]) <= {HEAD, CELL}
    assert result["states_off_table"] == 0
