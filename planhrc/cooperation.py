"""The cooperation model of the paper (section "Reasoning in the Ontology"), as one pure function.

Every perceived state is compared with the normative states of the current plan:

* goal reached: ``D(s^c) ⊑ D(s^g)``;
* continue with the next action ``a_k`` when ``D(s^c) ⊑ D(s^e_k)`` (the state ``a_k`` starts from) or,
  unless the last action failed or was done only in part, ``D(s^c) ⊑ D(pre(a_k))`` (``a_k`` is executable
  even if some unmodelled effect of a successful action made the state differ: the paper's second case);
* resume from the *latest* expected state ``s^e_i`` that subsumes ``s^c`` (a human did part of the work, or
  the robot did only part of an action): the next action is ``a_i``;
* otherwise re-plan from ``s^c`` to the same goal.

Indices follow CONVENTIONS.md: ``s^e_1`` is the state the plan starts from and ``a_j`` turns ``s^e_j`` into
``s^e_{j+1}``, so the action executable from ``s^e_i`` is ``a_i``. (The paper's text says "resumes from
``a_{i+1}``", which with its own definition of ``s^e_1 = s^c`` is one step late.)

The function only decides; storing states, planning and dispatching belong to the service's use cases.

`escalate` then applies what the paper asks of a repeated failure: after a failed or partial action whose reason
says the motion itself is the problem (unreachable, stall, slip, collision, left_table), the same motion is not retried
identically. The remedies are tried in turn, one per failure of that motion: split the macro step (dispatch its
steps one by one), turn that joint the other way round (360° - delta), re-plan; when they are spent, or the robot
cannot reach the links at all, the human is asked (`human_help_requested`).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

from planhrc.errors import PlanhrcError
from planhrc.model import State, is_subsumed
from planhrc.transition import matching_states
from planhrc.vocabulary import ActionOutcome, DecisionKind, FailureReason, Remedy

# Reasons that say the motion itself failed (a retry of the same motion would fail the same way); a turn the
# worker did not start because its sweep would leave the table, as measured, is refused again the same way.
MOTION_FAILURES = frozenset({FailureReason.UNREACHABLE, FailureReason.STALL, FailureReason.SLIP,
                             FailureReason.COLLISION, FailureReason.LEFT_TABLE})


class CooperationError(PlanhrcError, ValueError):
    """A plan view that does not describe a plan (the message names the field)."""


@dataclass(frozen=True)
class PlanView:
    """What the cooperation model needs of a plan: ``s^e_1 .. s^e_{N+1}`` and ``pre(a_1) .. pre(a_N)``."""

    expected_states: Sequence[State]  # a tuple, or the replay's `ExpectedStates` (each state made when read)
    preconditions: tuple[State, ...]

    def __post_init__(self) -> None:
        if len(self.expected_states) != len(self.preconditions) + 1:
            raise CooperationError(
                f"expected_states: a plan of {len(self.preconditions)} actions needs "
                f"{len(self.preconditions) + 1} expected states, got {len(self.expected_states)}"
            )

    @property
    def n_actions(self) -> int:
        return len(self.preconditions)


@dataclass(frozen=True)
class Decision:
    """What to do after a perception.

    `next_step` is the 1-based step of the action to execute next (None for goal_reached, replan and
    no_plan); `matched_expected_step` is the i of the expected state ``s^e_i`` that subsumes the perceived
    state, when one does.
    """

    kind: DecisionKind
    next_step: int | None
    matched_expected_step: int | None
    reason: str
    remedy: Remedy | None = None


@dataclass(frozen=True)
class FailureHistory:
    """The failures of one motion (the joint turned about and the link turned) since the last success: how many,
    the last reason, and the remedies already tried, in order."""

    joint: int
    turned: int
    reason: FailureReason | None
    failures: int = 1
    tried: tuple[Remedy, ...] = ()


def decide(
    perceived: State,
    goal: State,
    plan: PlanView | None,
    next_step: int | None,
    last_outcome: ActionOutcome | None = None,
) -> Decision:
    """Apply the cooperation model to one perceived state.

    `next_step` is the step of the action the execution expects to run next (None when there is none, e.g.
    no plan yet or the goal was reached before); `last_outcome` is the worker's last feedback: after a failed
    or partial action only expected states are normative (the paper's first case), after a successful one
    (or none) ``pre(a_k)`` is too (its second case).
    """
    if is_subsumed(perceived, goal):
        return Decision(DecisionKind.GOAL_REACHED, None, None, "the perceived state is subsumed by the goal state")
    if plan is None:
        return Decision(DecisionKind.NO_PLAN, None, None, "there is no plan to follow: plan from the perceived state")

    n = plan.n_actions
    after = _after(last_outcome)
    if next_step is not None and 1 <= next_step <= n:
        if is_subsumed(perceived, plan.expected_states[next_step - 1]):
            verb = "retry" if last_outcome in (ActionOutcome.FAILED, ActionOutcome.PARTIAL) else "execute"
            return Decision(
                DecisionKind.CONTINUE,
                next_step,
                next_step,
                f"{after}the perceived state is subsumed by the expected state s^e_{next_step}: {verb} a_{next_step}",
            )
        if last_outcome not in (ActionOutcome.FAILED, ActionOutcome.PARTIAL) and is_subsumed(perceived, plan.preconditions[next_step - 1]):
            return Decision(
                DecisionKind.CONTINUE,
                next_step,
                None,
                f"{after}the perceived state differs from s^e_{next_step} but satisfies pre(a_{next_step}): "
                f"execute a_{next_step}",
            )

    for i in (k + 1 for k in matching_states(perceived, plan.expected_states)):  # the latest expected state first
        if i == n + 1:
            # A valid plan's last state satisfies the goal, which was checked above: the plan is stale.
            return Decision(
                DecisionKind.REPLAN,
                None,
                i,
                f"{after}the perceived state matches the plan's final state s^e_{i}, which does not satisfy "
                "the goal: re-plan",
            )
        return Decision(
            DecisionKind.RESUME,
            i,
            i,
            f"{after}the perceived state is subsumed by the expected state s^e_{i}"
            f"{_expected_note(next_step)}: resume from a_{i}",
        )

    return Decision(
        DecisionKind.REPLAN,
        None,
        None,
        f"{after}the perceived state is subsumed by no expected state of the plan"
        f"{_expected_note(next_step)}: re-plan from it",
    )


def escalate(decision: Decision, history: FailureHistory | None, next_motion: tuple[int, int] | None,
             macro_steps: int = 1, reachable: bool = True) -> Decision:
    """The decision after a failure of a motion, when it would retry that same motion.

    `history` is the failing motion's record (None: no failure to answer), `next_motion` the (joint, turned link)
    of the action `decision` would dispatch, `macro_steps` how many plan steps that motion merges, `reachable`
    whether the robot can reach the links it grasps (geometry; False makes an `unreachable` failure go to the
    human at once). Any other decision is returned unchanged."""
    if history is None or history.reason not in MOTION_FAILURES:
        return decision
    if decision.kind not in (DecisionKind.CONTINUE, DecisionKind.RESUME) or decision.next_step is None:
        return decision
    if next_motion != (history.joint, history.turned):
        return decision
    what = (f"turning link {history.turned} about joint {history.joint} failed "
            f"{history.failures} time{'s' if history.failures > 1 else ''} ({history.reason})")
    if history.reason == FailureReason.UNREACHABLE and not reachable:
        return Decision(DecisionKind.HUMAN_HELP_REQUESTED, decision.next_step, decision.matched_expected_step,
                        f"{decision.reason}; {what} and the robot cannot reach the link: ask the human",
                        Remedy.ASK_HUMAN)
    remedies = ([Remedy.SPLIT] if macro_steps > 1 else []) + [Remedy.OTHER_WAY, Remedy.REPLAN]
    remedy = next((r for r in remedies if r not in history.tried), Remedy.ASK_HUMAN)
    if remedy == Remedy.SPLIT:
        return Decision(decision.kind, decision.next_step, decision.matched_expected_step,
                        f"{decision.reason}; {what} as one motion of {macro_steps} steps: dispatch its steps one "
                        "by one", remedy)
    if remedy == Remedy.OTHER_WAY:
        return Decision(DecisionKind.REPLAN, None, decision.matched_expected_step,
                        f"{decision.reason}; {what}: turn that joint the other way round", remedy)
    if remedy == Remedy.REPLAN:
        return Decision(DecisionKind.REPLAN, None, decision.matched_expected_step,
                        f"{decision.reason}; {what}, the other way round too: re-plan", remedy)
    return Decision(DecisionKind.HUMAN_HELP_REQUESTED, decision.next_step, decision.matched_expected_step,
                    f"{decision.reason}; {what} after {', '.join(history.tried)}: ask the human", remedy)


def _after(last_outcome: ActionOutcome | None) -> str:
    return "" if last_outcome is None else f"last feedback {last_outcome}; "


def _expected_note(next_step: int | None) -> str:
    return "" if next_step is None else f" (expected s^e_{next_step})"
