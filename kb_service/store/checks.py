"""Input checks of the store's writes: every atom, state, observation and plan is checked against its object
before anything is written, and a refused input names its field (`ValidationError`).

The checks are pure: they read only an `ObjectInfo` (the object and the lookups they need), never the database,
so a backend calls them before it opens a transaction, and `check_plan` runs outside the store's lock (the
service runs it while VAL checks the same plan). Nothing here depends on a backend.
"""
from __future__ import annotations

import json
import time
from functools import cached_property
from typing import Any, Sequence

from planhrc.control import check_control, possible_control
from planhrc.model import (
    HAS_ORIENTATION,
    ArticulatedObject,
    Atom,
    ModelError,
    Perception,
    format_atom,
    orientation_name,
    perceive,
)
from planhrc.vocabulary import ExecutionStatus, one_of

from .errors import DeadlineError, ValidationError
from .interface import FORMATS, HISTORY, MAX_SEQ
from .names import ACTION_CLASSES, COMPLETE_KINDS, PREDICATES, atom_fragment
from .records import STATE_KINDS, ActionSpec, CheckedPlan, CondEffect, Execution, StoredPlan

MAX_VALID_ACTIONS = 20_000  # actions kept as checked per object (`ObjectInfo.valid_actions`)


class ObjectInfo:
    """An object and the lookups the checks need (names -> PDDL type, static facts, its orientation atoms and, for a
    bimanual object, its control atoms), each built when a check first asks for it: listing or reading objects
    needs none of them (building them all took most of a first `GET /objects` on a store of many objects)."""

    def __init__(self, obj: ArticulatedObject) -> None:
        self.obj = obj
        self.joints = obj.joints

    @cached_property
    def types(self) -> dict[str, str]:
        types: dict[str, str] = {}
        for name in self.obj.all_links:
            types[name] = "link"
        for name in self.obj.joints:
            types[name] = "joint"
        for name in self.obj.orientation_names:
            types[name] = "orientation"
        for name in self.obj.grippers:
            types[name] = "gripper"
        return types

    @cached_property
    def static(self) -> frozenset[Atom]:
        return self.obj.static_atoms()

    @cached_property
    def static_fragment(self) -> dict[Atom, str]:
        return {atom: atom_fragment(self.obj, self.obj.ident, atom) for atom in self.static}

    @cached_property
    def orientation_atom_name(self) -> dict[Atom, str]:
        """Every well-formed HasOrientation atom of the object, with the name of its individual."""
        obj = self.obj
        return {(HAS_ORIENTATION, o, j): atom_fragment(obj, obj.ident, (HAS_ORIENTATION, o, j))
                for j in obj.joints for o in obj.orientation_names}

    @cached_property
    def orientation_atoms(self) -> frozenset[Atom]:
        return frozenset(self.orientation_atom_name)

    @cached_property
    def control_atoms(self) -> frozenset[Atom]:
        """A bimanual object's control atoms (what the grippers hold, the centre): individuals its states share."""
        return possible_control(self.obj)

    @cached_property
    def valid_actions(self) -> set[ActionSpec]:
        """The actions `check_plan` found valid for this object: a check reads only the action and this object's
        lookups, which never change, and a re-planning object's plans are made of the same few ground actions,
        so each is checked once per object (at most `MAX_VALID_ACTIONS` kept)."""
        return set()

    @cached_property
    def shared_atom_name(self) -> dict[Atom, str]:
        """The atoms every state of the object shares as one individual each (orientations, control), named."""
        obj = self.obj
        return {**self.orientation_atom_name,
                **{atom: atom_fragment(obj, obj.ident, atom) for atom in sorted(self.control_atoms)}}


def check_kind(kind: Any) -> str:
    if kind not in STATE_KINDS:
        raise ValidationError(f"kind: must be one of {', '.join(STATE_KINDS)}, got {kind!r}")
    return str(kind)


def check_atom(info: ObjectInfo, atom: Any, field: str) -> Atom:
    if not isinstance(atom, tuple) or not atom or not all(isinstance(x, str) for x in atom):
        raise ValidationError(f"{field}: an atom is a tuple of names, got {atom!r}")
    spec = PREDICATES.get(atom[0])
    if spec is None:
        raise ValidationError(f"{field}: atom {format_atom(atom)}: unknown predicate {atom[0]!r}")
    _, types, _, _ = spec
    if len(atom) - 1 != len(types):
        raise ValidationError(
            f"{field}: atom {format_atom(atom)}: {atom[0]} takes {len(types)} arguments, got {len(atom) - 1}"
        )
    for i, (arg, typ) in enumerate(zip(atom[1:], types), start=1):
        got = info.types.get(arg)
        if got is None:
            raise ValidationError(
                f"{field}: atom {format_atom(atom)}: argument {i} {arg!r} is no {typ} of object {info.obj.ident!r}"
            )
        if got != typ:
            raise ValidationError(
                f"{field}: atom {format_atom(atom)}: argument {i} {arg!r} is a {got}, expected a {typ}"
            )
    return atom


def check_state_atoms(info: ObjectInfo, kind: str, atoms: Any, field: str) -> dict[str, Atom]:
    """Validate a state's atoms; returns joint -> its hasorientation atom."""
    if not isinstance(atoms, (set, frozenset)):
        raise ValidationError(f"{field}: expected a frozenset of atoms, got {type(atoms).__name__}")
    if not atoms:
        raise ValidationError(f"{field}: a state needs at least one atom")
    static = info.static
    # A bimanual object's control atoms: in a complete state, a whole control part (one joint at the centre, each
    # gripper free or holding one link)
    control = frozenset(atoms) & info.control_atoms
    if info.control_atoms and kind in COMPLETE_KINDS:
        try:
            check_control(info.obj, control, field)
        except ModelError as exc:
            raise ValidationError(str(exc)) from None
    # The common case in a few set operations: every atom is a static fact or a well-formed hasorientation
    # atom of the object, one per joint (a complete state: every joint). Anything else takes the path below,
    # which finds the first error in a fixed order.
    rest_set = frozenset(atoms) - static - control
    if rest_set <= info.orientation_atoms:
        by_joint = {atom[2]: atom for atom in rest_set}
        if len(by_joint) == len(rest_set) and (kind not in COMPLETE_KINDS or len(by_joint) == len(info.joints)):
            return by_joint
    by_joint = {}
    # Static facts of the object are valid by construction; only the rest needs checking. Sorting the rest
    # makes the first error reported the same on every run.
    well_formed = info.orientation_atom_name
    rest = [atom for atom in atoms if atom not in static and atom not in control]
    try:
        rest.sort()
    except TypeError:
        rest.sort(key=repr)
    for atom in rest:
        if atom not in well_formed:
            check_atom(info, atom, field)
        if atom[0] == HAS_ORIENTATION:
            joint = atom[2]
            if joint in by_joint:
                raise ValidationError(
                    f"{field}: two orientations for joint {joint!r} in one state: "
                    f"{format_atom(by_joint[joint])} and {format_atom(atom)}"
                )
            by_joint[joint] = atom
        elif atom not in info.static:
            raise ValidationError(f"{field}: atom {format_atom(atom)} is not a fact of object {info.obj.ident!r}")
    if kind in COMPLETE_KINDS:
        missing = [j for j in info.joints if j not in by_joint]
        if missing:
            raise ValidationError(
                f"{field}: a {kind} state is complete but has no orientation for joint(s) {', '.join(missing)}"
            )
    return by_joint


def check_observation(info: ObjectInfo, kind: str, by_joint: dict[str, Atom], values: Any) -> Perception | None:
    """The observed link orientations of a state (None: none given), agreeing with its atoms."""
    if values is None:
        return None
    obj = info.obj
    field = "link_orientations_deg"
    if kind != "perceived":
        raise ValidationError(f"{field}: only perceived states carry observed link orientations, not {kind!r}")
    try:
        perception = perceive(obj, values, field)
    except ModelError as exc:
        raise ValidationError(str(exc)) from None
    for k, deg in zip(obj.joint_indices, perception.joint_values):
        atom = by_joint.get(obj.joint(k))
        if atom is not None and atom[1] != orientation_name(deg):
            raise ValidationError(
                f"{field}: the observation gives {orientation_name(deg)} for joint {obj.joint(k)}, "
                f"but atoms say {format_atom(atom)}"
            )
    return perception


def check_perception(info: ObjectInfo, perception: Perception) -> None:
    """A perception was validated and snapped where it entered (`model.perceive`): only its size is checked."""
    n = info.obj.n_links
    if len(perception.snapped_deg) != n or len(perception.raw_deg) != n:
        raise ValidationError(f"perception: expected {n} link orientations")


def _check_atoms(info: ObjectInfo, atoms: set[Any] | frozenset[Any], field: str) -> None:
    """`check_atom` on each atom that is not one of the object's known facts (its static facts and its
    well-formed hasorientation atoms, valid by construction), in a fixed order (the first error is the same on
    every run)."""
    rest = [a for a in atoms if a not in info.static and a not in info.shared_atom_name]
    for atom in sorted(rest, key=repr):
        check_atom(info, atom, field)


def check_action(info: ObjectInfo, i: int, spec: Any) -> None:
    field = f"actions[{i}]"
    if not isinstance(spec, ActionSpec):
        raise ValidationError(f"{field}: expected an ActionSpec, got {type(spec).__name__}")
    if spec.name not in ACTION_CLASSES:
        raise ValidationError(f"{field}.name: must be one of {', '.join(ACTION_CLASSES)}, got {spec.name!r}")
    if not isinstance(spec.params, tuple) or not spec.params:
        raise ValidationError(f"{field}.params: expected a non-empty tuple of names")
    for k, p in enumerate(spec.params):
        if not isinstance(p, str) or p not in info.types:
            raise ValidationError(f"{field}.params[{k}]: {p!r} is no link, joint or orientation of object "
                                  f"{info.obj.ident!r}")
    for part in ("pre", "eff_neg", "eff_pos"):
        atoms = getattr(spec, part)
        if not isinstance(atoms, (set, frozenset)):
            raise ValidationError(f"{field}.{part}: expected a frozenset of atoms")
        _check_atoms(info, atoms, f"{field}.{part}")
    if not isinstance(spec.cond_eff, tuple):
        raise ValidationError(f"{field}.cond_eff: expected a tuple of CondEffect")
    for c, ce in enumerate(spec.cond_eff):
        if not isinstance(ce, CondEffect):
            raise ValidationError(f"{field}.cond_eff[{c}]: expected a CondEffect, got {type(ce).__name__}")
        for part in ("when", "eff_neg", "eff_pos"):
            atoms = getattr(ce, part)
            if not isinstance(atoms, (set, frozenset)):
                raise ValidationError(f"{field}.cond_eff[{c}].{part}: expected a frozenset of atoms")
            _check_atoms(info, atoms, f"{field}.cond_eff[{c}].{part}")


def check_plan(info: ObjectInfo, actions: tuple[ActionSpec, ...], expected_states: Sequence[frozenset[Atom]],
               deadline_at: float | None = None, first_steps: int | None = None) -> CheckedPlan:
    """Every check a plan's write makes on its actions and expected states, stopped with a DeadlineError once
    `deadline_at` (`time.monotonic()`) has passed: a caller's request deadline bounds the check of a huge plan.

    With `first_steps`, only what the plan's first `first_steps` steps need: their actions and the expected states
    s^e_1 .. s^e_(first_steps+1); the caller checks each later step (`check_steps`) before it uses it (the service
    answers a long plan once its first motion is checked and gates each later motion on its checks)."""
    if len(expected_states) != len(actions) + 1:
        raise ValidationError(
            f"expected_states: a plan of {len(actions)} actions needs {len(actions) + 1} expected states "
            f"(s^e_1 .. s^e_N+1), got {len(expected_states)}"
        )
    steps = len(actions) if first_steps is None else max(0, min(first_steps, len(actions)))
    _check_actions(info, actions, 0, steps)
    _check_states(info, expected_states, 0, steps + 1, deadline_at)
    return CheckedPlan(info.obj.ident, actions, expected_states,
                       checked_steps=None if steps == len(actions) else steps)


def check_steps(info: ObjectInfo, actions: tuple[ActionSpec, ...], expected_states: Sequence[frozenset[Atom]],
                first: int, last: int) -> None:
    """The checks of steps a_first .. a_last (1-based, inclusive) of a plan that `check_plan` checked up to a step
    before them: their actions and the expected states they lead to, s^e_(first+1) .. s^e_(last+1)."""
    if not 1 <= first <= last <= len(actions) or len(expected_states) != len(actions) + 1:
        raise ValidationError(f"steps: a_{first}..a_{last} are not steps of a plan of {len(actions)} actions with "
                              f"{len(expected_states)} expected states")
    _check_actions(info, actions, first - 1, last)
    _check_states(info, expected_states, first, last + 1, None)


def _check_actions(info: ObjectInfo, actions: tuple[ActionSpec, ...], start: int, end: int) -> None:
    """`check_action` on actions[start:end], each at most once per object (`ObjectInfo.valid_actions`)."""
    valid = info.valid_actions
    for i in range(start, end):
        spec = actions[i]
        try:
            if spec in valid:
                continue
        except TypeError:  # not hashable (sets where frozensets belong): checked, never kept
            check_action(info, i, spec)
            continue
        check_action(info, i, spec)
        if len(valid) >= MAX_VALID_ACTIONS:
            valid.clear()
        valid.add(spec)


def _check_states(info: ObjectInfo, expected_states: Sequence[frozenset[Atom]], start: int, end: int,
                  deadline_at: float | None) -> None:
    """`check_state_atoms` on expected_states[start:end] (0-based), past `deadline_at` a DeadlineError."""
    for i in range(start, end):
        if deadline_at is not None and time.monotonic() > deadline_at:
            raise DeadlineError(f"planning: the deadline passed while the store checked expected state {i + 1} of "
                                f"{len(expected_states)}")
        check_state_atoms(info, "expected", expected_states[i], f"expected_states[{i}]")


def is_checked(checked: CheckedPlan | None, object_id: str, actions: tuple[ActionSpec, ...],
               expected_states: Sequence[frozenset[Atom]]) -> bool:
    """Whether `checked` is the check of exactly these objects (the same tuples, not equal ones: a caller that
    built new ones may have changed them since)."""
    return (checked is not None and checked.object_id == object_id and checked.actions is actions
            and checked.expected_states is expected_states)


# -- arguments of reads, exports and compaction -------------------------------------------------------------------
def check_events_page(after_seq: Any, limit: Any) -> None:
    if isinstance(after_seq, bool) or not isinstance(after_seq, int) or not 0 <= after_seq <= MAX_SEQ:
        raise ValidationError(f"after_seq: must be an integer from 0 to {MAX_SEQ}, got {after_seq!r}")
    if limit is not None and (isinstance(limit, bool) or not isinstance(limit, int) or limit < 1):
        raise ValidationError(f"limit: must be a positive integer, got {limit!r}")


def check_keep_perceived(keep_perceived: Any) -> int:
    if isinstance(keep_perceived, bool) or not isinstance(keep_perceived, int) or keep_perceived < 1:
        raise ValidationError(f"keep_perceived: must be a positive integer, got {keep_perceived!r}")
    return keep_perceived


def check_export(history: Any, object_ids: Any, fmt: Any = "nt") -> None:
    if fmt not in FORMATS:
        raise ValidationError(f"fmt: must be one of {', '.join(FORMATS)}, got {fmt!r}")
    if history not in HISTORY:
        raise ValidationError(f"history: must be one of {', '.join(HISTORY)}, got {history!r}")
    if history == "all" and object_ids is not None:
        raise ValidationError("object: the whole history is exported for every object (history=all)")


# -- the side tables' rows (every engine's: the core checks them before its engine writes them) ---------------------
def check_event(kind: Any, reason: Any, data: Any) -> str:
    """Validate an event; returns its data as JSON text."""
    if not isinstance(kind, str) or not kind:
        raise ValidationError("kind: must be a non-empty string")
    if not isinstance(reason, str):
        raise ValidationError("reason: must be a string")
    data = {} if data is None else data
    if not isinstance(data, dict):
        raise ValidationError(f"data: expected a dict, got {type(data).__name__}")
    return _json_text("data", data)


def check_response(key: Any, response: Any) -> str:
    """Validate a response to remember; returns it as JSON text."""
    if not isinstance(key, str) or not key:
        raise ValidationError("key: must be a non-empty string")
    if not isinstance(response, dict):
        raise ValidationError(f"response: expected a dict, got {type(response).__name__}")
    return _json_text("response", response)


def _json_text(field: str, value: dict[str, Any]) -> str:
    try:
        return json.dumps(value, sort_keys=True, allow_nan=False)
    except (TypeError, ValueError) as exc:
        raise ValidationError(f"{field}: not JSON-serialisable ({exc})") from None


def check_inferred(scope: object, lines: Sequence[object]) -> list[str]:
    """Validate what a reasoner inferred, to keep: a non-empty scope, N-Triples lines (each ending with ' .'); the
    lines, each ending with a newline."""
    if not isinstance(scope, str) or not scope:
        raise ValidationError("scope: must be a non-empty string")
    out = []
    for i, line in enumerate(lines):
        if not isinstance(line, str) or not line.rstrip().endswith("."):
            raise ValidationError(f"lines[{i}]: not an N-Triples line")
        out.append(line if line.endswith("\n") else line + "\n")
    return out


def check_execution(object_id: str, execution: Execution, plan: StoredPlan | None) -> None:
    """Validate a new execution of `object_id`; `plan` is the stored plan `execution.plan_id` names."""
    if execution.status not in set(ExecutionStatus):
        raise ValidationError(f"execution.status: must be {one_of(ExecutionStatus)}, got {execution.status!r}")
    if plan is not None and plan.object_id != object_id:
        raise ValidationError(f"execution.plan_id: plan {plan.id!r} belongs to object {plan.object_id!r}")
    if execution.next_step is not None:
        if isinstance(execution.next_step, bool) or not isinstance(execution.next_step, int):
            raise ValidationError("execution.next_step: must be an integer or None")
        if plan is None:
            raise ValidationError("execution.next_step: needs a plan_id")
        if not 1 <= execution.next_step <= len(plan.actions) + 1:
            raise ValidationError(
                f"execution.next_step: must be in 1..{len(plan.actions) + 1}, got {execution.next_step}"
            )
    if execution.dispatched_action_id is not None:
        if plan is None or execution.dispatched_action_id not in {a.id for a in plan.actions}:
            raise ValidationError(
                f"execution.dispatched_action_id: {execution.dispatched_action_id!r} is no action of plan "
                f"{execution.plan_id!r}"
            )
