"""CONVENTIONS.md says what the code does: each checkable statement of it is checked here."""
import re
from pathlib import Path

from planhrc.model import make_object, natural_key, relative_from_absolute, snap_angle
from planhrc.vocabulary import (ActionOutcome, DecisionKind, ExecutionStatus, FailureReason, GiveUpReason,
                                Infeasible, PlanStatus, Remedy, Skill, StopReason)

TEXT = (Path(__file__).resolve().parents[1] / "CONVENTIONS.md").read_text()
ENUMS = (DecisionKind, Skill, ExecutionStatus, ActionOutcome, FailureReason, Remedy, GiveUpReason, StopReason,
         Infeasible, PlanStatus)


def test_a_perceived_angle_snaps_to_the_nearest_allowed_value_ties_to_the_smaller():
    assert "ties go to the smaller value" in TEXT
    assert snap_angle(44.9, 4) == 0 and snap_angle(45.0, 4) == 0 and snap_angle(45.1, 4) == 90
    assert snap_angle(359.0, 4) == 0 and snap_angle(-10.0, 12) == 0


def test_the_relative_angle_keeps_its_direction():
    assert "`(θK+1 − θK) mod 360`" in TEXT
    assert relative_from_absolute([350, 10, 0]) == (20, 350)


def test_objects_have_the_links_and_joints_the_conventions_name():
    relative, absolute = make_object("o", "relative", 3, 4), make_object("o", "absolute", 3, 4)
    assert relative.all_links == ("o_l1", "o_l2", "o_l3") and relative.joints == ("o_j1", "o_j2")
    assert absolute.all_links == ("o_l0", "o_l1", "o_l2", "o_l3") and absolute.joints == ("o_j1", "o_j2", "o_j3")
    assert ("affected", "o_j2", "o_l2", "o_j2") in absolute.affected_atoms()  # the reflexive fact


def test_names_sort_naturally():
    assert sorted(["o_l10", "o_l2", "deg_120", "deg_30"], key=natural_key) == ["deg_30", "deg_120", "o_l2", "o_l10"]


def test_the_shared_words_are_the_vocabulary():
    words = TEXT[TEXT.index("## Words"):]
    for enum in ENUMS:
        for member in enum:
            assert f"`{member.value}`" in words, member
    listed = set(re.findall(r"`([a-z_]+)`", words))
    known = {m.value for e in ENUMS for m in e}
    assert listed - known <= {"planhrc"}, listed - known
