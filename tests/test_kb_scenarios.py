"""Named knowledge-base scenarios shared by the other tests/test_kb_*.py modules (no tests here)."""
from __future__ import annotations

from planhrc.kb_service.store.records import ActionSpec, CondEffect
from planhrc.model import (
    AFFECTED,
    CONNECTED,
    HAS_ORIENTATION,
    ORIENTATION_ORD,
    ArticulatedObject,
    Formulation,
    State,
    orientation_name,
)


def rotate(obj: ArticulatedObject, state: State, k: int, clockwise: bool = True) -> ActionSpec:
    """The ground action turning joint k one step (downstream link turns; absolute adds conditional effects)."""
    values = obj.joint_values_of(state)
    step = obj.step if clockwise else -obj.step
    up, down = obj.joint_links(k)
    j = obj.joint(k)
    o1 = orientation_name(values[k])
    o2 = orientation_name((values[k] + step) % 360)
    first, second = (o1, o2) if clockwise else (o2, o1)
    pre = {(CONNECTED, j, up), (CONNECTED, j, down), (HAS_ORIENTATION, o1, j), (ORIENTATION_ORD, first, second)}
    conds = []
    if obj.formulation is Formulation.ABSOLUTE:
        pre.add((AFFECTED, j, down, j))
        for m in obj.joint_indices:
            if m == k:
                continue
            jm = obj.joint(m)
            for deg in obj.orientation_degrees:
                a, b = orientation_name(deg), orientation_name((deg + step) % 360)
                conds.append(CondEffect(
                    when=frozenset({(AFFECTED, jm, down, j), (HAS_ORIENTATION, a, jm),
                                    (ORIENTATION_ORD, a, b) if clockwise else (ORIENTATION_ORD, b, a)}),
                    eff_neg=frozenset({(HAS_ORIENTATION, a, jm)}),
                    eff_pos=frozenset({(HAS_ORIENTATION, b, jm)}),
                ))
    name = "rotateclockwise" if clockwise else "rotateanticlockwise"
    return ActionSpec(name, (up, down, j, o1, o2), frozenset(pre), frozenset({(HAS_ORIENTATION, o1, j)}),
                      frozenset({(HAS_ORIENTATION, o2, j)}), tuple(conds))


def apply(state: State, action: ActionSpec) -> State:
    """s' = (s - (eff- ∪ C-)) ∪ (eff+ ∪ C+), conditions evaluated in s."""
    neg, pos = set(action.eff_neg), set(action.eff_pos)
    for ce in action.cond_eff:
        if ce.when <= state:
            neg |= ce.eff_neg
            pos |= ce.eff_pos
    return frozenset((state - neg) | pos)


def plan_for(obj: ArticulatedObject, init: State, moves: list[tuple[int, bool]]):
    """Ground actions and expected states s^e_1..s^e_{N+1} of a list of (joint index, clockwise) moves."""
    actions, states = [], [init]
    for k, cw in moves:
        a = rotate(obj, states[-1], k, cw)
        actions.append(a)
        states.append(apply(states[-1], a))
    return actions, states
