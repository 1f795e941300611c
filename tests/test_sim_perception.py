"""Camera perception: every marker is found and gives its link's table angle within 3 degrees."""
import numpy as np
import pybullet
import pytest
from pybullet_utils.bullet_client import BulletClient

from planhrc.robot_sim.perception import CameraPerception, FallbackPerception, angle_difference_deg
from planhrc.robot_sim.scene import SceneSpec, build_scene, random_orientations

pytestmark = pytest.mark.sim


@pytest.fixture(scope="module")
def scene():
    client = BulletClient(connection_mode=pybullet.DIRECT)
    built = build_scene(client, SceneSpec())
    yield built
    built.close()
    client.disconnect()


def test_camera_measures_every_link_within_3_degrees(scene):
    camera = CameraPerception(scene.client, scene)
    rng = np.random.default_rng(7)
    errors = []
    for _ in range(6):
        scene.set_configuration(random_orientations(rng, scene.spec))
        seen = camera.perceive()
        assert seen.complete, f"markers missing for links {seen.missing_links}"
        assert seen.frame.shape == (camera.camera.height, camera.camera.width, 3)
        errors += [abs(angle_difference_deg(a, b)) for a, b in zip(seen.link_orientations_deg, scene.link_orientations_deg())]
    assert max(errors) < 3.0


def test_a_covered_marker_is_reported_missing(scene):
    scene.set_configuration([90] * 5)
    camera = CameraPerception(scene.client, scene)
    scene.client.changeVisualShape(scene.marker_bodies[2], -1, rgbaColor=[1, 1, 1, 0])
    try:
        seen = camera.perceive()
    finally:
        scene.client.changeVisualShape(scene.marker_bodies[2], -1, rgbaColor=[1, 1, 1, 1])
    assert seen.missing_links == (3,)


def test_fallback_adds_seeded_noise(scene):
    scene.set_configuration([10, 20, 30, 40, 50])
    a = FallbackPerception(scene, sigma_deg=1.0, seed=3).perceive().link_orientations_deg
    b = FallbackPerception(scene, sigma_deg=1.0, seed=3).perceive().link_orientations_deg
    assert a == b
    assert a != (10.0, 20.0, 30.0, 40.0, 50.0)
    assert all(abs(angle_difference_deg(x, y)) < 5 for x, y in zip(a, (10, 20, 30, 40, 50)))
