"""The ROS 2 layer's pure conversions (no rclpy: these run in `.venv`): REP 103 radians <-> the service's degrees
clockwise, JointState <-> perception, a dispatched action -> trajectory, the JSON requests, markers."""
from __future__ import annotations

import importlib.util
import json
import math
import subprocess
import sys

import numpy as np
import pytest

from planhrc.geometry import ObjectGeometry, joint_points, rotated
from planhrc.ros2 import topics
from planhrc.ros2.convert import (decision_from_event, decision_key, decision_text, goal_orientations,
                                  joint_state_fields, read_feedback, read_give_up, read_joint_state, to_ros_rad,
                                  to_service_deg, turn_target)
from planhrc.ros2.errors import Ros2Error
from planhrc.ros2.markers import object_shapes


@pytest.mark.parametrize("deg, rad", [(0, 0.0), (90, -math.pi / 2), (270, math.pi / 2), (45, -math.pi / 4),
                                      (315, math.pi / 4)])
def test_clockwise_degrees_are_counter_clockwise_radians_negated(deg, rad):
    assert to_ros_rad(deg) == pytest.approx(rad)
    assert to_service_deg(rad) == pytest.approx(deg % 360)


def test_the_direction_on_the_table_is_the_same_in_both_conventions():
    """A link at 90 deg clockwise points to the robot's right (-y); in REP 103 that is the angle -pi/2."""
    rad = to_ros_rad(90.0)
    assert (math.cos(rad), math.sin(rad)) == pytest.approx((0.0, -1.0), abs=1e-12)
    point = joint_points(ObjectGeometry((1.0,), (0.0, 0.0)), [90.0])[1]
    assert tuple(point) == pytest.approx((math.cos(rad), math.sin(rad)), abs=1e-12)


def test_any_angle_comes_back_within_a_turn():
    for deg in np.linspace(0, 359.9, 97):
        assert 0 <= to_service_deg(to_ros_rad(deg)) < 360
        assert to_service_deg(to_ros_rad(deg)) == pytest.approx(deg, abs=1e-9)
    assert to_service_deg(-2 * math.pi - math.pi / 2) == pytest.approx(90.0)


def test_a_joint_state_reads_in_any_order_with_unseen_links_and_a_base_point():
    names = ["l3", "base_y", "l1", "base_x", "l2"]
    positions = [to_ros_rad(180), 0.25, to_ros_rad(90), 0.6, math.nan]
    reading = read_joint_state("perceived", names, positions, 4)
    assert reading.link_orientations_deg[0] == pytest.approx(90)
    assert reading.link_orientations_deg[2] == pytest.approx(180)
    assert reading.link_orientations_deg[1] is None and reading.link_orientations_deg[3] is None
    assert reading.base_point_xy == (0.6, 0.25)


def test_the_fields_written_read_back():
    names, positions = joint_state_fields([0.0, 90.0, None], (0.7, -0.1))
    assert names == ["l1", "l2", "l3", "base_x", "base_y"] and math.isnan(positions[2])
    reading = read_joint_state("perceived", names, positions, 3)
    assert reading.link_orientations_deg[:2] == pytest.approx((0.0, 90.0)) and reading.base_point_xy == (0.7, -0.1)


@pytest.mark.parametrize("names, positions, complete, field", [
    (["l1", "l2"], [0.0], False, "perceived.position"),
    (["l1", "wrist"], [0.0, 0.0], False, "perceived.name"),
    (["l1", "l5"], [0.0, 0.0], False, "perceived.name"),
    (["l1", "l1"], [0.0, 0.0], False, "perceived.name"),
    (["l1", "l2"], [math.inf, 0.0], False, "perceived.position[l1]"),
    (["l1", "base_x"], [0.0, 0.5], False, "perceived.name"),
    (["l1", "base_x", "base_y"], [0.0, math.nan, 0.1], False, "perceived.position[base_x]"),
    (["l1", "l2"], [math.nan, math.nan], False, "perceived.position"),
    (["l1", "l2"], [0.0, math.nan], True, "perceived.position"),
])
def test_a_bad_joint_state_is_refused_naming_the_field(names, positions, complete, field):
    with pytest.raises(Ros2Error) as err:
        read_joint_state("perceived", names, positions, 4 if not complete else 2, complete=complete)
    assert str(err.value).startswith(field + ":")
    assert "\n" not in str(err.value)


def test_a_downstream_turn_is_a_trajectory_from_now_to_the_target_with_the_turns_sign():
    action = {"turned_link_index": 3, "held_link_index": 2, "delta_deg": 90}
    target = turn_target(action, [0.0, 90.0, 90.0, 180.0])
    assert target.joint_names == ("l2", "l3")
    assert target.start == pytest.approx((to_ros_rad(90), to_ros_rad(90)))
    assert target.end[0] == target.start[0]  # the held link stays still
    assert target.end[1] - target.start[1] == pytest.approx(-math.pi / 2)  # clockwise: negative in REP 103
    assert to_service_deg(target.end[1]) == pytest.approx(180.0)
    assert target.duration_s > 0


def test_an_absolute_first_link_is_held_against_the_table():
    target = turn_target({"turned_link_index": 1, "held_link_index": 0, "delta_deg": -45}, [90.0, 90.0])
    assert target.joint_names == ("l0", "l1") and target.start[0] == 0.0
    assert target.end[1] - target.start[1] == pytest.approx(math.pi / 4)


def test_a_turn_of_an_unseen_link_is_refused():
    with pytest.raises(Ros2Error, match="l2 was not seen"):
        turn_target({"turned_link_index": 2, "held_link_index": 1, "delta_deg": 90}, [0.0, None])


def test_feedback_and_give_up_json():
    feedback = read_feedback(json.dumps({"outcome": "failed", "reason": "slip", "measured_deg": 87.5,
                                         "message": "let go", "request_id": "r1"}))
    assert (feedback.outcome, feedback.reason, feedback.measured_deg, feedback.action_id) == ("failed", "slip", 87.5, None)
    assert not feedback.hands_open and read_feedback('{"outcome": "succeeded", "hands_open": true}').hands_open
    assert read_give_up('{"reason": "unseen_links", "message": "no markers"}').reason == "unseen_links"
    for text, field in (("[1]", "feedback.data"), ("nope", "feedback.data"), ('{"outcome": "done"}', "feedback.outcome"),
                        ('{"outcome": "failed", "reason": "tired"}', "feedback.reason"),
                        ('{"outcome": "failed", "measured_deg": "x"}', "feedback.measured_deg"),
                        ('{"outcome": "succeeded", "action_id": 3}', "feedback.action_id"),
                        ('{"outcome": "succeeded", "hands_open": "yes"}', "feedback.hands_open")):
        with pytest.raises(Ros2Error) as err:
            read_feedback(text)
        assert str(err.value).startswith(field + ":")
    with pytest.raises(Ros2Error, match=r"^give_up\.message:"):
        read_give_up('{"reason": "x"}')


def test_an_event_becomes_the_answer_body_and_shares_its_key():
    event = {"seq": 7, "kind": "replan", "reason": "why", "data": {
        "perceived_state_id": "obj1_state_2", "plan_id": "obj1_plan_1", "next_action_id": "obj1_plan_1_a1",
        "next_step": 1, "matched_expected_step": None}}
    step = {"id": "obj1_plan_1_a1", "name": "rotateclockwise", "params": ["a"], "step": 1, "pre": ["x"],
            "joint_index": 1, "turned_link_index": 2, "held_link_index": 1, "delta_deg": 90}
    answer = decision_from_event(event, step)
    assert answer["decision"] == "replan" and answer["next_action"]["plan_id"] == "obj1_plan_1"
    assert "pre" not in answer["next_action"] and answer["next_action"]["delta_deg"] == 90
    assert decision_key(answer["decision"], answer["perceived_state_id"], answer["reason"]) == \
        decision_key("replan", "obj1_state_2", "why")
    body = json.loads(decision_text(answer, None, 7))
    assert body["event_seq"] == 7 and body["perception_stamp"] is None and body["reason"] == "why"
    assert json.loads(decision_text(answer, (5, 6)))["perception_stamp"] == [5, 6]


def test_goal_orientations_of_both_formulations():
    absolute = {"o_j1": 90, "o_j2": 180, "o_j3": 0}
    assert goal_orientations("absolute", absolute, 3, None) == (90.0, 180.0, 0.0)
    assert goal_orientations("absolute", {"o_j1": 90}, 3, None) is None  # a partial goal is not drawn
    relative = {"o_j1": 90, "o_j2": 270}
    assert goal_orientations("relative", relative, 3, 90.2) == (90.0, 180.0, 90.0)
    assert goal_orientations("relative", relative, 3, None) is None


def test_a_bimanual_goal_is_link_orientations_measured_from_link_one():
    # jK carries l(K+1)'s orientation from l1 (not its angle from lK, as a relative goal would)
    from_first = {"o_j1": 90, "o_j2": 90, "o_j3": 180}
    assert goal_orientations("bimanual", from_first, 4, 0.3) == (0.0, 90.0, 90.0, 180.0)
    assert goal_orientations("relative", from_first, 4, 0.3) == (0.0, 90.0, 180.0, 0.0)  # the reading it is not
    assert goal_orientations("bimanual", from_first, 4, 89.8) == (90.0, 180.0, 180.0, 270.0)
    assert goal_orientations("bimanual", {"o_j1": 90, "o_j3": 180}, 4, 0.0) is None  # a partial goal is not drawn
    assert goal_orientations("bimanual", from_first, 4, None) is None  # l1 unseen: nowhere to draw it from


def test_markers_draw_the_perceived_chain_the_goal_and_the_turn_to_come():
    lengths, base = (0.2, 0.2, 0.2), (0.6, 0.1)
    shapes = {s.namespace: s for s in object_shapes(lengths, base, (0.0, 0.0, 0.0), (0.0, 90.0, 90.0), (2, 1, 90.0),
                                                    table_z=-0.18)}
    geometry = ObjectGeometry(lengths, base)
    assert np.allclose([p[:2] for p in shapes["perceived"].points], joint_points(geometry, (0, 0, 0)))
    assert all(p[2] == -0.18 for p in shapes["perceived"].points)
    after = rotated(geometry, (0, 0, 0), 2, 1, 90.0)[1]
    assert np.allclose([p[:2] for p in shapes["expected"].points], joint_points(geometry, after))
    assert not np.allclose(shapes["expected"].points, shapes["perceived"].points)
    assert shapes["goal"].rgba[3] < 1  # a ghost
    unseen = {s.namespace: s for s in object_shapes(lengths, base, (0.0, None, 0.0), None, (2, 1, 90.0))}
    assert unseen["perceived"].points == () and unseen["expected"].points == () and unseen["goal"].points == ()


def test_every_topic_is_under_the_objects_namespace_with_its_qos():
    names = {spec.name("obj3") for spec in topics.OBJECT_TOPICS}
    assert "/planhrc/objects/obj3/perceived" in names and "/planhrc/objects/obj3/decision" in names
    assert topics.DECISION.qos_text == "reliable, transient local, depth 10"
    assert topics.NEXT_ACTION.durability is topics.Durability.VOLATILE
    assert topics.OBJECT.depth == 10 and {s.suffix for s in topics.OBJECT_TOPICS if s.durability is topics.Durability.TRANSIENT_LOCAL} == {
        "decision", "markers", "help", "plan", "object"}


@pytest.mark.parametrize("argv, says", [
    (["ros2-bridge", "--kb", "http://127.0.0.1:9"], "planhrc ros2-bridge: needs ROS 2's rclpy"),
    (["worker", "--ros2", "--object", "obj1"], "planhrc worker: --ros2: needs ROS 2's rclpy"),
    (["demo", "--ros2"], "planhrc demo: --ros2: needs ROS 2's rclpy"),
])
def test_without_rclpy_each_command_says_how_to_get_it_in_one_line(argv, says):
    if importlib.util.find_spec("rclpy") is not None:
        pytest.skip("rclpy is installed in this environment (the test is about one without it)")
    result = subprocess.run([sys.executable, "-m", "planhrc.cli", *argv], capture_output=True, text=True, timeout=120)
    assert result.returncode == 2
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith(says) and "run.py ros2-bridge" in lines[0]
