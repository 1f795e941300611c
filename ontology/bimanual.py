"""The bimanual formulation in the TBox: the classes it adds to the paper's, and its PDDL domain model.

The same authors' later formulation has two grippers work on one joint at a time, at a working position, the
"centre". Ours (docs/planning.md states it in full):

* links l1 .. lN, joints j1 .. j(N-1); jK joins lK and l(K+1) and carries the orientation of l(K+1) measured
  from l1 (l1 itself never turns: the robot always turns the downstream link), so turning l(K+1) about jK moves
  jK and every joint after it: the absolute formulation's `Affected` facts and conditional effect;
* two grippers, `left` and `right`; the object's static fact `Keeper(left)` says which one keeps the upstream link
  still while the other turns the downstream one;
* `MoveToCentre` brings both open hands to another joint (the centre), `GraspLinks` closes them on the two links
  the centred joint joins, `RotateClockwise` / `RotateAntiClockwise` turn the held downstream link one step,
  `RotateClockwise45` / `RotateAntiClockwise45` turn it 45 degrees at once (the static `OrientationOrd45` facts
  exist only where 45 degrees is several steps, K a multiple of 8 above 8), `ReleaseLinks` opens both hands.

Every schema lists the turned link, the kept link and the joint first (`?l1 ?l2 ?j1`), so a plan step says which
link turns about which joint whatever its kind.
"""
from __future__ import annotations

import types
from typing import Any, Mapping, Sequence

from owlready2 import AllDisjoint, Thing

from planhrc.ontology.patterns import Patterns

REQUIREMENTS = ":strips :typing :equality :negative-preconditions :conditional-effects"


def subclass(base: Any, name: str, **annotations: list[str]) -> Any:
    """A TBox class `name` under `base` with its annotations (`comment`, `pddlName`, ...), made in the ontology of
    the enclosing `with`: the bases come from the TBox's own namespace, which no static type checker can follow."""
    made = types.new_class(name, (base,))
    for key, value in annotations.items():
        setattr(made, key, value)
    return made


def declare_bimanual(ns: Mapping[str, Any]) -> dict[str, Any]:
    """The TBox classes the bimanual formulation needs beyond the paper's; call inside the ontology's `with`."""
    Type, Predicate, Action = ns["Type"], ns["Predicate"], ns["Action"]
    arg1, arg2 = ns["arg1"], ns["arg2"]
    Link, Joint, Orientation = ns["Link"], ns["Joint"], ns["Orientation"]

    Gripper = subclass(Type, "Gripper",
        comment=["A gripper of the robot (Baxter's left and right)."],
        pddlName=["gripper"])

    AllDisjoint([Link, Joint, Orientation, Gripper])

    Free = subclass(Predicate, "Free",
        comment=["Free(g): gripper g holds nothing."],
        pddlName=["free"],
        pddlParameters=["?g - gripper"],
        pddlArgumentOrder=["arg1"])

    Free.is_a += [arg1.some(Gripper), arg1.exactly(1)]

    Holding = subclass(Predicate, "Holding",
        comment=["Holding(g, l): gripper g holds link l."],
        pddlName=["holding"],
        pddlParameters=["?g - gripper ?l - link"],
        pddlArgumentOrder=["arg1 arg2"])

    Holding.is_a += [arg1.some(Gripper), arg1.exactly(1), arg2.some(Link), arg2.exactly(1)]

    InCentre = subclass(Predicate, "InCentre",
        comment=["InCentre(j): joint j is at the working position, where both hands work."],
        pddlName=["incentre"],
        pddlParameters=["?j - joint"],
        pddlArgumentOrder=["arg1"])

    InCentre.is_a += [arg1.some(Joint), arg1.exactly(1)]

    Keeper = subclass(Predicate, "Keeper",
        comment=["Keeper(g): gripper g keeps the upstream link still while the other gripper turns the downstream"
                " one (a static fact of a bimanual object)."],
        pddlName=["keeper"],
        pddlParameters=["?g - gripper"],
        pddlArgumentOrder=["arg1"])

    Keeper.is_a += [arg1.some(Gripper), arg1.exactly(1)]

    OrientationOrd45 = subclass(Predicate, "OrientationOrd45",
        comment=["OrientationOrd45(o1, o2): o2 lies 45 degrees clockwise of o1 (asserted where 45 degrees is"
                " several steps of the orientation set)."],
        pddlName=["orientationord45"],
        pddlParameters=["?o1 - orientation ?o2 - orientation"],
        pddlArgumentOrder=["arg1 arg2"])

    OrientationOrd45.is_a += [arg1.some(Orientation), arg1.exactly(1), arg2.some(Orientation), arg2.exactly(1)]

    AllDisjoint([ns["Connected"], ns["HasOrientation"], ns["OrientationOrd"], ns["Affected"], ns["LinkOrientation"],
                 Free, Holding, InCentre, Keeper, OrientationOrd45])

    MoveToCentre = subclass(Action, "MoveToCentre",
        comment=["Brings both open hands to another joint: that joint is at the centre from then on."],
        pddlName=["movetocentre"])

    GraspLinks = subclass(Action, "GraspLinks",
        comment=["Closes both hands on the two links the centred joint joins: the keeper on the upstream link."],
        pddlName=["grasplinks"])

    ReleaseLinks = subclass(Action, "ReleaseLinks",
        comment=["Opens both hands."],
        pddlName=["releaselinks"])

    RotateClockwise45 = subclass(Action, "RotateClockwise45",
        comment=["Turns the held downstream link 45 degrees clockwise (seen from above) at once."],
        pddlName=["rotateclockwise45"])

    RotateAntiClockwise45 = subclass(Action, "RotateAntiClockwise45",
        comment=["Turns the held downstream link 45 degrees anticlockwise at once."],
        pddlName=["rotateanticlockwise45"])

    AllDisjoint([ns["RotateClockwise"], ns["RotateAntiClockwise"], MoveToCentre, GraspLinks, ReleaseLinks,
                 RotateClockwise45, RotateAntiClockwise45])
    return {c.__name__: c for c in (Gripper, Free, Holding, InCentre, Keeper, OrientationOrd45, MoveToCentre,
                                    GraspLinks, ReleaseLinks, RotateClockwise45, RotateAntiClockwise45)}


def build_bimanual_model(ns: Mapping[str, Any]) -> Thing:
    """The DomainModel individual `bimanual_domain` and its action schemas."""
    patterns = Patterns(ns)
    var, atom = patterns.var, patterns.atom
    dm = ns["DomainModel"]("bimanual_domain")
    dm.pddlName = ["planhrc-bimanual"]
    dm.pddlRequirements = [REQUIREMENTS]
    dm.pddlTypes = ["link joint orientation gripper"]

    def schema(order: int, action: str) -> tuple[Thing, str, dict[str, Thing]]:
        """A schema with the parameters every bimanual action starts with: turned link, kept link, joint."""
        p = f"bimanual_{action}"
        s = ns["ActionSchema"](p)
        s.position = order
        s.describesActionName = action
        s.schemaFormulation = "bimanual"
        v = {"l1": var(p, "l1", "link", 1), "l2": var(p, "l2", "link", 2), "j1": var(p, "j1", "joint", 3)}
        dm.hasSchema.append(s)
        return s, p, v

    def joined(p: str, v: Mapping[str, Thing], start: int) -> list[Thing]:
        """?j1 joins ?l1 and ?l2, and ?l1 is the link that turns about it (the reflexive Affected fact)."""
        return [atom(p, "pre", start, "connected", [v["j1"], v["l1"]]),
                atom(p, "pre", start + 1, "connected", [v["j1"], v["l2"]]),
                atom(p, "pre", start + 2, "=", [v["l1"], v["l2"]], negated=True),
                atom(p, "pre", start + 3, "affected", [v["j1"], v["l1"], v["j1"]])]

    def hands(p: str, v: Mapping[str, Thing], start: int, pred: str) -> list[Thing]:
        """Both grippers `free` (or `holding` their links), ?g2 the keeper and ?g1 the other one."""
        which = [[v["g1"]], [v["g2"]]] if pred == "free" else [[v["g1"], v["l1"]], [v["g2"], v["l2"]]]
        return [atom(p, "pre", start, pred, which[0]), atom(p, "pre", start + 1, pred, which[1]),
                atom(p, "pre", start + 2, "keeper", [v["g2"]]),
                atom(p, "pre", start + 3, "=", [v["g1"], v["g2"]], negated=True)]

    def grippers(p: str, v: dict[str, Thing], first: int) -> None:
        v["g1"], v["g2"] = var(p, "g1", "gripper", first), var(p, "g2", "gripper", first + 1)

    # movetocentre ?l1 ?l2 ?j1 ?j2 ?g1 ?g2: both hands free go from joint ?j2 to joint ?j1
    s, p, v = schema(1, "movetocentre")
    v["j2"] = var(p, "j2", "joint", 4)
    grippers(p, v, 5)
    s.hasParameter = [v[n] for n in ("l1", "l2", "j1", "j2", "g1", "g2")]
    s.precondition = joined(p, v, 1) + [atom(p, "pre", 5, "incentre", [v["j2"]]),
                                        atom(p, "pre", 6, "=", [v["j1"], v["j2"]], negated=True)] + hands(
        p, v, 7, "free")
    s.deleteEffect = [atom(p, "del", 1, "incentre", [v["j2"]])]
    s.addEffect = [atom(p, "add", 2, "incentre", [v["j1"]])]

    # grasplinks / releaselinks ?l1 ?l2 ?j1 ?g1 ?g2: at the centred joint, ?g1 takes ?l1 and the keeper ?g2 takes ?l2
    for order, action, before, after in ((2, "grasplinks", "free", "holding"), (3, "releaselinks", "holding", "free")):
        s, p, v = schema(order, action)
        grippers(p, v, 4)
        s.hasParameter = [v[n] for n in ("l1", "l2", "j1", "g1", "g2")]
        s.precondition = joined(p, v, 1) + [atom(p, "pre", 5, "incentre", [v["j1"]])] + hands(p, v, 6, before)
        drop = [[v["g1"]], [v["g2"]]] if before == "free" else [[v["g1"], v["l1"]], [v["g2"], v["l2"]]]
        take = [[v["g1"]], [v["g2"]]] if after == "free" else [[v["g1"], v["l1"]], [v["g2"], v["l2"]]]
        s.deleteEffect = [atom(p, "del", i, before, args) for i, args in enumerate(drop, start=1)]
        s.addEffect = [atom(p, "add", i, after, args) for i, args in enumerate(take, start=3)]

    # the turns ?l1 ?l2 ?j1 ?o1 ?o2 ?g1 ?g2: one step, or 45 degrees, of the held downstream link
    turns = (("rotateclockwise", "orientationord", True), ("rotateanticlockwise", "orientationord", False),
             ("rotateclockwise45", "orientationord45", True), ("rotateanticlockwise45", "orientationord45", False))
    for order, (action, ordering, forward) in enumerate(turns, start=4):
        s, p, v = schema(order, action)
        v["o1"], v["o2"] = var(p, "o1", "orientation", 4), var(p, "o2", "orientation", 5)
        grippers(p, v, 6)
        s.hasParameter = [v[n] for n in ("l1", "l2", "j1", "o1", "o2", "g1", "g2")]
        s.precondition = joined(p, v, 1) + [atom(p, "pre", 5, "incentre", [v["j1"]])] + hands(p, v, 6, "holding") + [
            atom(p, "pre", 10, "hasorientation", [v["j1"], v["o1"]]),
            atom(p, "pre", 11, ordering, _along([v["o1"], v["o2"]], forward))]
        s.deleteEffect = [atom(p, "del", 1, "hasorientation", [v["j1"], v["o1"]])]
        s.addEffect = [atom(p, "add", 2, "hasorientation", [v["j1"], v["o2"]])]
        ce = ns["ConditionalEffectPattern"](f"{p}_condeff_1")
        ce.position = 1
        j2 = var(p, "j2", "joint", 8)
        o3, o4 = var(p, "o3", "orientation", 9), var(p, "o4", "orientation", 10)
        ce.forallVariable = [j2, o3, o4]
        ce.whenCondition = [atom(p, "when", 1, "affected", [j2, v["l1"], v["j1"]]),
                            atom(p, "when", 2, "=", [j2, v["j1"]], negated=True),
                            atom(p, "when", 3, "hasorientation", [j2, o3]),
                            atom(p, "when", 4, ordering, _along([o3, o4], forward))]
        ce.effNeg_a = [atom(p, "cdel", 1, "hasorientation", [j2, o3])]
        ce.effPos_a = [atom(p, "cadd", 2, "hasorientation", [j2, o4])]
        s.conditionalEffect = [ce]
    return dm


def _along(pair: Sequence[Thing], forward: bool) -> list[Thing]:
    """The two orientations as the ordering relation takes them: (before, after) clockwise."""
    return list(pair) if forward else list(pair)[::-1]
