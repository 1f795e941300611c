"""The simulated human is a visible body that turns links physically on the physics clock; random scenarios
are random: starts, goals with several links changed, human moves anywhere on the chain."""
import pybullet
import pytest
from pybullet_utils.bullet_client import BulletClient

from planhrc.geometry import configuration_feasible
from planhrc.robot_sim.demo import random_scenario
from planhrc.robot_sim.human import Human, HumanMove, get_scenario
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
