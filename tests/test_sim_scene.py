"""The simulated cell: Baxter loads, the object is a physical body on the table, its pose is measured."""
import pybullet
import pytest
from pybullet_utils.bullet_client import BulletClient

from planhrc.robot_sim.perception import angle_difference_deg
from planhrc.robot_sim.errors import SimError
from planhrc.robot_sim.scene import SceneSpec, build_scene, joint_between

pytestmark = pytest.mark.sim


@pytest.fixture(scope="module")
def scene():
    client = BulletClient(connection_mode=pybullet.DIRECT)
    built = build_scene(client, SceneSpec())
    yield built
    built.close()
    client.disconnect()


def _close(a, b, tol=1e-6):
    return all(abs(angle_difference_deg(x, y)) < tol for x, y in zip(a, b))


def test_baxter_loads_with_15_revolute_joints_and_4_finger_joints(scene):
    c = scene.client
    types = [c.getJointInfo(scene.robot, j)[2] for j in range(c.getNumJoints(scene.robot))]
    assert types.count(pybullet.JOINT_REVOLUTE) == 15  # 2 x 7 arm joints + head pan
    assert types.count(pybullet.JOINT_PRISMATIC) == 4  # gripper fingers
    assert set(scene.arms) == {"left", "right"}


def test_the_object_is_one_body_of_links_with_mass_on_revolute_joints(scene):
    c = scene.client
    assert c.getNumJoints(scene.body) == 4
    assert all(c.getJointInfo(scene.body, j)[2] == pybullet.JOINT_REVOLUTE for j in range(4))
    assert all(c.getDynamicsInfo(scene.body, k)[0] == pytest.approx(0.2) for k in range(-1, 4))


def test_set_configuration_is_read_back_from_the_bodies_and_stays_at_rest_under_gravity(scene):
    scene.set_configuration([0, 45, 90, 300, 359.5], base_point_xy=(0.5, 0.3))
    assert _close(scene.link_orientations_deg(), [0, 45, 90, 300, 359.5], 1e-3)
    p = scene.joint_points()
    assert p[1][0] == pytest.approx(0.5 + 0.155) and p[1][1] == pytest.approx(0.3)
    scene.step(120)  # one second of physics: the object lies on the table and does not move by itself
    assert _close(scene.link_orientations_deg(), [0, 45, 90, 300, 359.5], 0.2)
    assert all(abs(scene.link_pose(k)[0][2] - scene.link_center_z) < 2e-3 for k in range(1, 6))


def test_theta_90_points_to_the_robots_right(scene):
    scene.set_configuration([90] * 5, base_point_xy=(0.5, 0.3))
    p = scene.joint_points()
    assert p[1][1] == pytest.approx(0.3 - 0.155)  # clockwise from +x seen from above -> towards -y


def test_links_past_the_far_edge_are_measured_off_the_table(scene):
    scene.set_configuration([90, 90, 0, 0, 0], base_point_xy=(0.6, 0.39))
    assert scene.off_table_links() == (4, 5)


def test_the_default_object_is_centred_and_bad_specs_name_the_field():
    assert SceneSpec(n_links=7).base_xy == (0.6, pytest.approx(7 * 0.155 / 2))
    with pytest.raises(SimError, match="initial_orientations_deg"):
        SceneSpec(n_links=3, initial_orientations_deg=(90.0, 90.0))


def test_joint_between_refuses_links_that_are_not_neighbours():
    assert joint_between(1, 0, 5) == (1, "downstream")
    assert joint_between(2, 3, 5) == (3, "upstream")
    with pytest.raises(SimError, match="held_link_index"):
        joint_between(2, 4, 5)
