"""The robot's own part of a bimanual state: what its grippers hold and which joint is at the centre.

A perception sees the links, not the robot's hands. The service follows the control facts from the plan instead
(docs/service.md): they start as `ArticulatedObject.initial_control` (both grippers free, the middle joint at the
centre); after an action the worker reports `succeeded`, they are those of the expected state after it; after one
it reports `failed` or `partial`, the worker has opened both hands (`after_failure`: the grasps are gone, the
centre is where it was). Each perceived state holds them beside the perceived orientations, so the cooperation
model compares whole states with the plan's expected ones.
"""
from __future__ import annotations

from typing import Iterable, Sequence

from planhrc.model import (CONTROL_PREDICATES, FREE, HOLDING, IN_CENTRE, ActionSpec, ArticulatedObject, Atom,
                           Formulation, ModelError, State, format_atom)


def control_of(state: Iterable[Atom]) -> frozenset[Atom]:
    """The control facts of a state (none outside the bimanual formulation)."""
    return frozenset(a for a in state if a[0] in CONTROL_PREDICATES)


def possible_control(obj: ArticulatedObject) -> frozenset[Atom]:
    """Every control fact the object's states may hold."""
    if obj.formulation is not Formulation.BIMANUAL:
        return frozenset()
    return frozenset({(FREE, g) for g in obj.grippers} | {(HOLDING, g, link) for g in obj.grippers for link in obj.links}
                     | {(IN_CENTRE, j) for j in obj.joints})


def after_failure(control: Iterable[Atom]) -> frozenset[Atom]:
    """The control facts once the worker has let go after a failed or partial action: both grippers free, the
    centre unchanged."""
    kept = {a for a in control if a[0] == IN_CENTRE}
    grippers = {a[1] for a in control if a[0] in (FREE, HOLDING)}
    return frozenset(kept | {(FREE, g) for g in grippers})


def control_after(control: Iterable[Atom], done: Sequence[ActionSpec], succeeded: bool,
                  hands_open: bool = False) -> frozenset[Atom]:
    """The control facts after the worker's feedback on the actions `done` (one motion, in order): their control
    effects when it succeeded, else `after_failure`; `after_failure` too when the worker opened its hands after
    the motion (`hands_open`: a succeeded turn whose grasp hid a link from every camera)."""
    now = frozenset(control)
    if not succeeded:
        return after_failure(now)
    for action in done:
        now = (now - control_of(action.eff_neg)) | control_of(action.eff_pos)
    return after_failure(now) if hands_open else now


def check_control(obj: ArticulatedObject, control: Iterable[Atom], field: str = "control") -> frozenset[Atom]:
    """`control` as a valid control part of the object's states: facts it may hold, one joint at the centre, each
    gripper free or holding one link; else a ModelError naming `field`."""
    atoms = frozenset(control)
    if obj.formulation is not Formulation.BIMANUAL:
        if atoms:
            raise ModelError(f"{field}: a {obj.formulation.value} object has no control facts")
        return atoms
    foreign = sorted(atoms - possible_control(obj))
    if foreign:
        raise ModelError(f"{field}: {format_atom(foreign[0])} is no control fact of {obj.ident}")
    if sum(1 for a in atoms if a[0] == IN_CENTRE) != 1:
        raise ModelError(f"{field}: exactly one joint is at the centre")
    for g in obj.grippers:
        if sum(1 for a in atoms if a[0] in (FREE, HOLDING) and a[1] == g) != 1:
            raise ModelError(f"{field}: gripper {g} is either free or holding one link")
    return atoms


def with_control(state: State, control: Iterable[Atom]) -> State:
    """The state with its control facts replaced by `control`."""
    return frozenset(a for a in state if a[0] not in CONTROL_PREDICATES) | frozenset(control)
