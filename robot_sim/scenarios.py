"""What the simulated human does to the object and when: scenarios, as data (`robot_sim.human` acts them out).

A scenario is a list of `HumanEvent`s plus `RobotFault`s (a robot rotation that stops part-way). Steps count
the worker's perceive -> act cycles from 1. Timing of an event:

* ``before``: after the robot's previous action and before it perceives at that step. If the goal was reached
  before the step comes, the human acts once the robot is idle and the robot perceives again.
* ``during``: half-way through the robot's rotation at that step (the human acts while the robot turns; if the
  robot's action stops early, the human acts anyway).

Kinds of event (the human turns a link lK about joint point pK: lK .. lN move, l(K-1) stays):

* ``rotate``: turn link `link` (negative counts from the end: -1 = the last link) by `delta_deg`.
* ``toward_goal``: turn some link beyond the ones the robot handles by one step towards the goal.
* ``next_planned``: do the plan's action that follows the robot's current one (the worker looks it up).
* ``complete_partial``: finish the robot's last rotation that stopped part-way.

`delta_deg=None` means one step of the object's orientation set, in the direction `direction` (+1 = clockwise).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from planhrc.robot_sim.errors import SimError

WHEN = ("before", "during")
KINDS = ("rotate", "toward_goal", "next_planned", "complete_partial")


@dataclass(frozen=True)
class HumanEvent:
    at_step: int
    when: str
    link: int | None = None
    delta_deg: float | None = None
    kind: str = "rotate"
    direction: int = 1
    keep_workable: bool = False  # a considerate human: only moves that leave the object within the robot's reach

    def __post_init__(self) -> None:
        if self.at_step < 1:
            raise SimError(f"at_step: must be >= 1, got {self.at_step}")
        if self.when not in WHEN:
            raise SimError(f"when: must be one of {WHEN}, got {self.when!r}")
        if self.kind not in KINDS:
            raise SimError(f"kind: must be one of {KINDS}, got {self.kind!r}")
        if self.kind == "rotate" and (self.link is None or self.link == 0):
            raise SimError("link: a 'rotate' event names the link the human turns (1-based, or negative from the end)")


@dataclass(frozen=True)
class RobotFault:
    """The robot's rotation at `at_step` stops after `stop_fraction` of its amount (a partial execution)."""

    at_step: int
    stop_fraction: float

    def __post_init__(self) -> None:
        if not 0.0 <= self.stop_fraction < 1.0:
            raise SimError(f"stop_fraction: must be in [0, 1), got {self.stop_fraction}")


@dataclass(frozen=True)
class Scenario:
    name: str
    events: tuple[HumanEvent, ...] = ()
    faults: tuple[RobotFault, ...] = ()
    # The paper: when a robot action is not successful, the human can do it on the robot's behalf.
    assists_after_failures: int | None = None

    def events_at(self, step: int, when: str) -> tuple[HumanEvent, ...]:
        return tuple(e for e in self.events if e.at_step == step and e.when == when)

    def fault_at(self, step: int) -> RobotFault | None:
        return next((f for f in self.faults if f.at_step == step), None)

    def pending_after(self, step: int) -> tuple[HumanEvent, ...]:
        """Events still to come after `step`, in order."""
        return tuple(sorted((e for e in self.events if e.at_step > step), key=lambda e: (e.at_step, e.when)))


def scenario_none() -> Scenario:
    return Scenario("none")


def scenario_fig13() -> Scenario:
    """While the robot does its first action the human does the plan's second one (the robot resumes further
    on: the goal comes early); later the human disturbs link 3, and the robot puts it back."""
    return Scenario(
        "fig13", assists_after_failures=2,
        events=(
            HumanEvent(at_step=1, when="during", kind="next_planned"),
            HumanEvent(at_step=3, when="before", kind="rotate", link=3, delta_deg=None, direction=1),
        ),
    )


def scenario_fig14() -> Scenario:
    """The robot's second rotation stops half-way; the human completes it and also turns the last link."""
    return Scenario(
        "fig14", assists_after_failures=2,
        events=(
            HumanEvent(at_step=3, when="before", kind="complete_partial"),
            HumanEvent(at_step=3, when="before", kind="rotate", link=-1, delta_deg=None, direction=-1),
        ),
        faults=(RobotFault(at_step=2, stop_fraction=0.5),),
    )


def scenario_bimanual() -> Scenario:
    """Once the robot holds two links (after its first step, a grasp), the human turns the last link, beyond them,
    one step clockwise: the robot's turn still applies, and the last joint needs a turn of its own afterwards."""
    return Scenario(
        "bimanual", assists_after_failures=2,
        events=(HumanEvent(at_step=2, when="before", kind="rotate", link=-1, delta_deg=None, direction=1),),
    )


def scenario_random(seed: int = 0, n: int = 3, max_step: int = 6, n_links: int = 5) -> Scenario:
    """`n` random interventions: any link of the chain turned by one step either way, before or during a
    random step (a considerate human: only moves that keep the object feasible, see `planhrc.geometry`)."""
    rng = np.random.default_rng(seed)
    events = tuple(
        sorted(
            (
                HumanEvent(
                    at_step=int(rng.integers(1, max_step + 1)),
                    when=str(rng.choice(WHEN)),
                    kind="rotate",
                    link=int(rng.integers(1, n_links + 1)),
                    delta_deg=None,
                    direction=int(rng.choice([-1, 1])),
                    keep_workable=True,
                )
                for _ in range(n)
            ),
            key=lambda e: (e.at_step, e.when),
        )
    )
    return Scenario(f"random-{seed}-{n}", events=events, assists_after_failures=2)


SCENARIOS: dict[str, Callable[[], Scenario]] = {
    "none": scenario_none,
    "fig13": scenario_fig13,
    "fig14": scenario_fig14,
    "bimanual": scenario_bimanual,
}


def get_scenario(name: str, n_links: int = 5) -> Scenario:
    """`none`, `fig13`, `fig14`, `bimanual` or `random:SEED:N` (also `random`, = random:0:3)."""
    if name in SCENARIOS:
        return SCENARIOS[name]()
    if name == "random" or name.startswith("random:"):
        parts = name.split(":")
        try:
            seed = int(parts[1]) if len(parts) > 1 else 0
            n = int(parts[2]) if len(parts) > 2 else 3
        except ValueError as exc:
            raise SimError(f"human_scenario: expected random:SEED:N, got {name!r}") from exc
        return scenario_random(seed, n, n_links=n_links)
    raise SimError(f"human_scenario: unknown {name!r}; choose from {sorted(SCENARIOS)} or random:SEED:N")
