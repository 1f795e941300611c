"""What a plan step means for the robot: which link turns about which joint and by how much (`action_motion`),
and consecutive steps of one motion merged into a macro step. A bimanual step that turns nothing (a grasp, a
release, a centring) is a motion of 0 degrees at its joint, never merged with another."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, Sequence

from planhrc.model import MACRO_DEG, ActionSpec, ArticulatedObject, Formulation
from planhrc.ordering import Move
from planhrc.transition import parse_step


class PlanStep(Protocol):
    """A stored plan step: its id, 1-based position and ground action (e.g. the store's `StoredAction`)."""

    @property
    def id(self) -> str: ...

    @property
    def step(self) -> int: ...

    @property
    def spec(self) -> ActionSpec: ...



def _index(name: str) -> int:
    return int(name.rsplit("_", 1)[1][1:])


# The turn of each turning action, in steps of the orientation set or in degrees (the bimanual 45-degree macros);
# every other action of our domains (the bimanual grasp, release and centring) turns nothing.
_STEPS = {"rotateclockwise": 1, "rotateanticlockwise": -1}
_DEGREES = {"rotateclockwise45": MACRO_DEG, "rotateanticlockwise45": -MACRO_DEG}


def turn_deg(obj: ArticulatedObject, name: str) -> int:
    """The signed turn (degrees, + clockwise seen from above) of the link a plan step of action `name` turns."""
    if name in _STEPS:
        return _STEPS[name] * obj.step
    return _DEGREES.get(name, 0)


def action_motion(obj: ArticulatedObject, action: PlanStep | ActionSpec | Sequence[str] | str) -> dict[str, int]:
    """Which link turns, which is held (0 = the table), about which joint and by how many degrees
    (+ clockwise seen from above) for one plan step."""
    if isinstance(action, ActionSpec):
        name, params = action.name, action.params
    elif isinstance(action, str):
        name, params = parse_step(action)
    elif isinstance(action, Sequence):
        name, params = action[0], tuple(action[1:])
    else:
        name, params = action.spec.name, action.spec.params
    turned, held, joint = _index(params[0]), _index(params[1]), _index(params[2])
    delta = turn_deg(obj, name)
    if obj.formulation is Formulation.RELATIVE and turned == joint:
        # jK joins lK and lK+1 and carries lK+1 relative to lK: turning lK instead of lK+1 is the opposite turn
        delta = -delta
    return {"joint_index": joint, "turned_link_index": turned, "held_link_index": held, "delta_deg": delta,
            "macro_steps": 1}


@dataclass(frozen=True)
class MacroStep:
    """Consecutive steps on the same joint, turned link and direction, merged for execution."""

    first_step: int
    last_step: int
    joint_index: int
    turned_link_index: int
    held_link_index: int
    delta_deg: int
    action_ids: tuple[str, ...]

    @property
    def expected_state_step(self) -> int:
        """Index (1-based, s^e_i) of the expected state after the merged step."""
        return self.last_step + 1


def merge_macro_steps(obj: ArticulatedObject, actions: Sequence[PlanStep], first_only: bool = False
                      ) -> tuple[MacroStep, ...]:
    """The paper's consolidation: e.g. two 45° steps of one joint become one 90° step. With `first_only`, only the
    first macro step (the actions after it are not looked at: the motion to dispatch next)."""
    merged: list[MacroStep] = []
    for action in sorted(actions, key=lambda a: a.step):
        if first_only and len(merged) > 1:
            break
        m = action_motion(obj, action)
        prev = merged[-1] if merged else None
        same = (
            prev is not None
            and prev.delta_deg != 0 and m["delta_deg"] != 0  # a step that turns nothing is a motion of its own
            and prev.joint_index == m["joint_index"]
            and prev.turned_link_index == m["turned_link_index"]
            and (prev.delta_deg > 0) == (m["delta_deg"] > 0)
            and abs(prev.delta_deg + m["delta_deg"]) < 360
        )
        if same and prev is not None:
            merged[-1] = MacroStep(prev.first_step, action.step, prev.joint_index, prev.turned_link_index,
                                   prev.held_link_index, prev.delta_deg + m["delta_deg"],
                                   prev.action_ids + (action.id,))
        else:
            merged.append(MacroStep(action.step, action.step, m["joint_index"], m["turned_link_index"],
                                    m["held_link_index"], m["delta_deg"], (action.id,)))
    return tuple(merged[:1]) if first_only else tuple(merged)


def move_of(obj: ArticulatedObject, step: str | ActionSpec) -> Move:
    """The motion of one plan step (a PDDL step or a ground action)."""
    name = step.name if isinstance(step, ActionSpec) else parse_step(step)[0]
    m = action_motion(obj, step)
    return Move(name, m["turned_link_index"], m["held_link_index"], m["joint_index"], m["delta_deg"])


def step_text(action: ActionSpec) -> str:
    """A ground action as a plan step for VAL: "(name arg ...)"."""
    return "(" + " ".join((action.name,) + tuple(action.params)) + ")"


def first_motion_steps(obj: ArticulatedObject, actions: Sequence[ActionSpec] | Sequence[str], merge: bool) -> int:
    """How many plan steps the robot's first motion covers: 1, or with macro steps merged (`merge_macro_steps`)
    the first run of steps on one joint, one turned link and one direction, short of a full turn. The ground
    actions or the plan's steps as PDDL text: the same answer (`action_motion`)."""
    if not actions:
        return 0
    if not merge:
        return 1
    first = action_motion(obj, actions[0])
    total, n = first["delta_deg"], 1
    if total == 0:  # a bimanual step that turns nothing
        return 1
    for action in actions[1:]:
        m = action_motion(obj, action)
        if ((m["joint_index"], m["turned_link_index"]) != (first["joint_index"], first["turned_link_index"])
                or m["delta_deg"] == 0
                or (m["delta_deg"] > 0) != (total > 0) or abs(total + m["delta_deg"]) >= 360):
            break
        total += m["delta_deg"]
        n += 1
    return n
