"""The motion a dispatch sends: a plan's action, merged with the steps after it into one macro step when the
setting `merge_macro_steps` is on (not in a plan whose merged motion failed: remedy split)."""
from __future__ import annotations

from planhrc.model import ArticulatedObject
from planhrc.pipeline import action_motion, merge_macro_steps

from ..store import StoredAction, StoredPlan
from .values import NextAction


def last_step(merge: bool, obj: ArticulatedObject, plan: StoredPlan, action: StoredAction) -> int:
    """Last plan step of the motion that starts with `action`: itself unless macro steps are merged (`merge`).
    Every single step of a placed object's plan was checked geometrically, sweep included, so a merged motion
    sweeps only through checked configurations."""
    if not merge:
        return action.step
    rest = [a for a in plan.actions if a.step >= action.step]
    return merge_macro_steps(obj, rest, first_only=True)[0].last_step


def next_action(merge: bool, obj: ArticulatedObject, plan: StoredPlan, action: StoredAction) -> NextAction:
    """The motion starting with `action`, as a worker executes it."""
    motion = action_motion(obj, action)
    last = last_step(merge, obj, plan, action)
    delta, macro = motion["delta_deg"], motion["macro_steps"]
    if last > action.step:
        merged = merge_macro_steps(obj, [a for a in plan.actions if action.step <= a.step <= last], True)[0]
        delta, macro = merged.delta_deg, last - action.step + 1
    return NextAction(action.id, action.spec.name, tuple(action.spec.params), action.step, last, plan.id,
                      motion["joint_index"], motion["turned_link_index"], motion["held_link_index"], delta, macro,
                      last >= len(plan.actions))


def merges(merge_macro_steps: bool, split_plans: frozenset[str], plan_id: str) -> bool:
    """Whether the motions of plan `plan_id` are merged macro steps: the setting, unless a merged motion of that
    plan failed (remedy split: its steps go out one by one)."""
    return merge_macro_steps and plan_id not in split_plans
