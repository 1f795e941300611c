"""The TBox's SWRL rules, as owlready2 reads them (`Imp().set_as_rule`): written once, here, for the TBox builder
(`build_tbox`, which states them in `planhrc.owl`) and the service's in-process entailment
(`kb_service.knowledge.entailment`, which applies them without a reasoner). A test checks that the TBox holds
exactly these.

1. the link that turns about a joint is the downstream one of the two links it connects;
2. the joint right after j is the one about which the link after j's link turns;
3. and 4. turning about j changes the orientation carried by j and by every joint downstream of it (`Affected`);
5. a state that includes its object's static facts is made of them;
6. the relative orientation of an observed link, from two absolute observations of one perceived state.
"""
from __future__ import annotations

SWRL_RULES = (
    "Connected(?c), arg1(?c, ?j), arg2(?c, ?l), Connected(?d), arg1(?d, ?j), arg2(?d, ?u), nextLink(?u, ?l)"
    " -> turns(?j, ?l)",
    "turns(?j, ?l), nextLink(?l, ?m), turns(?k, ?m) -> nextJoint(?j, ?k)",
    "turns(?j, ?l), downstreamJoint(?j, ?k) -> affectsJoint(?j, ?k)",
    "turns(?j, ?l) -> affectsJoint(?j, ?j)",
    "State(?s), includesStaticFacts(?s, true), stateOf(?s, ?x), staticFactOf(?p, ?x) -> madeof(?s, ?p)",
    "PerceivedState(?s), observes(?s, ?p), observes(?s, ?q), arg1(?p, ?a), arg1(?q, ?b), nextLink(?a, ?b),"
    " arg2(?p, ?oa), arg2(?q, ?ob), degrees(?oa, ?x), degrees(?ob, ?y), subtract(?d, ?y, ?x),"
    " add(?e, ?d, 360), mod(?r, ?e, 360), Orientation(?o), degrees(?o, ?r) -> relativeOrientation(?q, ?o)",
)
