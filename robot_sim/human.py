"""Simulated human co-workers, as data: what the human does to the object, and when.

A scenario is a list of `HumanEvent`s plus `RobotFault`s (a robot rotation that stops part-way). Steps count
the worker's perceive -> act cycles from 1. Timing of an event:

* ``before``: after the robot's previous action and before it perceives at that step. If the goal was reached
  before the step comes, the human acts once the robot is idle and the robot perceives again.
* ``during``: half-way through the robot's rotation at that step.

Kinds of event (the human turns a link lK about joint point pK: lK .. lN move, l(K-1) stays):

* ``rotate``: turn link `link` (negative counts from the end: -1 = the last link) by `delta_deg`.
* ``toward_goal``: turn some link beyond the ones the robot handles by one step towards the goal.
* ``next_planned``: do the plan's action that follows the robot's current one (the worker looks it up).
* ``complete_partial``: finish the robot's last rotation that stopped part-way.

`delta_deg=None` means one step of the object's orientation set, in the direction `direction` (+1 = clockwise).
"""
from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import Callable, Mapping, Sequence

import numpy as np

from planhrc.robot_sim.scene import Scene, SimError, is_workable

log = logging.getLogger(__name__)

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
    on: the goal comes early); later the human disturbs link 2, and the robot puts it back."""
    return Scenario(
        "fig13", assists_after_failures=2,
        events=(
            HumanEvent(at_step=1, when="during", kind="next_planned"),
            HumanEvent(at_step=3, when="before", kind="rotate", link=2, delta_deg=None, direction=1),
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


def scenario_random(seed: int = 0, n: int = 3, max_step: int = 6, n_links: int = 5) -> Scenario:
    """`n` random interventions: a random link turned by one step either way, before or during a random step."""
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
}


def get_scenario(name: str, n_links: int = 5) -> Scenario:
    """`none`, `fig13`, `fig14` or `random:SEED:N` (also `random`, = random:0:3)."""
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


# -- acting on the scene -------------------------------------------------------------------------------------
@dataclass
class HumanContext:
    """What a simulated human knows when acting: the orientation step, the goal, the robot's current work."""

    step_deg: float
    goal_differences: Mapping[int, float] = field(default_factory=dict)  # link K -> wanted theta_K - theta_(K-1)
    busy_links: tuple[int, ...] = ()  # links the robot is handling now
    partial: tuple[int, int, float] | None = None  # (turned link, held link, remaining degrees) of a stopped rotation
    next_planned: tuple[int, int, float] | None = None  # (turned link, held link, degrees) of the plan's next action


def goal_differences(formulation: str, joint_values: Mapping[int, float | None]) -> dict[int, float]:
    """Link K -> wanted theta_K - theta_(K-1) (theta_0 = 0, the table) from the goal's joint values.

    Absolute: joint jK carries theta_K. Relative: jK carries theta_(K+1) - theta_K. None = free joint.
    """
    out: dict[int, float] = {}
    if formulation == "absolute":
        for k, v in joint_values.items():
            prev = 0.0 if k == 1 else joint_values.get(k - 1)
            if v is not None and prev is not None:
                out[k] = (float(v) - float(prev)) % 360.0
    else:
        for k, v in joint_values.items():
            if v is not None:
                out[k + 1] = float(v) % 360.0
    return out


def _difference(theta: Sequence[float], link: int) -> float:
    prev = 0.0 if link == 1 else theta[link - 2]
    return (theta[link - 1] - prev) % 360.0


def apply_event(scene: Scene, event: HumanEvent, context: HumanContext) -> str | None:
    """Perform `event` on the scene; return a description of what the human did, or None if nothing."""
    n = scene.n_links
    if event.kind == "rotate":
        link = event.link if event.link > 0 else n + 1 + event.link
        if not 1 <= link <= n:
            raise SimError(f"link: {event.link} is not a link of a {n}-link object")
        delta = event.delta_deg if event.delta_deg is not None else event.direction * context.step_deg
        if event.keep_workable:
            return _considerate_rotation(scene, link, delta, context)
        scene.rotate_at_joint(link, delta, "downstream")
        return f"human turned l{link} by {delta:+g} deg"
    if event.kind == "next_planned":
        if context.next_planned is None:
            log.info("human: the plan has no action after the robot's current one")
            return None
        turned, held, delta = context.next_planned
        scene.rotate_link(turned, held, delta)
        context.next_planned = None
        return f"human did the plan's next action: l{turned} (holding l{held}) by {delta:+g} deg"
    if event.kind == "complete_partial":
        if context.partial is None:
            log.info("human: no partial rotation to complete")
            return None
        turned, held, remaining = context.partial
        scene.rotate_link(turned, held, remaining)
        context.partial = None
        return f"human completed the rotation of l{turned} by {remaining:+g} deg"
    # toward_goal: the highest link beyond the robot's hands whose angle to its predecessor is off the goal
    # (turning a link at or before them would move the links the robot holds)
    _, theta = scene.configuration()
    first_free = max(context.busy_links, default=0) + 1
    for link in sorted(context.goal_differences, reverse=True):
        if link < first_free:
            continue
        wanted = context.goal_differences[link]
        off = (wanted - _difference(theta, link) + 180.0) % 360.0 - 180.0
        if abs(off) >= context.step_deg / 2:
            delta = context.step_deg if off > 0 else -context.step_deg
            scene.rotate_at_joint(link, delta, "downstream")
            return f"human turned l{link} by {delta:+g} deg towards the goal"
    log.info("human: no link to turn towards the goal")
    return None


def _considerate_rotation(scene: Scene, link: int, delta: float, context: HumanContext) -> str | None:
    """Turn `link` (or, while the robot works, a link beyond its hands) by `delta`, or the other way, so that
    the object stays within the robot's reach; do nothing when no such move exists."""
    first_free = max(context.busy_links, default=0) + 1
    candidates = [link] if link >= first_free else []
    candidates += [k for k in range(first_free, scene.n_links + 1) if k != link]
    base, theta = scene.configuration()
    for k in candidates:
        for d in (delta, -delta):
            trial = [t + d if i >= k - 1 else t for i, t in enumerate(theta)]
            if is_workable(scene.spec, trial, base):
                scene.rotate_at_joint(k, d, "downstream")
                return f"human turned l{k} by {d:+g} deg"
    log.info("human: no move of l%d or beyond keeps the object workable", link)
    return None


def assist_failed_action(scene: Scene, turned_link: int, held_link: int, delta_deg: float) -> str:
    """The human performs the rotation the robot could not (the paper's cooperation model)."""
    scene.rotate_link(turned_link, held_link, delta_deg)
    return f"human did the robot's failed action: l{turned_link} (holding l{held_link}) by {delta_deg:+g} deg"
