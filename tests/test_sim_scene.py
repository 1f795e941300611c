"""The simulated cell: Baxter loads, the object is kinematic and turns as the inertial assumption says."""
import pybullet
import pytest
from pybullet_utils.bullet_client import BulletClient

from planhrc.robot_sim.perception import angle_difference_deg
from planhrc.robot_sim.scene import SceneSpec, SimError, build_scene, joint_between

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


def test_set_configuration_is_read_back_from_the_bodies(scene):
    scene.set_configuration([0, 45, 90, 300, 359.5], base_point_xy=(0.5, 0.3))
    assert _close(scene.link_orientations_deg(), [0, 45, 90, 300, 359.5], 1e-3)
    p = scene.joint_points()
    assert p[1][0] == pytest.approx(0.5 + 0.155) and p[1][1] == pytest.approx(0.3)


def test_theta_90_points_to_the_robots_right(scene):
    scene.set_configuration([90] * 5, base_point_xy=(0.5, 0.3))
    p = scene.joint_points()
    assert p[1][1] == pytest.approx(0.3 - 0.155)  # clockwise from +x seen from above -> towards -y


def test_downstream_turn_moves_every_later_link(scene):
    scene.set_configuration([90] * 5, base_point_xy=(0.5, 0.3))
    scene.rotate_at_joint(3, 45, "downstream")
    assert _close(scene.link_orientations_deg(), [90, 90, 135, 135, 135], 1e-3)
    assert scene.base_point() == pytest.approx((0.5, 0.3))


def test_upstream_turn_keeps_the_joint_point_and_moves_the_base(scene):
    scene.set_configuration([90] * 5, base_point_xy=(0.5, 0.3))
    pivot = scene.joint_points()[2].copy()
    scene.rotate_link(turned_link=2, held_link=3, delta_deg=-30, fraction=0.5)
    assert _close(scene.link_orientations_deg(), [75, 75, 90, 90, 90], 1e-3)
    assert scene.joint_points()[2] == pytest.approx(pivot)
    assert scene.base_point() != pytest.approx((0.5, 0.3))


def test_joint_between_refuses_links_that_are_not_neighbours():
    assert joint_between(1, 0, 5) == (1, "downstream")
    assert joint_between(2, 3, 5) == (3, "upstream")
    with pytest.raises(SimError, match="held_link_index"):
        joint_between(2, 4, 5)
