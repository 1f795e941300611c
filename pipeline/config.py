"""The pipeline's values: how plans are made (`PlanningConfig`, built from the settings) and what one run made
(`PlanOutcome`), with the deadline every stage keeps."""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping, Sequence

from planhrc.model import ActionSpec, ArticulatedObject, State
from planhrc.motion_search import Slide
from planhrc.ordering import HelpItem
from planhrc.planner.result import PlannerAttempt
from planhrc.settings import Settings
from planhrc.translator.translate import PddlTask
from planhrc.vocabulary import PlanningStatus


@dataclass(frozen=True)
class PlanningConfig:
    """How plans are made; built from the settings (`config_from_settings`), which hold every default."""

    tbox_path: Path
    planner: str
    timeout_s: float
    validate: bool
    fallback_planner: str | None
    deadline_s: float = 10.0  # planning and VAL of one request together
    val_pieces: int = 1  # VAL runs on this many pieces of a long plan at once (see `validate`)


def config_from_settings(settings: Settings) -> PlanningConfig:
    return PlanningConfig(
        tbox_path=Path(settings.tbox_path),
        planner=settings.planner,
        timeout_s=float(settings.planner_timeout_s),
        validate=bool(settings.validate_plans),
        fallback_planner=settings.fallback_planner or None,
        deadline_s=float(settings.planning_deadline_s),
        val_pieces=int(settings.val_pieces),
    )


@dataclass(frozen=True)
class LaterSlide:
    """A slide a placed object's plan makes between two of its turns: before step `before_step` (1-based, > 1)."""

    before_step: int
    slide: Slide


@dataclass(frozen=True)
class PlanOutcome:
    """What one run of the pipeline produced.

    When solved, `actions` are the ground actions a_1 .. a_N and `expected_states` the states s^e_1 .. s^e_{N+1}
    (s^e_1 is the initial state; the replay's `ExpectedStates`, each state made whole when read); both are empty when the initial state already satisfies the goal or when
    nothing was solved. `task` is the PDDL the planner saw (None when no planner ran)."""

    status: PlanningStatus
    message: str
    planner: str
    optimal: bool | None = None
    actions: tuple[ActionSpec, ...] = ()
    expected_states: Sequence[State] = ()
    timings: Mapping[str, float] = field(default_factory=dict)
    task: PddlTask | None = None
    attempts: tuple[PlannerAttempt, ...] = ()
    steps: tuple[str, ...] = ()  # the planner's plan as VAL reads it, one "(action arg ...)" per step
    validated: bool = False  # VAL accepted the plan
    validated_steps: int = 0  # VAL accepted the first steps a_1 .. a_k so far (the early answer; see `validate_first`)
    help: tuple[HelpItem, ...] = ()  # no feasible order: what the human could do instead
    ordering: str = ""  # what the ordering did, in words (empty when the object is not placed)
    slide: Slide | None = None  # the plan's turns are made after the robot has slid the object there
    later_slides: tuple[LaterSlide, ...] = ()  # slides between the plan's turns (`order.LaterSlide`)
    # no plan where the links lie, one once these turns (turned link, held link, degrees) put them back on the grid
    straighten: tuple[tuple[int, int, float], ...] = ()

    @property
    def solved(self) -> bool:
        return self.status is PlanningStatus.SOLVED


def problem_name(obj: ArticulatedObject) -> str:
    """The name of an object's PDDL problem (the same for every re-plan, so the text depends on states only)."""
    return f"{obj.ident}-task"


def deadline_from(config: PlanningConfig) -> float:
    """The `time.monotonic()` by which a request planned now must be done."""
    return time.monotonic() + config.deadline_s


def time_left(deadline_at: float) -> float:
    """Seconds until `deadline_at` (`time.monotonic()`), negative once it passed."""
    return deadline_at - time.monotonic()


def over_deadline(config: PlanningConfig, where: str, planner: str, timings: Mapping[str, float],
                  task: PddlTask | None) -> PlanOutcome:
    return PlanOutcome(PlanningStatus.TIMEOUT, f"planning deadline of {config.deadline_s:g} s exceeded {where}",
                       planner, timings=timings, task=task)
