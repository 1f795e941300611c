"""The robot's new skills in the physical cell (PyBullet, stepped; outcomes judged from the world): sliding the whole
object towards the table's middle with both arms, a turn re-grasped when one arm cannot follow it to its end; and a
worker that stops short of the goal always ends with a help request the service recorded."""
from __future__ import annotations

import numpy as np
import pybullet
import pytest
from pybullet_utils.bullet_client import BulletClient

from planhrc.client import KBClient
from planhrc.robot_sim.acting import perform_skill
from planhrc.robot_sim.regrasp import perform_with_regrasp, regrasp_skill
from planhrc.robot_sim.scene import ARMS, SceneSpec, arm_joints, build_scene, set_arm_joints
from planhrc.robot_sim.skills import Command, Robot, RotationAction, Unreachable, execute, rotate_skill
from planhrc.robot_sim.slide import slide, slide_skill
from planhrc.robot_sim.worker import run_worker
from planhrc.vocabulary import ActionOutcome
from tests.servers import serving

pytestmark = pytest.mark.sim

# Folded near the robot's left (the service found no plan there, `test_one_judge`): slid 11 cm the plan fits
START = (90.52, 134.86, 89.96, 314.51, 314.58)
BASE = (0.538, 0.128)
TARGET = (0.645, 0.155)


@pytest.fixture
def cell():
    client = BulletClient(connection_mode=pybullet.DIRECT)
    scenes = []

    def make(spec: SceneSpec):
        scene = build_scene(client, spec)
        scenes.append(scene)
        return scene, Robot(scene)

    yield make
    for scene in scenes:
        scene.close()
    client.disconnect()


def _bent(before, after) -> float:
    return max(abs((a - b + 180.0) % 360.0 - 180.0) for a, b in zip(before, after))


def test_both_arms_slide_the_object_towards_the_middle_keeping_its_shape(cell):
    scene, robot = cell(SceneSpec(initial_orientations_deg=START, base_point_xy=BASE))
    before = scene.link_orientations_deg()
    result = slide(scene, robot, TARGET, (1, 5))
    assert result.outcome is ActionOutcome.SUCCEEDED, result.message
    x, y = scene.base_point()
    assert abs(x - TARGET[0]) < 0.03 and abs(y - TARGET[1]) < 0.03  # measured where it was asked to go
    assert _bent(before, scene.link_orientations_deg()) < 6.0  # the links between were dragged along, not bent
    assert not scene.off_table_links()


def test_the_robot_straightens_links_a_turn_dragged_off_the_orientation_grid(cell):
    # absolute random task 1018 after a 270-degree turn dragged the object (its numbers kept here), slid to where
    # the service found room to straighten it: links 1, 2 and 5 lie 13 to 16 degrees off the 45-degree grid
    dragged = (192.88, 240.79, 315.51, 181.1, 121.8)
    scene, robot = cell(SceneSpec(initial_orientations_deg=dragged, base_point_xy=(0.785, 0.1025)))
    off = [((a + 22.5) % 45.0) - 22.5 for a in scene.link_orientations_deg()]
    assert max(abs(v) for v in off) > 12.0
    done = perform_skill(scene, robot, {"name": "straighten", "turns": [[1, 0, -12.88], [3, 2, 15.28], [5, 4, 14.3]]})
    assert done.startswith("straighten succeeded"), done
    off = [((a + 22.5) % 45.0) - 22.5 for a in scene.link_orientations_deg()]
    assert max(abs(v) for v in off) < 6.0, off  # every link within the perception's snapping of the grid
    assert not scene.off_table_links()


def test_a_slide_no_arm_can_follow_is_not_planned_and_nothing_moves(cell):
    scene, robot = cell(SceneSpec(initial_orientations_deg=START, base_point_xy=BASE))
    before = scene.configuration()
    assert slide_skill(scene, robot, (0.95, 0.6), (1, 5)) is None  # the far corner: beyond both arms
    assert slide_skill(scene, robot, TARGET, (1, 1)) is None  # one link for two arms
    assert scene.configuration() == before


def _grasp_xy(scene, command, link):
    """Where the gripper that grasps `link` closes: its pose in the arm move just before that grasp."""
    moves = {}
    for primitive in command.primitives:
        if type(primitive).__name__ == "MoveArm":
            moves[primitive.arm] = primitive.joint_positions
        elif type(primitive).__name__ == "Grasp" and primitive.link == link:
            set_arm_joints(scene, primitive.arm, moves[primitive.arm])
            state = scene.client.getLinkState(scene.robot, scene.arms[primitive.arm].end_effector,
                                              computeForwardKinematics=True)
            return np.asarray(state[0][:2])
    raise AssertionError(f"no grasp of link {link}")


def test_a_turn_grasped_nearer_the_joint_takes_the_link_there_and_still_turns_it(cell):
    scene, robot = cell(SceneSpec())
    action = RotationAction(turned_link=4, held_link=3, delta_deg=45)
    centre, joint = np.asarray(scene.link_center(4)), np.asarray(scene.joint_points()[3 - 1])
    home = {arm: arm_joints(scene, arm) for arm in ARMS}
    at_centre = rotate_skill(scene, robot, action)
    nearer = rotate_skill(scene, robot, action, near_joint=True)
    assert isinstance(at_centre, Command) and isinstance(nearer, Command)
    half = float(np.linalg.norm(centre - joint))
    assert np.linalg.norm(_grasp_xy(scene, at_centre, 4) - centre) < 0.02
    assert np.linalg.norm(_grasp_xy(scene, nearer, 4) - joint) < half - 0.005  # between the centre and the joint
    for arm, q in home.items():
        set_arm_joints(scene, arm, q)
    before = scene.link_orientations_deg()[3]
    result = execute(scene, nearer, robot)
    assert result.outcome is ActionOutcome.SUCCEEDED, result.message
    assert abs(((scene.link_orientations_deg()[3] - before) - 45.0 + 180.0) % 360.0 - 180.0) < 4.0


# No arm can follow this half-turn of link 5 (held by link 4) holding the link at its centre; found by trying random
# configurations of the cell with `rotate_skill` and `regrasp_skill`
REGRASP_START = (180.0, 0.0, 90.0, 0.0, 270.0)
REGRASP_BASE = (0.642, 0.253)


def test_a_turn_no_arm_can_follow_from_the_links_centre_is_re_grasped_and_done(cell):
    scene, robot = cell(SceneSpec(initial_orientations_deg=REGRASP_START, base_point_xy=REGRASP_BASE))
    action = RotationAction(turned_link=5, held_link=4, delta_deg=180)
    whole = rotate_skill(scene, robot, action)
    command = regrasp_skill(scene, robot, action)
    if not isinstance(whole, Unreachable) or command is None:
        pytest.skip("this physics build plans the turn in one grasp (or not at all): no re-grasp to test here")
    assert sum(1 for p in command.primitives if type(p).__name__ == "Grasp") >= 2  # held, turned (again)
    before = scene.link_orientations_deg()
    result = perform_with_regrasp(scene, robot, action)
    assert result.outcome is ActionOutcome.SUCCEEDED, result.message
    assert abs(((scene.link_orientations_deg()[4] - before[4]) - 180.0 + 180.0) % 360.0 - 180.0) < 4.0
    assert not scene.off_table_links()


def test_a_worker_that_stops_short_of_the_goal_ends_with_a_help_request_the_service_recorded(tmp_path):
    spec = SceneSpec(n_links=3, initial_orientations_deg=(90.0, 90.0, 90.0), base_point_xy=(0.7, 0.2325))
    with serving(tmp_path / "kb.sqlite3") as url, KBClient(url) as kb:
        oid = kb.create_object("rod", 3, 4, "relative", base_point_xy=spec.base_xy)["id"]
        # the paper's 3-4 example needs two actions: one step is not enough, and no human helps
        summary = run_worker(url, oid, spec, "none", tmp_path / "worker", max_steps=1, perception="fallback",
                             goal_link_orientations_deg=(90.0, 180.0, 270.0), record_frames=False)
        events = kb.read_events(oid)
    assert not summary.reached_goal and summary.stop_reason == "max_steps"
    assert summary.final_help and all(s.startswith("turn link ") for s in summary.final_help)
    gave_up, asked = events[-2:]
    assert gave_up["kind"] == "worker_gave_up" and gave_up["data"]["reason"] == "max_steps"
    assert asked["kind"] == "human_help_requested" and "max_steps" in asked["reason"]
    assert [h["sentence"] for h in asked["data"]["help"]] == list(summary.final_help)
