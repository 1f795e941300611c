"""How the knowledge base names what it stores: the IRIs of the TBox and the ABox, the OWL class of each state
kind and action, and the readable IRI fragment of each ground predicate.

Every ABox individual goes into the ontology `http://planhrc.org/abox#` with a readable IRI whose fragment is the
PDDL name (`obj42_l3`, `obj42_j3`, `deg_90`) or a name built from it (`obj42_state_7`, `obj42_ho_j3_90`,
`obj42_connected_j3_l2`, `obj42_plan_2_a5`). A ground predicate is one individual of its object, whichever
states and actions it belongs to (as the paper writes `has_orientation_j1_45`): a state is the set of predicate
individuals it is `madeof`, so a new state costs its `madeof` links, not new predicates.

Nothing here depends on how a backend keeps the triples: every backend names the same individuals the same way,
so the RDF export and the reasoners read the same ontology from any of them.
"""
from __future__ import annotations

from planhrc.model import (AFFECTED, CONNECTED, FREE, HAS_ORIENTATION, HOLDING, IN_CENTRE, KEEPER, ORIENTATION_ORD,
                           ORIENTATION_ORD45, ArticulatedObject, Atom)

TBOX_IRI = "http://planhrc.org/ontology/planhrc.owl#"
ABOX_IRI = "http://planhrc.org/abox#"

STATE_CLASSES = {
    "perceived": "PerceivedState",
    "expected": "ExpectedState",
    "goal": "GoalState",
    "initial": "InitialState",
}
# States that give every joint its orientation (a goal may be partial).
COMPLETE_KINDS = frozenset({"perceived", "expected", "initial"})
ACTION_CLASSES = {"rotateclockwise": "RotateClockwise", "rotateanticlockwise": "RotateAntiClockwise",
                  # the bimanual formulation's
                  "movetocentre": "MoveToCentre", "grasplinks": "GraspLinks", "releaselinks": "ReleaseLinks",
                  "rotateclockwise45": "RotateClockwise45", "rotateanticlockwise45": "RotateAntiClockwise45"}

# PDDL predicate -> (OWL class, PDDL argument types, OWL property of each PDDL argument, IRI tag).
# The property order matches the TBox annotation pddlArgumentOrder (a test checks it).
PREDICATES: dict[str, tuple[str, tuple[str, ...], tuple[str, ...], str]] = {
    CONNECTED: ("Connected", ("joint", "link"), ("arg1", "arg2"), "connected"),
    HAS_ORIENTATION: ("HasOrientation", ("orientation", "joint"), ("arg2", "arg1"), "ho"),
    ORIENTATION_ORD: ("OrientationOrd", ("orientation", "orientation"), ("arg1", "arg2"), "ord"),
    AFFECTED: ("Affected", ("joint", "link", "joint"), ("arg1", "arg2", "arg3"), "affected"),
    # the bimanual formulation's: the robot's control facts, and its static facts
    FREE: ("Free", ("gripper",), ("arg1",), "free"),
    HOLDING: ("Holding", ("gripper", "link"), ("arg1", "arg2"), "holding"),
    IN_CENTRE: ("InCentre", ("joint",), ("arg1",), "centre"),
    KEEPER: ("Keeper", ("gripper",), ("arg1",), "keeper"),
    ORIENTATION_ORD45: ("OrientationOrd45", ("orientation", "orientation"), ("arg1", "arg2"), "ord45"),
}
PREDICATE_OF_CLASS = {v[0]: k for k, v in PREDICATES.items()}

# The TBox's classes and properties the store writes and reads.
TBOX_TERMS = (
    "ArticulatedObject Link Joint Orientation Connected HasOrientation OrientationOrd Affected LinkOrientation "
    "CondPredicate RotateClockwise RotateAntiClockwise State PerceivedState ExpectedState GoalState InitialState "
    "Problem Plan degrees lengthM chainIndex formulation objectName isVirtual hasLink hasJoint allowedOrientation "
    "nextLink arg1 arg2 arg3 forall when effNeg_a effPos_a params pre effNeg effPos condEff stepIndex paramList "
    "nextAction madeof observes stateOf aboutObject observedDegrees createdAt init goal solves expectedState "
    "plannerName position staticFactOf includesStaticFacts "
    "Gripper Free Holding InCentre Keeper OrientationOrd45 MoveToCentre GraspLinks ReleaseLinks RotateClockwise45 "
    "RotateAntiClockwise45"
).split()


def _short(obj: ArticulatedObject, name: str) -> str:
    """Short form of an argument inside an IRI fragment: `obj1_j3` -> `j3`, `deg_90` -> `90`; the robot's grippers
    (`left`, `right`) as they are."""
    if name.startswith("deg_"):
        return name[4:]
    if name in obj.grippers:
        return name
    return name[len(obj.ident) + 1:]


def atom_fragment(obj: ArticulatedObject, prefix: str, atom: Atom) -> str:
    """IRI fragment of a reified predicate: prefix + tag + arguments in OWL argument order."""
    _, _, props, tag = PREDICATES[atom[0]]
    by_prop = sorted(zip(props, atom[1:]))
    return "_".join([prefix, tag] + [_short(obj, name) for _, name in by_prop])


def record_name(object_id: str, kind: str, n: int) -> str:
    """The fragment of an object's n-th record of a kind (`state`, `problem`, `plan`): `obj42_plan_2`. The
    store counts each kind per object (counter `counter_name(object_id, kind)`), so n is never handed out twice."""
    return f"{object_id}_{kind}_{n}"


def counter_name(object_id: str, kind: str) -> str:
    return f"{object_id}:{kind}"


def action_name(plan_id: str, step: int) -> str:
    """The fragment of a plan's action at `step` (1-based): `obj42_plan_2_a5`."""
    return f"{plan_id}_a{step}"
