"""The motion a dispatch sends: a plan's action, merged with the steps after it into one macro step when the
setting `merge_macro_steps` is on (not in a plan whose merged motion failed: remedy split), never past a step the
plan slides the object before."""
from __future__ import annotations

from dataclasses import dataclass

from planhrc.model import ArticulatedObject
from planhrc.pipeline import action_motion, merge_macro_steps

from ..store import StoredAction, StoredPlan
from .memory import ObjectMemo
from .values import NextAction


@dataclass(frozen=True)
class Merging:
    """Whether a plan's macro steps are merged into one motion (`on`), and the steps a merged motion does not reach
    into (`breaks`: the plan slides the object before them)."""

    on: bool
    breaks: frozenset[int] = frozenset()


def last_step(merge: Merging, obj: ArticulatedObject, plan: StoredPlan, action: StoredAction) -> int:
    """Last plan step of the motion that starts with `action`: itself unless macro steps are merged (`merge`), and
    never a step a slide comes before. Every single step of a placed object's plan was checked geometrically, sweep
    included, so a merged motion sweeps only through checked configurations."""
    if not merge.on:
        return action.step
    until = min((b for b in merge.breaks if b > action.step), default=len(plan.actions) + 1)
    rest = [a for a in plan.actions if action.step <= a.step < until]
    return merge_macro_steps(obj, rest, first_only=True)[0].last_step


def next_action(merge: Merging, obj: ArticulatedObject, plan: StoredPlan, action: StoredAction) -> NextAction:
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


def merges(merge_macro_steps: bool, memo: ObjectMemo, plan_id: str) -> Merging:
    """Whether the motions of plan `plan_id` are merged macro steps: the setting, unless a merged motion of that
    plan failed (remedy split: its steps go out one by one); and the steps the plan slides the object before."""
    breaks = frozenset(s.before_step for s in memo.planned_skills(plan_id))
    return Merging(merge_macro_steps and plan_id not in memo.split_plans, breaks)
