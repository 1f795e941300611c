"""Rotation skills: a reachable action succeeds, an unreachable one fails, a stopped one is partial."""
import pybullet
import pytest
from pybullet_utils.bullet_client import BulletClient

from planhrc.robot_sim.perception import angle_difference_deg
from planhrc.robot_sim.scene import SceneSpec, build_scene, set_arm_joints
from planhrc.robot_sim.skills import Grip, MoveArm, Outcome, Robot, RotateObject, RotationAction, execute, perform_action, rotate_skill

pytestmark = pytest.mark.sim


@pytest.fixture(scope="module")
def cell():
    client = BulletClient(connection_mode=pybullet.DIRECT)
    scene = build_scene(client, SceneSpec())
    yield scene, Robot(scene)
    scene.close()
    client.disconnect()


@pytest.fixture
def scene(cell):
    scene, _ = cell
    scene.set_configuration([90] * 5, base_point_xy=scene.spec.base_point_xy)
    return scene


@pytest.fixture
def robot(cell):
    return cell[1]


def _close(a, b, tol=1e-3):
    return all(abs(angle_difference_deg(x, y)) < tol for x, y in zip(a, b))


def test_rotation_reaches_the_expected_configuration(scene, robot):
    command = rotate_skill(scene, robot, RotationAction(turned_link=3, held_link=2, delta_deg=45))
    assert command is not None
    kinds = [type(p) for p in command.primitives]
    assert kinds.count(Grip) == 4 and MoveArm in kinds and kinds.count(RotateObject) == 9
    assert execute(scene, command, robot) is Outcome.SUCCEEDED
    assert _close(scene.link_orientations_deg(), [90, 90, 135, 135, 135])


def test_planning_moves_nothing(scene, robot):
    before = [scene.client.getJointState(scene.robot, j)[0] for j in scene.arms["left"].joints]
    assert rotate_skill(scene, robot, RotationAction(turned_link=4, held_link=3, delta_deg=-45)) is not None
    assert [scene.client.getJointState(scene.robot, j)[0] for j in scene.arms["left"].joints] == before
    assert _close(scene.link_orientations_deg(), [90] * 5)


def test_turning_the_first_link_holds_nothing(scene, robot):
    command = rotate_skill(scene, robot, RotationAction(turned_link=1, held_link=0, delta_deg=-45))
    assert command is not None
    assert len({p.arm for p in command.primitives if isinstance(p, Grip)}) == 1
    assert execute(scene, command, robot) is Outcome.SUCCEEDED
    assert _close(scene.link_orientations_deg(), [45] * 5)


def test_grasping_arm_ends_on_the_turned_link(scene, robot):
    command = rotate_skill(scene, robot, RotationAction(turned_link=5, held_link=4, delta_deg=-90))
    assert command is not None
    # the last move before letting go places the gripper where the turned link's centre ends up
    last_follow = [p for p in command.primitives if isinstance(p, (MoveArm, Grip))]
    release = next(i for i, p in enumerate(last_follow) if isinstance(p, Grip) and not p.close)
    arm_pose = last_follow[release - 1]
    assert execute(scene, command, robot) is Outcome.SUCCEEDED
    set_arm_joints(scene, arm_pose.arm, arm_pose.joint_positions)
    reached, _ = robot.end_effector_pose(arm_pose.arm)
    centre = scene.link_center(5)
    assert ((reached[0] - centre[0]) ** 2 + (reached[1] - centre[1]) ** 2) ** 0.5 < 0.03


def test_unreachable_object_fails_and_does_not_move(scene, robot):
    scene.set_configuration([90] * 5, base_point_xy=(2.5, 0.3))
    assert rotate_skill(scene, robot, RotationAction(turned_link=3, held_link=2, delta_deg=45)) is None
    assert perform_action(scene, robot, RotationAction(turned_link=3, held_link=2, delta_deg=45)) is Outcome.FAILED
    assert _close(scene.link_orientations_deg(), [90] * 5)


def test_stopped_rotation_is_partial_and_half_way(scene, robot):
    outcome = perform_action(scene, robot, RotationAction(turned_link=3, held_link=2, delta_deg=45), stop_fraction=0.5)
    assert outcome is Outcome.PARTIAL
    assert _close(scene.link_orientations_deg(), [90, 90, 112.5, 112.5, 112.5])


def test_interrupt_before_any_motion_is_a_failure(scene, robot):
    outcome = perform_action(scene, robot, RotationAction(turned_link=3, held_link=2, delta_deg=45), interrupt=lambda done, total: True)
    assert outcome is Outcome.FAILED
    assert _close(scene.link_orientations_deg(), [90] * 5)
