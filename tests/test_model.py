"""Unit tests of the shared object model: names, static facts, snapping and angle conversions."""
import math

import pytest

from planhrc.model import (
    AFFECTED,
    ModelError,
    absolute_from_relative,
    is_subsumed,
    make_object,
    relative_from_absolute,
    snap_angle,
)


def test_absolute_object_has_virtual_link_and_n_joints():
    obj = make_object("obj1", "absolute", 5, 8)
    assert obj.n_joints == 5
    assert obj.all_links[0] == "obj1_l0"
    assert obj.joint_links(1) == ("obj1_l0", "obj1_l1")


def test_relative_object_has_n_minus_one_joints():
    obj = make_object("obj1", "relative", 5, 8)
    assert obj.joints == ("obj1_j1", "obj1_j2", "obj1_j3", "obj1_j4")
    assert obj.joint_links(4) == ("obj1_l4", "obj1_l5")
    assert not obj.affected_atoms()


def test_affected_lists_downstream_joints_and_the_turned_joint():
    obj = make_object("o", "absolute", 4, 4)
    aff = {(a[1], a[2], a[3]) for a in obj.affected_atoms()}
    assert ("o_j4", "o_l2", "o_j2") in aff
    assert ("o_j2", "o_l2", "o_j2") in aff
    assert ("o_j1", "o_l2", "o_j2") not in aff
    assert len(aff) == 4 + 3 + 2 + 1
    assert all(a[0] == AFFECTED for a in obj.affected_atoms())


@pytest.mark.parametrize(
    "angle,k,expected",
    [(44.9, 4, 0), (45.0, 4, 0), (45.1, 4, 90), (-10, 4, 0), (346, 12, 0), (344.9, 12, 330), (719.0, 4, 0)],
)
def test_snap_angle(angle, k, expected):
    assert snap_angle(angle, k) == expected


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_snap_rejects_non_finite(bad):
    with pytest.raises(ModelError, match="finite"):
        snap_angle(bad, 4)


def test_relative_absolute_round_trip():
    links = (30, 330, 0, 90, 60)
    rel = relative_from_absolute(links)
    assert rel == (300, 30, 90, 330)
    assert absolute_from_relative(30, rel) == links


def test_bad_values_are_refused_with_field_names():
    obj = make_object("o", "relative", 3, 4)
    with pytest.raises(ModelError, match="joint_angles_deg"):
        obj.configuration_atoms([0])
    with pytest.raises(ModelError, match=r"joint_angles_deg\[1\]"):
        obj.configuration_atoms([0, 45])
    with pytest.raises(ModelError, match="orientations"):
        make_object("o", "relative", 3, 7)
    with pytest.raises(ModelError, match="formulation"):
        make_object("o", "sideways", 3, 4)


def test_subsumption_is_superset_check():
    obj = make_object("o", "relative", 3, 4)
    full = obj.state([0, 90])
    goal = frozenset({("hasorientation", "deg_90", "o_j2")})
    assert is_subsumed(full, goal)
    assert not is_subsumed(goal, full)
    assert not is_subsumed(obj.state([0, 180]), goal)


def test_partial_configuration_atoms_leave_free_joints_out():
    obj = make_object("o", "absolute", 3, 4)
    atoms = obj.partial_configuration_atoms([450, None, 0.0])
    assert atoms == {("hasorientation", "deg_90", "o_j1"), ("hasorientation", "deg_0", "o_j3")}
    for values, match in [([45, None, None], r"goal\[0\]"), ([None, None, None], "at least one"),
                          ([0, 0], "expected 3 values"), ([math.inf, 0, 0], "finite")]:
        with pytest.raises(ModelError, match=match):
            obj.partial_configuration_atoms(values)
