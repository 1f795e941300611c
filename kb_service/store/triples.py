"""What each record is as ABox triples: an object (links, joints, orientations, static facts), a state, an action
and a plan, added to a batch (`unit.TripleBatch`) that the caller flushes in its transaction, on every backend.

A state's and an action's atoms are linked in a fixed order (`state_order`, `action_order`), so the same records
give the same triples; for a journalled plan that order is worked out when the plan is written out, behind the
answer (`backlog`).
"""
from __future__ import annotations

import time

from planhrc.model import Atom, Perception, orientation_name

from .checks import ObjectInfo
from .journal import JournalEntry
from .names import ACTION_CLASSES, PREDICATES, STATE_CLASSES, action_name, atom_fragment, counter_name, record_name
from .records import ActionSpec
from .unit import AboxNames, TripleBatch

# Writing order of a state: (lists only its non-static atoms?, the atoms it links with madeof, sorted).
StateOrder = tuple[bool, tuple[Atom, ...]]
# Writing order of an action: its pre, eff-, eff+ sorted, and per conditional effect (forall names, (when, eff-,
# eff+) sorted).
ActionOrder = tuple[tuple[tuple[Atom, ...], ...],
                    tuple[tuple[tuple[str, ...], tuple[tuple[Atom, ...], ...]], ...]]


def state_order(info: ObjectInfo, atoms: frozenset[Atom]) -> StateOrder:
    # A state with all of its object's static facts lists only the rest: the static facts are linked to the
    # object once (staticFactOf) and the TBox's SWRL rule derives the state's madeof links to them.
    compact = info.static <= atoms
    return compact, tuple(sorted(a for a in atoms if a in info.shared_atom_name or not compact))


def action_order(spec: ActionSpec) -> ActionOrder:
    parts = tuple(tuple(sorted(getattr(spec, part))) for part in ("pre", "eff_neg", "eff_pos"))
    params = set(spec.params)
    conds = tuple((tuple(sorted({a for atom in ce.eff_neg | ce.eff_pos for a in atom[1:]} - params)),
                   tuple(tuple(sorted(getattr(ce, part))) for part in ("when", "eff_neg", "eff_pos")))
                  for ce in spec.cond_eff)
    return parts, conds


def add_predicate(b: TripleBatch, name: str, atom: Atom) -> str:
    cls, _, props, _ = PREDICATES[atom[0]]
    b.individual(name, cls)
    for prop, arg in zip(props, atom[1:]):
        b.rel(name, prop, arg)
    return name


def shared_predicate(abox: AboxNames, b: TripleBatch, info: ObjectInfo, atom: Atom) -> str:
    """The object's individual for a HasOrientation atom (or a bimanual object's control atom), created in this
    batch on first use."""
    name = info.shared_atom_name[atom]
    if name in b.shared or abox.existing([name]):
        return name
    b.shared.add(name)
    return add_predicate(b, name, atom)


def object_triples(abox: AboxNames, b: TripleBatch, info: ObjectInfo) -> None:
    """An object: its links in chain order, its joints, its allowed orientations (shared by every object that
    has them) and its static facts."""
    obj = info.obj
    o = b.individual(obj.ident, "ArticulatedObject")
    b.data(o, "formulation", obj.formulation.value)
    b.data(o, "objectName", obj.name)
    b.data(o, "createdAt", time.time())
    previous = None
    for link in obj.all_links:
        index = int(link.rsplit("_l", 1)[1])
        b.individual(link, "Link")
        b.data(link, "chainIndex", index)
        if index == 0:
            b.data(link, "isVirtual", True)
        else:
            b.data(link, "lengthM", float(obj.link_lengths_m[index - 1]))
            b.data(link, "isVirtual", False)
        b.rel(o, "hasLink", link)
        if previous is not None:
            b.rel(previous, "nextLink", link)
        previous = link
    for k in obj.joint_indices:
        joint = obj.joint(k)
        b.individual(joint, "Joint")
        b.data(joint, "chainIndex", k)
        b.rel(o, "hasJoint", joint)
    for deg, name in zip(obj.orientation_degrees, obj.orientation_names):
        if not abox.has_class(name, "Orientation"):
            b.individual(name, "Orientation")
            b.data(name, "degrees", deg)
        b.rel(o, "allowedOrientation", name)
    for gripper in obj.grippers:  # the robot's, shared by every bimanual object like the orientations
        if not abox.has_class(gripper, "Gripper"):
            b.individual(gripper, "Gripper")
    for atom in sorted(info.static):
        name = add_predicate(b, info.static_fragment[atom], atom)
        b.rel(name, "staticFactOf", obj.ident)


def state_triples(
    abox: AboxNames, b: TripleBatch, info: ObjectInfo, kind: str, atoms: frozenset[Atom],
    observation: Perception | None, step: int | None, created_at: float,
    state_id: str | None = None, order: StateOrder | None = None,
) -> str:
    """A state (named from the object's state counter unless `state_id` is given); its name."""
    obj = info.obj
    state_id = state_id or record_name(obj.ident, "state", abox.next_counter(counter_name(obj.ident, "state")))
    s = b.individual(state_id, STATE_CLASSES[kind])
    b.rel(s, "stateOf", obj.ident)
    b.data(s, "createdAt", created_at)
    if step is not None:
        b.data(s, "stepIndex", step)
    compact, linked = order or state_order(info, atoms)
    if compact:
        b.data(s, "includesStaticFacts", True)
    for atom in linked:
        if atom in info.shared_atom_name:
            pred = shared_predicate(abox, b, info, atom)
        else:
            pred = info.static_fragment[atom]
        b.rel(s, "madeof", pred)
    if observation is not None:
        for k, (value, deg) in enumerate(zip(observation.raw_deg, observation.snapped_deg), start=1):
            p = b.individual(f"{state_id}_lo_l{k}", "LinkOrientation")
            b.rel(p, "arg1", obj.link(k))
            b.rel(p, "arg2", orientation_name(deg))
            b.data(p, "observedDegrees", value)
            b.rel(s, "observes", p)
    return state_id


def action_triples(abox: AboxNames, b: TripleBatch, info: ObjectInfo, aid: str, step: int, spec: ActionSpec,
                   order: ActionOrder | None = None) -> None:
    b.individual(aid, ACTION_CLASSES[spec.name])
    b.data(aid, "stepIndex", step)
    b.data(aid, "paramList", " ".join(spec.params))
    b.rel(aid, "aboutObject", info.obj.ident)
    for p in dict.fromkeys(spec.params):
        b.rel(aid, "params", p)
    made: dict[Atom, str] = {}

    def pred(atom: Atom) -> str:
        name = info.static_fragment.get(atom) or made.get(atom)
        if name is None and atom in info.shared_atom_name:
            name = made[atom] = shared_predicate(abox, b, info, atom)
        if name is None:
            name = made[atom] = add_predicate(b, atom_fragment(info.obj, aid, atom), atom)
        return name

    parts, conds = order or action_order(spec)
    for atoms, prop in zip(parts, ("pre", "effNeg", "effPos")):
        for atom in atoms:
            b.rel(aid, prop, pred(atom))
    for c, (quantified, ce_parts) in enumerate(conds, start=1):
        cid = b.individual(f"{aid}_ce{c}", "CondPredicate")
        b.data(cid, "position", c)
        b.rel(aid, "condEff", cid)
        for name in quantified:
            b.rel(cid, "forall", name)
        for atoms, prop in zip(ce_parts, ("when", "effNeg_a", "effPos_a")):
            for atom in atoms:
                b.rel(cid, prop, pred(atom))


def plan_triples(abox: AboxNames, b: TripleBatch, info: ObjectInfo, entry: JournalEntry) -> None:
    """A journalled plan: the plan, its actions in order and its expected states, with the names its journal row
    gave them."""
    action_orders = [action_order(spec) for spec in entry.actions]
    state_orders = [state_order(info, frozenset(atoms)) for atoms in entry.expected_states]
    plan_id = entry.plan_id
    b.individual(plan_id, "Plan")
    b.rel(plan_id, "aboutObject", entry.object_id)
    b.rel(plan_id, "solves", entry.problem_id)
    b.data(plan_id, "plannerName", entry.planner)
    b.data(plan_id, "createdAt", entry.created_at)
    previous = None
    for step, (spec, order) in enumerate(zip(entry.actions, action_orders), start=1):
        aid = action_name(plan_id, step)
        action_triples(abox, b, info, aid, step, spec, order)
        b.rel(plan_id, "madeof", aid)
        if previous:
            b.rel(previous, "nextAction", aid)
        previous = aid
    for step, (atoms, s_order) in enumerate(zip(entry.expected_states, state_orders), start=1):
        sid = state_triples(abox, b, info, "expected", atoms, None, step, entry.created_at,
                            entry.state_id(step), s_order)
        b.rel(plan_id, "expectedState", sid)
