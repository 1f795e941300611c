"""The simulated human is a visible body that turns links physically on the physics clock; random scenarios
are random: starts, goals with several links changed, human moves anywhere on the chain."""
import pybullet
import pytest
from pybullet_utils.bullet_client import BulletClient

from planhrc.geometry import configuration_feasible, rotated
from planhrc.robot_sim.demo import random_scenario
from planhrc.robot_sim.human import Human, HumanMove
from planhrc.robot_sim.scenarios import get_scenario
from planhrc.robot_sim.perception import angle_difference_deg
from planhrc.robot_sim.scene import SceneSpec, build_scene

pytestmark = pytest.mark.sim


def test_the_human_is_visible_and_turns_a_link_on_the_physics_clock():
    client = BulletClient(connection_mode=pybullet.DIRECT)
    scene = build_scene(client, SceneSpec(load_robot=False))
    try:
        human = Human(scene)
        assert all(client.getVisualShapeData(hand) for hand in human.hands)
        human.start(HumanMove(4, 3, -45.0, "turn l4"))
        assert scene.link_orientations_deg() == pytest.approx((90.0,) * 5, abs=0.1)  # nothing until time passes
        started = scene.time_s
        human.finish()
        assert scene.time_s - started > 0.3  # reaching, turning at a human pace, letting go
        theta = scene.link_orientations_deg()
        assert all(abs(angle_difference_deg(a, b)) < 4 for a, b in zip(theta, (90, 90, 90, 45, 45))), theta
        assert human.idle and human.done == ["turn l4"] and client.getNumConstraints() == 0
    finally:
        scene.close()
        client.disconnect()


def test_random_scenarios_start_anywhere_change_several_links_and_the_human_acts_anywhere():
    scenarios = [random_scenario(seed) for seed in range(10)]
    spec = SceneSpec()
    for sc in scenarios:
        changed = sum(1 for a, b in zip(sc.initial_deg, sc.goal_deg) if abs(angle_difference_deg(a, b)) > 1e-6)
        assert 3 <= changed <= 10, sc
        assert configuration_feasible(spec.geometry(sc.base_point_xy), sc.goal_deg, spec.cell()).ok
        assert configuration_feasible(spec.geometry(sc.base_point_xy), sc.initial_deg, spec.cell()).ok
        if sc.formulation == "relative":
            assert sc.goal_deg[0] == sc.initial_deg[0]
    assert sum(sc.initial_deg != (90.0,) * 5 for sc in scenarios) >= 5  # not always straight
    assert len({sc.base_point_xy for sc in scenarios}) >= 5  # nor always in the same place
    links = {e.link for sc in scenarios for e in get_scenario(sc.human).events}
    assert links == {1, 2, 3, 4, 5}


def test_a_considerate_human_leaves_the_object_on_the_table_not_hanging_over_its_edge():
    from planhrc.robot_sim.human import HumanContext, choose_move
    from planhrc.robot_sim.scenarios import HumanEvent

    client = BulletClient(connection_mode=pybullet.DIRECT)
    scene = build_scene(client, SceneSpec(load_robot=False, initial_orientations_deg=(90, 90, 90, 45, 45)))
    try:
        base, theta = scene.configuration()
        # turning l4 back by 45 would leave link 5's end 2.5 cm past the far edge: tolerable while acting, but
        # not where a considerate human leaves the object
        ahead = scene.spec.geometry(base), (90, 90, 90, 0, 0)
        reasons = configuration_feasible(*ahead, scene.spec.cell(), reach_links=()).reasons
        assert [r.code for r in reasons] == ["off_table"]
        event = HumanEvent(at_step=1, when="before", link=4, direction=-1, keep_workable=True)
        move = choose_move(scene, event, HumanContext(step_deg=45.0))
        assert move is not None and (move.turned, move.delta_deg) != (4, -45.0)
        _, end = rotated(scene.spec.geometry(base), theta, move.turned, move.held, move.delta_deg)
        feasible = configuration_feasible(scene.spec.geometry(base), end, scene.spec.cell(), reach_links=())
        assert feasible.ok, feasible.sentence()
    finally:
        scene.close()
        client.disconnect()


def test_a_considerate_human_keeps_the_clearance_the_robot_keeps_from_the_tables_edge():
    """A move ending on the table as drawn but under 1.5 cm from its edge is one a physical turn a degree or two
    off takes past the edge: a considerate human makes another (a random episode beside the robot: the human's
    move ended less than 5 mm past the edge)."""
    from planhrc.geometry import PLANNING
    from planhrc.robot_sim.human import HumanContext, choose_move
    from planhrc.robot_sim.scenarios import HumanEvent

    base = (0.66, 0.3875)  # straight, along -y; turning l4 by -45 brings link 5's end within 1.5 cm of the far edge
    client = BulletClient(connection_mode=pybullet.DIRECT)
    scene = build_scene(client, SceneSpec(load_robot=False, base_point_xy=base))
    try:
        cell, geometry = scene.spec.cell(), scene.spec.geometry(base)
        _, theta = scene.configuration()
        assert configuration_feasible(geometry, theta, cell, tolerance=PLANNING).ok
        ahead = rotated(geometry, theta, 4, 3, -45.0)
        assert configuration_feasible(*ahead, cell, reach_links=()).ok  # on the table as drawn
        assert [(r.code, r.link) for r in configuration_feasible(*ahead, cell, reach_links=(),
                                                                  tolerance=PLANNING).reasons] == [("off_table", 5)]
        event = HumanEvent(at_step=1, when="before", link=4, direction=-1, keep_workable=True)
        move = choose_move(scene, event, HumanContext(step_deg=45.0))
        assert move is not None and (move.turned, move.delta_deg) != (4, -45.0)
        end = rotated(geometry, theta, move.turned, move.held, move.delta_deg)
        kept = configuration_feasible(*end, cell, reach_links=(), tolerance=PLANNING)
        assert kept.ok, kept.sentence()
    finally:
        scene.close()
        client.disconnect()


def test_a_human_acting_during_a_robot_turn_counts_the_rest_of_that_turn():
    from planhrc.robot_sim.human import HumanContext, RobotTurn, choose_move
    from planhrc.robot_sim.scenarios import HumanEvent

    client = BulletClient(connection_mode=pybullet.DIRECT)
    scene = build_scene(client, SceneSpec(load_robot=False))  # straight, along -y
    try:
        event = HumanEvent(at_step=1, when="during", link=4, direction=-1, keep_workable=True)
        alone = choose_move(scene, event, HumanContext(step_deg=45.0, busy_links=(2, 1)))
        assert alone is not None and (alone.turned, alone.delta_deg) == (4, -45.0)  # fine on a still object
        base, theta = scene.configuration()
        # but the robot is turning l2 by -45 (links 2-5 with it): l4's turn then points links 4-5 off the far edge
        turning = RobotTurn(turned=2, held=1, delta_deg=-45.0, base_xy=base, theta=tuple(theta))
        move = choose_move(scene, event, HumanContext(step_deg=45.0, busy_links=(2, 1), robot_turn=turning))
        assert move is not None and (move.turned, move.delta_deg) != (4, -45.0)
        geometry, end = rotated(scene.spec.geometry(base), theta, move.turned, move.held, move.delta_deg)
        geometry, end = rotated(geometry, end, 2, 1, -45.0)
        feasible = configuration_feasible(geometry, end, scene.spec.cell(), reach_links=())
        assert feasible.ok, feasible.sentence()
    finally:
        scene.close()
        client.disconnect()


def test_a_human_turning_the_first_link_of_a_bent_chain_does_not_slide_it_or_bend_it():
    """l1 turns about its point on the table with the whole chain beyond it held by joint friction alone: the hand
    speeds up and slows down smoothly and the other hand holds that point down (a random episode's help request:
    turned at full speed from the first tick, this turn slid the base point by 4 cm and bent joint 2 by 10°)."""
    theta, base = (88.0, 90.0, 134.0, 90.0, 134.0), (0.593, 0.388)
    client = BulletClient(connection_mode=pybullet.DIRECT)
    scene = build_scene(client, SceneSpec(load_robot=False, initial_orientations_deg=theta, base_point_xy=base))
    try:
        human = Human(scene)
        before_base, before = scene.configuration()
        human.start(HumanMove(1, 0, -43.0, "turn l1 about the table"))
        human.finish()
        after_base, after = scene.configuration()
    finally:
        scene.close()
        client.disconnect()
    slide = ((after_base[0] - before_base[0]) ** 2 + (after_base[1] - before_base[1]) ** 2) ** 0.5
    assert slide < 0.005, f"the base point slid {slide * 100:.1f} cm"
    assert abs(angle_difference_deg(after[0], before[0]) + 43.0) < 3.0, after
    for k in range(1, 5):  # every joint beyond keeps its angle: the chain turned as one piece
        bend = angle_difference_deg(after[k] - after[k - 1], before[k] - before[k - 1])
        assert abs(bend) < 2.0, (k + 1, bend)
