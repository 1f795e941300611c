"""Feasibility of a configuration: on the table, clear of the robot, within reach, not overlapping itself."""
import numpy as np
import pytest

from planhrc.geometry import (Cell, Feasibility, GeometryError, ObjectGeometry, configuration_feasible, joint_points,
                              reach_shortfall, rotated, sweep_feasible)
from planhrc.model import make_object

FIVE = ObjectGeometry((0.155,) * 5)  # the simulated cell's default: base point (0.6, 0.39)


def test_the_default_straight_object_and_the_paper_goals_are_feasible():
    for angles in ([90] * 5, [90, 45, 90, 135, 90], [90, 90, 90, 180, 90]):
        result = configuration_feasible(FIVE, angles)
        assert result.ok and result.reasons == (), result.sentence()
    assert configuration_feasible(ObjectGeometry((0.155,) * 3), [90, 180, 270]).ok


def test_a_chain_past_the_far_edge_names_the_links_that_left_the_table():
    result = configuration_feasible(FIVE, [90, 90, 0, 0, 0])  # links 3-5 point forward, past x = 0.9
    assert not result.ok
    off = [r for r in result.reasons if r.code == "off_table"]
    assert [r.link for r in off] == [4, 5]
    assert off[-1].distance_m == pytest.approx(0.6 + 3 * 0.155 - (0.9 - 0.015), abs=1e-6)
    assert "link 5 leaves the table" in result.sentence()


def test_a_chain_turned_back_towards_the_robot_is_inside_its_body():
    result = configuration_feasible(ObjectGeometry((0.155,) * 5, (0.6, 0.1)), [180] * 5)
    assert "inside_robot" in result.codes and "off_table" in result.codes
    assert [r.link for r in result.reasons if r.code == "inside_robot"] == [2, 3, 4, 5]


def test_reach_is_measured_from_the_shoulders():
    assert reach_shortfall((0.6, 0.0)) == 0.0
    assert reach_shortfall((0.89, 0.6)) > 0.0
    far = ObjectGeometry((0.155,) * 2, (0.85, 0.6))  # on the table's far left corner
    result = configuration_feasible(far, [90, 180], Cell())
    assert [(r.code, r.link) for r in result.reasons] == [("out_of_reach", 1)]
    assert result.reasons[0].message == f"link 1 unreachable: {result.reasons[0].distance_m:.2f} m beyond reach"
    assert 0.03 < result.reasons[0].distance_m < 0.08


def test_folding_back_and_crossing_are_overlaps():
    folded = configuration_feasible(FIVE, [90, 90, 270, 270, 270])
    assert [(r.code, r.link) for r in folded.reasons] == [("overlap", 3)] + [
        (r.code, r.link) for r in folded.reasons[1:]]
    crossing = configuration_feasible(FIVE, [90, 0, 270, 180, 90])  # a closed square: l4 ends on l1
    assert "overlap" in crossing.codes


def test_rotations_move_the_right_side_of_the_joint():
    geometry, values = rotated(FIVE, [90] * 5, turned_link=3, held_link=2, delta_deg=45)
    assert values == (90, 90, 135, 135, 135) and geometry == FIVE
    geometry, values = rotated(FIVE, [90] * 5, turned_link=2, held_link=3, delta_deg=-90)
    assert values[:2] == (0, 0) and values[2:] == (90, 90, 90)
    assert joint_points(geometry, values)[2] == pytest.approx(joint_points(FIVE, [90] * 5)[2])


def test_a_sweep_through_the_robot_is_refused_even_when_both_ends_are_feasible():
    start = [90, 90, 90, 90, 90]
    end_geometry, end = rotated(FIVE, start, 2, 1, 180)  # links 2-5 swing through the robot side and back
    assert sweep_feasible(FIVE, start, 2, 1, 180).ok is False
    assert sweep_feasible(FIVE, start, 5, 4, 45).ok


def test_bad_input_names_the_field_and_a_kb_object_has_a_geometry():
    with pytest.raises(GeometryError, match="angles: expected 5 values"):
        configuration_feasible(FIVE, [90] * 4)
    with pytest.raises(GeometryError, match="link_lengths_m"):
        ObjectGeometry((0.155, -1.0))
    with pytest.raises(GeometryError, match="held_link"):
        rotated(FIVE, [90] * 5, 3, 5, 45)
    obj = make_object("o", "relative", 4, 8)
    geometry = ObjectGeometry.of(obj, (0.6, 0.3))
    assert geometry.n_links == 4 and geometry.base_point_xy == (0.6, 0.3)
    assert isinstance(configuration_feasible(geometry, np.full(4, 90.0)), Feasibility)


def test_a_physical_execution_is_given_one_shared_tolerance_the_plan_is_not():
    from planhrc.geometry import EXECUTION, STRICT

    hanging = [90, 90, 90, 0, 10]  # link 5's end 2 cm past the far edge: the bar still rests on the table
    strict = configuration_feasible(FIVE, hanging, reach_links=())
    assert [(r.code, r.link) for r in strict.reasons] == [("off_table", 5)] and strict.reasons[0].distance_m < 0.03
    assert configuration_feasible(FIVE, hanging, reach_links=(), tolerance=STRICT) == strict
    assert configuration_feasible(FIVE, hanging, reach_links=(), tolerance=EXECUTION).ok
    assert not configuration_feasible(FIVE, [90, 90, 0, 0, 0], tolerance=EXECUTION).ok  # 9 cm past: off
    # two bars side by side, their centre lines 2.5 cm apart (a link is 3 cm wide): as planned, an overlap
    u_turn = ObjectGeometry((0.155, 0.025, 0.155))
    side_by_side = [90, 0, 270]
    assert "overlap" in configuration_feasible(u_turn, side_by_side, min_fold_gap_deg=0).codes
    assert configuration_feasible(u_turn, side_by_side, min_fold_gap_deg=0, tolerance=EXECUTION).ok
