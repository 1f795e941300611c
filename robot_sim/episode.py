"""What one worker run records: a record per step (what was perceived, decided and done) and the run's summary,
with the pictures' view of each step. Values only: the worker fills them, the demo and the files read them."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Sequence

from planhrc.robot_sim.pictures import PictureStep, actor_between, describe_action
from planhrc.vocabulary import ActionOutcome, DecisionKind, FailureReason, StopReason


@dataclass(frozen=True)
class StepRecord:
    step: int
    human_before: tuple[str, ...]
    perceived_deg: tuple[float | None, ...]
    true_deg: tuple[float, ...]  # the simulator's measured poses, for evaluation only (never sent)
    missing_links: tuple[int, ...]
    decision: DecisionKind
    reason: str
    matched_expected_step: int | None
    action: dict[str, Any] | None = None
    outcome: ActionOutcome | None = None
    outcome_reason: FailureReason | None = None
    outcome_message: str = ""
    reached_deg: float | None = None
    human_during: tuple[str, ...] = ()
    human_assist: str | None = None
    help_requested: tuple[str, ...] = ()  # human_help_requested: the service's sentences, in order
    skill: str | None = None  # robot_skill: the skill asked for and what it did
    measured_deg: float | None = None  # after a failed or partial action: the turned link, as perceived again
    looks: int = 1
    seen_by: tuple[str | None, ...] = ()  # the camera that saw each link (`head`, `cell`; None: unseen)
    perception_s: float = 0.0
    service_s: float = 0.0
    action_s: float = 0.0


@dataclass(frozen=True)
class WorkerSummary:
    object_id: str
    scenario: str
    reached_goal: bool
    stop_reason: StopReason
    steps: tuple[StepRecord, ...]
    configurations: tuple[tuple[float, ...], ...]
    base_points: tuple[tuple[float, float], ...]
    out_dir: str
    wall_s: float
    perception: str = "camera"
    stop_message: str = ""
    human_scheduled: int = 0
    human_performed: int = 0
    final_help: tuple[str, ...] = ()  # ended short of the goal: the help request the worker's stop became

    @property
    def decisions(self) -> tuple[DecisionKind, ...]:
        return tuple(s.decision for s in self.steps)

    @property
    def outcomes(self) -> tuple[ActionOutcome, ...]:
        return tuple(s.outcome for s in self.steps if s.outcome is not None)

    @property
    def human_assists(self) -> int:
        return sum(1 for s in self.steps if s.human_assist)

    @property
    def help_requests(self) -> int:
        return sum(1 for s in self.steps if s.decision is DecisionKind.HUMAN_HELP_REQUESTED)

    @property
    def skills(self) -> int:
        return sum(1 for s in self.steps if s.decision is DecisionKind.ROBOT_SKILL)

    @property
    def seen_links(self) -> int:
        return sum(sum(1 for v in s.perceived_deg if v is not None) for s in self.steps)

    @property
    def unseen_links(self) -> int:
        return sum(len(s.missing_links) for s in self.steps)

    @property
    def failure_reasons(self) -> dict[str, int]:
        out: dict[str, int] = {}
        for s in self.steps:
            if s.outcome_reason:
                out[s.outcome_reason] = out.get(s.outcome_reason, 0) + 1
        return out


def picture_steps(records: Sequence[StepRecord], configurations: Sequence[Sequence[float]],
                  base_points: Sequence[Sequence[float]]) -> list[PictureStep]:
    """The pictures' view of each decision: who changed the object since the previous one and what followed."""
    out = []
    previous: StepRecord | None = None
    for record, theta, base in zip(records, configurations, base_points):
        human = list(record.human_before)
        if previous is not None:
            human = list(previous.human_during) + ([previous.human_assist] if previous.human_assist else []) + human
        actor = "start" if previous is None and not human else actor_between(
            previous.outcome if previous else None, human)
        out.append(PictureStep(
            step=record.step, decision=record.decision, configuration_deg=tuple(theta),
            base_xy=(float(base[0]), float(base[1])), actor=actor, action=describe_action(record.action),
            outcome=record.outcome, human=tuple(human)))
        previous = record
    return out
