"""Build `ontology/planhrc.owl`, the planHRC TBox, with owlready2.

Run `python ontology/build_tbox.py` after changing this file; a test checks that the committed OWL file is
what this script writes. The TBox holds

* the paper's classes and properties (Type, Link, Joint, Orientation, Predicate and its subclasses,
  CondPredicate, Action, RotateClockwise, RotateAntiClockwise, State, Problem, Plan) with the paper's
  cardinalities;
* the PDDL domain model of each formulation as individuals (DomainModel, ActionSchema, Variable,
  AtomPattern, ConditionalEffectPattern), so that the translator writes the PDDL domain from the TBox alone:
  relative and absolute here, and the bimanual one with the classes it adds (grippers, the centre) in `bimanual`;
* SWRL rules (`rules.SWRL_RULES`) that derive the chain structure (which joint turns which link, which joints lie
  downstream, hence the `Affected` facts) and relative joint angles from observed absolute link orientations.
"""
from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

from owlready2 import (
    AllDisjoint,
    AnnotationProperty,
    DataProperty,
    FunctionalProperty,
    Imp,
    ObjectProperty,
    Ontology,
    Thing,
    TransitiveProperty,
    World,
    comment,
    label,
)

from planhrc.ontology.bimanual import build_bimanual_model, declare_bimanual
from planhrc.ontology.patterns import Patterns
from planhrc.ontology.rules import SWRL_RULES

IRI = "http://planhrc.org/ontology/planhrc.owl#"
OUT = Path(__file__).resolve().parent / "planhrc.owl"


def build(path: Path = OUT) -> Path:
    world = World()
    onto = world.get_ontology(IRI[:-1])
    with onto:
        # ---- annotations used by the translator ------------------------------------------------------
        class pddlName(AnnotationProperty):
            comment = ["The PDDL name of a class, predicate, schema or variable."]

        class pddlParameters(AnnotationProperty):
            comment = ["PDDL parameter list of a predicate declaration, e.g. '?o - orientation ?j - joint'."]

        class pddlArgumentOrder(AnnotationProperty):
            comment = ["Which OWL argument properties give the PDDL arguments, in PDDL order, e.g. 'arg2 arg1'."]

        class pddlRequirements(AnnotationProperty):
            comment = ["PDDL :requirements of a domain model, space separated."]

        class pddlTypes(AnnotationProperty):
            comment = ["PDDL :types of a domain model, space separated."]

        # ---- types --------------------------------------------------------------------------------------
        class Type(Thing):
            comment = ["PDDL types: the things a planning action can take as parameters."]

        class Link(Type):
            comment = ["A rigid link of an articulated object."]
            pddlName = ["link"]

        class Joint(Type):
            comment = ["A revolute joint about the table normal; carries one orientation in a state."]
            pddlName = ["joint"]

        class Orientation(Type):
            comment = ["An allowed orientation value, in integer degrees (clockwise seen from above)."]
            pddlName = ["orientation"]

        AllDisjoint([Link, Joint, Orientation])

        class ArticulatedObject(Thing):
            comment = ["An articulated object: ordered links, joints and the allowed orientation set."]

        class degrees(DataProperty, FunctionalProperty):
            domain = [Orientation]
            range = [int]

        class lengthM(DataProperty, FunctionalProperty):
            domain = [Link]
            range = [float]

        class chainIndex(DataProperty, FunctionalProperty):
            comment = ["Position of a link or joint in its chain (the virtual link l0 has index 0)."]
            range = [int]

        class formulation(DataProperty, FunctionalProperty):
            comment = ["'relative', 'absolute' or 'bimanual'."]
            range = [str]

        class objectName(DataProperty, FunctionalProperty):
            range = [str]

        class isVirtual(DataProperty, FunctionalProperty):
            domain = [Link]
            range = [bool]

        class hasLink(ObjectProperty):
            domain = [ArticulatedObject]
            range = [Link]

        class hasJoint(ObjectProperty):
            domain = [ArticulatedObject]
            range = [Joint]

        class allowedOrientation(ObjectProperty):
            domain = [ArticulatedObject]
            range = [Orientation]

        class nextLink(ObjectProperty, FunctionalProperty):
            comment = ["Chain order: the next link downstream."]
            domain = [Link]
            range = [Link]

        ArticulatedObject.is_a.append(hasLink.min(2, Link))
        ArticulatedObject.is_a.append(hasJoint.min(1, Joint))
        ArticulatedObject.is_a.append(allowedOrientation.min(2, Orientation))
        Orientation.is_a.append(degrees.exactly(1, int))

        # ---- predicates -----------------------------------------------------------------------------------
        class Predicate(Thing):
            comment = ["A ground predicate, reified: its arguments are arg1, arg2, arg3."]

        class arg1(ObjectProperty, FunctionalProperty):
            domain = [Predicate]

        class arg2(ObjectProperty, FunctionalProperty):
            domain = [Predicate]

        class arg3(ObjectProperty, FunctionalProperty):
            domain = [Predicate]

        class Connected(Predicate):
            comment = ["Connected(j, l): joint j is attached to link l."]
            pddlName = ["connected"]
            pddlParameters = ["?j - joint ?l - link"]
            pddlArgumentOrder = ["arg1 arg2"]

        Connected.is_a += [arg1.some(Joint), arg1.exactly(1), arg2.some(Link), arg2.exactly(1)]

        class HasOrientation(Predicate):
            comment = ["HasOrientation(j, o): joint j carries orientation o (absolute or relative by formulation)."]
            pddlName = ["hasorientation"]
            pddlParameters = ["?o - orientation ?j - joint"]
            pddlArgumentOrder = ["arg2 arg1"]

        HasOrientation.is_a += [arg1.some(Joint), arg1.exactly(1), arg2.some(Orientation), arg2.exactly(1)]

        class OrientationOrd(Predicate):
            comment = ["OrientationOrd(o1, o2): o2 follows o1 in the allowed orientation set (wrapping)."]
            pddlName = ["orientationord"]
            pddlParameters = ["?o1 - orientation ?o2 - orientation"]
            pddlArgumentOrder = ["arg1 arg2"]

        OrientationOrd.is_a += [arg1.some(Orientation), arg1.exactly(1), arg2.some(Orientation), arg2.exactly(1)]

        class Affected(Predicate):
            comment = ["Affected(j2, l, j1): turning link l about joint j1 changes the orientation of joint j2."]
            pddlName = ["affected"]
            pddlParameters = ["?j2 - joint ?l - link ?j1 - joint"]
            pddlArgumentOrder = ["arg1 arg2 arg3"]

        Affected.is_a += [
            arg1.some(Joint), arg1.exactly(1), arg2.some(Link), arg2.exactly(1), arg3.some(Joint), arg3.exactly(1)
        ]

        class LinkOrientation(Predicate):
            comment = ["LinkOrientation(l, o): a perceived absolute orientation of link l (not a planning predicate)."]

        LinkOrientation.is_a += [arg1.some(Link), arg1.exactly(1), arg2.some(Orientation), arg2.exactly(1)]

        AllDisjoint([Connected, HasOrientation, OrientationOrd, Affected, LinkOrientation])

        class forall(ObjectProperty):
            comment = ["Variables quantified by a conditional effect."]

        class when(ObjectProperty):
            comment = ["Conditions of a conditional effect."]

        class effNeg_a(ObjectProperty):
            label = ["eff-_a"]
            comment = ["Additional negative effects of a conditional effect."]

        class effPos_a(ObjectProperty):
            label = ["eff+_a"]
            comment = ["Additional positive effects of a conditional effect."]

        class CondPredicate(Predicate):
            comment = ["A conditional effect: for all `forall` values, when `when` holds, apply eff-_a and eff+_a."]

        CondPredicate.is_a += [
            forall.some(Type), forall.min(1), when.some(Predicate), when.min(1),
            effNeg_a.some(Predicate), effNeg_a.min(1), effPos_a.some(Predicate), effPos_a.min(1),
        ]

        # ---- actions, states, problems, plans ---------------------------------------------------------------
        class params(ObjectProperty):
            comment = ["Parameters of an action (ordered by paramIndex of the ActionParameter individuals)."]

        class pre(ObjectProperty):
            comment = ["Preconditions."]

        class effNeg(ObjectProperty):
            label = ["eff-"]
            comment = ["Negative effects."]

        class effPos(ObjectProperty):
            label = ["eff+"]
            comment = ["Positive effects."]

        class condEff(ObjectProperty):
            comment = ["Conditional effects."]

        class Action(Thing):
            comment = ["A ground action of a plan."]

        Action.is_a += [
            params.some(Type), params.min(1), pre.some(Predicate), pre.min(1),
            effNeg.some(Predicate), effNeg.min(1), effPos.some(Predicate), effPos.min(1),
        ]

        class RotateClockwise(Action):
            comment = ["Moves the orientation carried by a joint one step forward (+step, clockwise seen from above)."]
            pddlName = ["rotateclockwise"]

        class RotateAntiClockwise(Action):
            comment = ["Moves the orientation carried by a joint one step back (-step)."]
            pddlName = ["rotateanticlockwise"]

        AllDisjoint([RotateClockwise, RotateAntiClockwise])

        class stepIndex(DataProperty, FunctionalProperty):
            comment = ["Position of an action in its plan (1-based) or of an expected state (1..N+1)."]
            range = [int]

        class paramList(DataProperty, FunctionalProperty):
            comment = ["The action's PDDL arguments in order, space separated (params gives them as individuals)."]
            range = [str]

        class nextAction(ObjectProperty, FunctionalProperty):
            domain = [Action]
            range = [Action]

        class madeof(ObjectProperty):
            comment = ["A State is made of Predicates; a Plan is made of Actions."]

        class State(Thing):
            comment = ["A set of ground predicates."]

        State.is_a += [madeof.some(Predicate), madeof.min(1)]

        class PerceivedState(State):
            comment = ["A state built from a perception (complete)."]

        class ExpectedState(State):
            comment = ["An expected intermediate state of a plan."]

        class GoalState(State):
            comment = ["A goal state (may be partial)."]

        class InitialState(State):
            comment = ["An initial state given by the user rather than perceived (complete)."]

        class observes(ObjectProperty):
            comment = ["The perceived absolute link orientations behind a perceived state."]
            domain = [PerceivedState]
            range = [LinkOrientation]

        class stateOf(ObjectProperty, FunctionalProperty):
            domain = [State]
            range = [ArticulatedObject]

        class aboutObject(ObjectProperty, FunctionalProperty):
            comment = ["The articulated object a problem, plan or action is about."]
            range = [ArticulatedObject]

        class observedDegrees(DataProperty, FunctionalProperty):
            comment = ["The raw perceived angle (degrees) behind an observed LinkOrientation, before snapping."]
            domain = [LinkOrientation]
            range = [float]

        class staticFactOf(ObjectProperty):
            comment = ["staticFactOf(p, x): predicate p (Connected, OrientationOrd, Affected) holds in every state"
                       " of object x; states that include their object's static facts say so with"
                       " includesStaticFacts, and a SWRL rule derives their madeof links."]
            domain = [Predicate]
            range = [ArticulatedObject]

        class includesStaticFacts(DataProperty, FunctionalProperty):
            comment = ["A state made of its object's static facts (every staticFactOf predicate) besides the"
                       " predicates it lists with madeof."]
            domain = [State]
            range = [bool]

        class createdAt(DataProperty, FunctionalProperty):
            range = [float]

        class init(ObjectProperty, FunctionalProperty):
            range = [State]

        class goal(ObjectProperty, FunctionalProperty):
            range = [State]

        class Problem(Thing):
            comment = ["A planning problem: exactly one initial and one goal state."]

        Problem.is_a += [init.some(State), init.exactly(1), goal.some(State), goal.exactly(1)]

        class Plan(Thing):
            comment = ["An ordered set of actions (ordered by stepIndex and nextAction)."]

        Plan.is_a += [madeof.some(Action), madeof.min(1)]

        class solves(ObjectProperty, FunctionalProperty):
            domain = [Plan]
            range = [Problem]

        class expectedState(ObjectProperty):
            comment = ["The expected states s^e_1 .. s^e_{N+1} of a plan (ordered by stepIndex)."]
            domain = [Plan]
            range = [ExpectedState]

        class plannerName(DataProperty, FunctionalProperty):
            domain = [Plan]
            range = [str]

        # ---- chain structure derived by SWRL ------------------------------------------------------------
        class turns(ObjectProperty):
            comment = ["turns(j, l): l is the link that turns about joint j (the downstream one)."]
            domain = [Joint]
            range = [Link]

        class downstreamJoint(ObjectProperty, TransitiveProperty):
            comment = ["downstreamJoint(j, k): joint k lies downstream of joint j in the chain."]
            domain = [Joint]
            range = [Joint]

        class nextJoint(downstreamJoint):
            comment = ["nextJoint(j, k): k is the joint right after j."]

        class affectsJoint(ObjectProperty):
            comment = ["affectsJoint(j, k): turning the link that turns about j changes the orientation of k;"
                       " with turns(j, l) this is Affected(k, l, j)."]
            domain = [Joint]
            range = [Joint]

        class relativeOrientation(ObjectProperty, FunctionalProperty):
            comment = ["relativeOrientation(p, o): for an observed LinkOrientation p of a link, o is its angle"
                       " relative to the upstream link's observed orientation in the same perceived state."]
            domain = [LinkOrientation]
            range = [Orientation]

        for text in SWRL_RULES:
            Imp().set_as_rule(text)

        # ---- the PDDL domain model of both formulations -----------------------------------------------------
        class DomainModel(Thing):
            comment = ["A PDDL domain: one per formulation."]

        class ActionSchema(Thing):
            comment = ["A PDDL action schema, describing an Action subclass."]

        class Variable(Thing):
            comment = ["A PDDL variable of a schema."]

        class AtomPattern(Thing):
            comment = ["A (possibly negated) literal over variables: a predicate class and its argument variables."]

        class ConditionalEffectPattern(Thing):
            comment = ["forall variables, when conditions, eff-_a and eff+_a of a schema."]

        class hasSchema(ObjectProperty):
            domain = [DomainModel]
            range = [ActionSchema]

        class hasParameter(ObjectProperty):
            range = [Variable]

        class variableType(ObjectProperty, FunctionalProperty):
            comment = ["The PDDL type of a variable, given as an individual naming a Type subclass."]
            domain = [Variable]

        class typeName(DataProperty, FunctionalProperty):
            domain = [Variable]
            range = [str]

        class position(DataProperty, FunctionalProperty):
            comment = ["Order of a parameter, precondition or effect within its list."]
            range = [int]

        class predicateName(DataProperty, FunctionalProperty):
            comment = ["pddlName of the Predicate subclass an AtomPattern instantiates, or '=' for equality."]
            domain = [AtomPattern]
            range = [str]

        class negated(DataProperty, FunctionalProperty):
            domain = [AtomPattern]
            range = [bool]

        class argVar1(ObjectProperty, FunctionalProperty):
            domain = [AtomPattern]
            range = [Variable]

        class argVar2(ObjectProperty, FunctionalProperty):
            domain = [AtomPattern]
            range = [Variable]

        class argVar3(ObjectProperty, FunctionalProperty):
            domain = [AtomPattern]
            range = [Variable]

        class precondition(ObjectProperty):
            range = [AtomPattern]

        class deleteEffect(ObjectProperty):
            label = ["eff-"]
            range = [AtomPattern]

        class addEffect(ObjectProperty):
            label = ["eff+"]
            range = [AtomPattern]

        class conditionalEffect(ObjectProperty):
            label = ["condEff"]
            domain = [ActionSchema]
            range = [ConditionalEffectPattern]

        class forallVariable(ObjectProperty):
            domain = [ConditionalEffectPattern]
            range = [Variable]

        class whenCondition(ObjectProperty):
            domain = [ConditionalEffectPattern]
            range = [AtomPattern]

        class schemaFormulation(DataProperty, FunctionalProperty):
            range = [str]

        class describesActionName(DataProperty, FunctionalProperty):
            comment = ["pddlName of the Action subclass this schema describes."]
            domain = [ActionSchema]
            range = [str]

        ns = locals()
        ns.update(declare_bimanual(ns))
        _build_domain_models(onto, ns)
        build_bimanual_model(ns)

    onto.save(file=str(path), format="rdfxml")
    return path


def _build_domain_models(onto: Ontology, ns: dict[str, Any]) -> None:
    """Individuals describing the two PDDL domains (paper figures 'relative' and 'conditional' RotateClockwise)."""
    DomainModel, ActionSchema = ns["DomainModel"], ns["ActionSchema"]
    CondPattern = ns["ConditionalEffectPattern"]
    patterns = Patterns(ns)
    var, atom = patterns.var, patterns.atom

    for form, requirements in (
        ("relative", ":strips :typing :equality :negative-preconditions"),
        ("absolute", ":strips :typing :equality :negative-preconditions :conditional-effects"),
    ):
        dm = DomainModel(f"{form}_domain")
        dm.pddlName = [f"planhrc-{form}"]
        dm.pddlRequirements = [requirements]
        dm.pddlTypes = ["link joint orientation"]
        for order, (action, forward) in enumerate((("rotateclockwise", True), ("rotateanticlockwise", False)), 1):
            p = f"{form}_{action}"
            s = ActionSchema(p)
            s.position = order
            s.describesActionName = action
            s.schemaFormulation = form
            l1, l2 = var(p, "l1", "link", 1), var(p, "l2", "link", 2)
            j1 = var(p, "j1", "joint", 3)
            o1, o2 = var(p, "o1", "orientation", 4), var(p, "o2", "orientation", 5)
            s.hasParameter = [l1, l2, j1, o1, o2]
            pre = [
                atom(p, "pre", 1, "connected", [j1, l1]),
                atom(p, "pre", 2, "connected", [j1, l2]),
                atom(p, "pre", 3, "=", [l1, l2], negated=True),
                atom(p, "pre", 4, "hasorientation", [j1, o1]),
                atom(p, "pre", 5, "orientationord", [o1, o2] if forward else [o2, o1]),
            ]
            if form == "absolute":
                pre.append(atom(p, "pre", 6, "affected", [j1, l1, j1]))
            s.precondition = pre
            s.deleteEffect = [atom(p, "del", 1, "hasorientation", [j1, o1])]
            s.addEffect = [atom(p, "add", 2, "hasorientation", [j1, o2])]
            if form == "absolute":
                ce = CondPattern(f"{p}_condeff_1")
                ce.position = 1
                j2 = var(p, "j2", "joint", 6)
                o3, o4 = var(p, "o3", "orientation", 7), var(p, "o4", "orientation", 8)
                ce.forallVariable = [j2, o3, o4]
                ce.whenCondition = [
                    atom(p, "when", 1, "affected", [j2, l1, j1]),
                    atom(p, "when", 2, "=", [j2, j1], negated=True),
                    atom(p, "when", 3, "hasorientation", [j2, o3]),
                    atom(p, "when", 4, "orientationord", [o3, o4] if forward else [o4, o3]),
                ]
                ce.effNeg_a = [atom(p, "cdel", 1, "hasorientation", [j2, o3])]
                ce.effPos_a = [atom(p, "cadd", 2, "hasorientation", [j2, o4])]
                s.conditionalEffect = [ce]
            dm.hasSchema.append(s)


if __name__ == "__main__":
    out = build(Path(sys.argv[1]) if len(sys.argv) > 1 else OUT)
    print(f"wrote {out}")
