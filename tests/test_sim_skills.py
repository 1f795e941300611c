"""Rotation skills, done physically: the grippers grasp, the arm carries the link along the arc, the outcome is
measured from the world afterwards (angle reached, reason, sentence)."""
import pybullet
import pytest
from pybullet_utils.bullet_client import BulletClient

from planhrc.robot_sim.perception import angle_difference_deg
from planhrc.robot_sim.scene import SceneSpec, arm_joints, build_scene
from planhrc.robot_sim.skills import (Command, Grasp, MoveArm, Release, Robot, RotationAction, Turn,
                                      Unreachable, execute, perform_action, rotate_skill)
from planhrc.vocabulary import ActionOutcome, FailureReason

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
    scene.set_configuration([90] * 5, base_point_xy=scene.spec.base_xy)
    scene.step(2)
    return scene


@pytest.fixture
def robot(cell):
    return cell[1]


def _close(a, b, tol):
    return all(abs(angle_difference_deg(x, y)) < tol for x, y in zip(a, b))


def test_a_physical_rotation_is_measured_afterwards(scene, robot):
    command = rotate_skill(scene, robot, RotationAction(turned_link=4, held_link=3, delta_deg=45))
    assert isinstance(command, Command)
    kinds = [type(p) for p in command.primitives]
    assert kinds.count(Grasp) == 2 and kinds.count(Release) == 2 and kinds.count(Turn) == 9 and MoveArm in kinds
    constraints_before = scene.client.getNumConstraints()
    result = execute(scene, command, robot)
    assert result.outcome is ActionOutcome.SUCCEEDED and result.reason is None, result.message
    assert abs(result.reached_deg - 45) < 4 and result.message.startswith("link 4 turned +4")
    # the links beyond the turned one moved with it; the held link and those before it stayed
    assert _close(scene.link_orientations_deg(), [90, 90, 90, 135, 135], 4)
    assert scene.client.getNumConstraints() == constraints_before and not scene.gripped  # both hands let go


def test_turning_the_first_link_holds_nothing(scene, robot):
    scene.set_configuration([90, 0, 135, 180, 270])  # compact: the whole object turns about p1 on the table
    command = rotate_skill(scene, robot, RotationAction(turned_link=1, held_link=0, delta_deg=-45))
    assert isinstance(command, Command)
    assert len({p.arm for p in command.primitives if isinstance(p, Grasp)}) == 1
    result = execute(scene, command, robot)
    assert result.outcome is ActionOutcome.SUCCEEDED and abs(result.reached_deg + 45) < 4, result.message


def test_planning_moves_nothing(scene, robot):
    before = arm_joints(scene, "left")
    assert isinstance(rotate_skill(scene, robot, RotationAction(turned_link=4, held_link=3, delta_deg=-45)), Command)
    assert arm_joints(scene, "left") == before
    assert _close(scene.link_orientations_deg(), [90] * 5, 0.5)


def test_an_object_out_of_reach_fails_with_the_link_and_the_distance_and_does_not_move(scene, robot):
    scene.set_configuration([90] * 5, base_point_xy=(1.5, 0.3))
    planned = rotate_skill(scene, robot, RotationAction(turned_link=3, held_link=2, delta_deg=45))
    assert isinstance(planned, Unreachable) and planned.link == 2 and planned.miss_m > 0.3
    result = perform_action(scene, robot, RotationAction(turned_link=3, held_link=2, delta_deg=45))
    assert result.outcome is ActionOutcome.FAILED and result.reason is FailureReason.UNREACHABLE
    assert result.message.startswith("link 2 unreachable: ") and " m beyond reach" in result.message
    assert _close(scene.link_orientations_deg(), [90] * 5, 0.5)


def test_a_grasp_released_mid_turn_is_partial_with_the_angle_reached(scene, robot):
    result = perform_action(scene, robot, RotationAction(turned_link=5, held_link=4, delta_deg=-90), stop_fraction=0.5)
    assert result.outcome is ActionOutcome.PARTIAL and result.reason is FailureReason.GRASP_LOST
    assert -60 < result.reached_deg < -30  # measured from the world after the release
    assert "short by" in result.message
    measured = angle_difference_deg(scene.link_orientations_deg()[4], 90)
    assert abs(measured - result.reached_deg) < 1.0


def test_a_turn_that_leaves_the_table_says_so(scene, robot):
    result = perform_action(scene, robot, RotationAction(turned_link=3, held_link=2, delta_deg=-90))  # l3-l5 forward
    assert result.reason is FailureReason.LEFT_TABLE and "left the table" in result.message
    assert result.outcome is ActionOutcome.PARTIAL


def test_a_macro_step_splits_into_single_steps():
    macro = RotationAction(turned_link=3, held_link=2, delta_deg=135, macro_steps=3)
    assert [a.delta_deg for a in macro.split()] == [45, 45, 45]
    assert RotationAction(3, 2, 45).split() == (RotationAction(3, 2, 45),)
