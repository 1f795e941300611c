"""How a human brings the object to a configuration: the joint turns in an order whose every sweep stays on the
table and clear of the robot, else a path through intermediate configurations; then physically, by the visible
human, to within a few degrees, the object never leaving the table."""
import pybullet
import pytest
from pybullet_utils.bullet_client import BulletClient

from planhrc.geometry import configuration_feasible, rotated
from planhrc.robot_sim.handling import (SWEEP_HAZARDS, joint_angles, orientations, shorter, turn_order,
                                        turn_path)
from planhrc.robot_sim.human import Human, help_turns
from planhrc.robot_sim.perception import angle_difference_deg
from planhrc.robot_sim.scene import SceneSpec, baseline_problems, build_scene, sweep_hazard

pytestmark = pytest.mark.sim

SPEC = SceneSpec()
CELL = SPEC.cell()
# A 5-link object between the arms; the goal (feasible) changes links 2-5. Turned upstream first, as a help
# request reads, link 2's turn swings links 3-5 through the robot one way and past the table's edge the other.
BASE = (0.577, 0.143)
START = (315.0, 0.0, 135.0, 90.0, 90.0)
END = (315.0, 90.0, 180.0, 270.0, 225.0)


def _turns(start, end):
    wanted, now = joint_angles(end), joint_angles(start)
    return {k: shorter(wanted[k - 1] - now[k - 1]) for k in range(1, len(end) + 1)
            if abs(shorter(wanted[k - 1] - now[k - 1])) > 1e-6}


def _safe_all_along(geometry, start, moves):
    baseline = baseline_problems(geometry, start, CELL)
    angles = start
    for link, delta in moves:
        if sweep_hazard(geometry, angles, CELL, link, link - 1, delta, baseline, SWEEP_HAZARDS) is not None:
            return False
        angles = rotated(geometry, angles, link, link - 1, delta)[1]
    return angles


def test_joint_angles_and_orientations_are_inverse():
    assert orientations(joint_angles(START)) == pytest.approx(START)
    assert joint_angles((90.0, 45.0, 90.0)) == (90.0, 315.0, 45.0)


def test_the_turns_go_in_an_order_that_stays_on_the_table_when_upstream_first_does_not():
    geometry = SPEC.geometry(BASE)
    turns = _turns(START, END)
    assert sorted(turns) == [2, 3, 4, 5]
    upstream_first = [(k, d) for k, d in sorted(turns.items())]
    assert _safe_all_along(geometry, START, upstream_first[:1]) is False
    assert _safe_all_along(geometry, START, [(2, turns[2] - 360.0)]) is False  # nor the other way round
    order = turn_order(geometry, START, CELL, turns, baseline_problems(geometry, START, CELL))
    assert order is not None and sorted(k for k, _ in order) == [2, 3, 4, 5]
    end = _safe_all_along(geometry, START, order)
    assert end and all(abs(angle_difference_deg(a, b)) < 1e-6 for a, b in zip(end, END))


def test_when_no_order_works_a_path_through_intermediate_configurations_does():
    base, start = (0.6427, -0.0983), (358.0, 45.3, 135.3, 90.4, 90.4)
    geometry = SPEC.geometry(base)
    end = (358.0, 270.0, 180.0, 225.0, 0.0)
    assert configuration_feasible(geometry, end, CELL).ok
    turns = _turns(start, end)
    baseline = baseline_problems(geometry, start, CELL)
    assert turn_order(geometry, start, CELL, turns, baseline) is None
    path = turn_path(geometry, start, CELL, joint_angles(end), baseline)
    assert path is not None and len(path) > len(turns)
    reached = _safe_all_along(geometry, start, path)
    assert reached and all(abs(angle_difference_deg(a, b)) < 1e-6 for a, b in zip(reached, end))


def test_the_visible_human_brings_the_object_where_asked_without_it_leaving_the_table():
    client = BulletClient(connection_mode=pybullet.DIRECT)
    scene = build_scene(client, SceneSpec(initial_orientations_deg=START, base_point_xy=BASE))
    try:
        human = Human(scene)
        done = help_turns(human, [(k, END[k - 1]) for k in (2, 3, 4, 5)])
        assert done, "the human found no safe way"
        theta = scene.link_orientations_deg()
        assert all(abs(angle_difference_deg(a, b)) < 3.0 for a, b in zip(theta, END)), theta
        assert scene.off_table_links() == ()
        assert client.getNumConstraints() == 0
    finally:
        scene.close()
        client.disconnect()
