"""What the worker does with what the service dispatches: a rotation, judged first by the one judge
(`planhrc.judge.judge_motion`) from the pose the worker measured and sent with its perception (the service judged
the same motion from the same pose before it dispatched it), then performed physically in its single steps when a
macro step failed; or a skill the service asks for besides rotations (`SKILLS`, one module each).

A turn the judge refuses is not started: the result is FAILED with the geometric fact (`refusal`: which link,
against what, how far, and the pose judged from) for the service to remember. A turn the arms cannot follow (no arm
pose reaches a grasp point along the way) fails `unreachable` with the same kind of fact.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass, replace
from typing import Any, Callable, Sequence

from planhrc.geometry import Cell, Infeasibility, ObjectGeometry, rotated
from planhrc.judge import judge_motion
from planhrc.robot_sim.regrasp import perform_with_regrasp
from planhrc.robot_sim.scene import Scene
from planhrc.robot_sim.skills import ActionResult, Interrupt, Robot, RotationAction
from planhrc.robot_sim.slide import SlideResult, slide
from planhrc.robot_sim.straighten import straighten
from planhrc.vocabulary import ActionOutcome, FailureReason, Infeasible, Skill

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Pose:
    """Where the object lies as the worker measured it (and told the service): its base point and every link's
    orientation."""

    geometry: ObjectGeometry
    angles: tuple[float, ...]

    def after(self, action: RotationAction) -> "Pose":
        """The pose once `action` is done as commanded."""
        geometry, angles = rotated(self.geometry, self.angles, action.turned_link, action.held_link, action.delta_deg)
        return Pose(geometry, angles)


def measured_pose(scene: Scene, link_deg: Sequence[float | None], base_xy: Sequence[float] | None) -> Pose:
    """The pose as perceived (a link not seen takes the scene's measured orientation: the service was not asked to
    act on such a perception)."""
    truth_base, truth = scene.configuration()
    angles = tuple(float(v) if v is not None else float(t) for v, t in zip(link_deg, truth))
    return Pose(scene.spec.geometry(base_xy if base_xy is not None else truth_base), angles)


def refusal_of(pose: Pose, reason: Infeasibility) -> dict[str, Any]:
    """The feedback's `refusal`: the fact and the pose it was judged from."""
    return {"code": reason.code.value, "link": reason.link, "against": reason.against,
            "distance_m": round(float(reason.distance_m), 4), "from_deg": [round(a, 2) for a in pose.angles],
            "base_point_xy": [round(float(v), 4) for v in pose.geometry.base_point_xy]}


def judge(pose: Pose, cell: Cell, action: RotationAction, final: bool) -> ActionResult | None:
    """A FAILED result, nothing moved, when the one judge refuses the turn from `pose` (see the module's note);
    None when it may be done."""
    verdict = judge_motion(pose.geometry, pose.angles, action.turned_link, action.held_link, action.delta_deg, cell,
                           final)
    if verdict.ok:
        return None
    first = verdict.reasons[0]
    reason = {Infeasible.OFF_TABLE: FailureReason.LEFT_TABLE, Infeasible.INSIDE_ROBOT: FailureReason.LEFT_TABLE,
              Infeasible.OUT_OF_REACH: FailureReason.UNREACHABLE}.get(first.code, FailureReason.COLLISION)
    log.warning("not turning l%d by %+g deg: %s", action.turned_link, action.delta_deg, verdict.sentence())
    return ActionResult(ActionOutcome.FAILED, reason, f"not started: turning link {action.turned_link} by "
                        f"{action.delta_deg:+g} deg would end with {verdict.sentence()}", action.delta_deg, 0.0,
                        refusal_of(pose, first))


def way_round(pose: Pose, cell: Cell, action: RotationAction, final: bool) -> RotationAction:
    """The action, or the same turn the other way round when the judge refuses the dispatched way and accepts the
    other: both end in the same orientation."""
    if abs(action.delta_deg) < 1e-9 or judge(pose, cell, action, final) is None:
        return action
    other = action.delta_deg - (360.0 if action.delta_deg > 0 else -360.0)
    step = abs(action.delta_deg) / max(1, action.macro_steps)
    turned = replace(action, delta_deg=other, macro_steps=max(1, round(abs(other) / step)))
    if judge(pose, cell, turned, final) is not None:
        return action
    log.info("turning l%d the other way round (%+g deg instead of %+g): that way stays on the table",
             action.turned_link, other, action.delta_deg)
    return turned


def perform_parts(scene: Scene, robot: Robot, pose: Pose, parts: Sequence[RotationAction], final: bool,
                  interrupt: Interrupt, stop_fraction: float | None,
                  turn: Callable[[RotationAction], ActionResult] | None = None) -> ActionResult:
    """Perform an action's parts (the whole motion, or its single steps) one after the other, each judged from
    the pose the ones before it leave (as commanded); stop at the first that is refused or does not succeed. The
    result covers them all: the turn reached is their sum. `turn` performs one part (default: grasp, turn and let
    go, re-grasping where the arm cannot follow; a bimanual object's held links: `robot_sim.bimanual`)."""
    reached = 0.0
    result = None
    cell = scene.spec.cell()
    for i, part in enumerate(parts):
        result = judge(pose, cell, part, final and i == len(parts) - 1) or (
            turn(part) if turn is not None
            else perform_with_regrasp(scene, robot, part, interrupt=interrupt, stop_fraction=stop_fraction))
        if result.reason is FailureReason.UNREACHABLE and result.refusal is None and result.reached_deg == 0.0:
            result = replace(result, refusal=refusal_of(pose, Infeasibility(
                Infeasible.OUT_OF_REACH, part.turned_link, result.message, 0.0, "the arms' reach")))
        reached += result.reached_deg
        if result.outcome is not ActionOutcome.SUCCEEDED:
            break
        pose = pose.after(part)
    assert result is not None
    if len(parts) == 1:
        return result
    total = sum(p.delta_deg for p in parts)
    outcome = result.outcome
    if outcome is ActionOutcome.FAILED and abs(reached) > 1.0:
        outcome = ActionOutcome.PARTIAL
    return ActionResult(outcome, result.reason, f"in single steps: {result.message}", total, reached,
                        result.refusal if outcome is ActionOutcome.FAILED else None)


def _slide(scene: Scene, robot: Robot, skill: dict[str, Any]) -> SlideResult:
    to = [float(v) for v in skill.get("base_point_xy") or ()]
    if len(to) != 2:
        return SlideResult(ActionOutcome.FAILED, None, "slide: no base point to slide to", 0.0)
    return slide(scene, robot, (to[0], to[1]), [int(k) for k in skill.get("links") or ()])


def _straighten(scene: Scene, robot: Robot, skill: dict[str, Any]) -> SlideResult:
    try:
        turns = [(int(t), int(h), float(d)) for t, h, d in skill.get("turns") or ()]
    except (TypeError, ValueError):
        return SlideResult(ActionOutcome.FAILED, None, "straighten: turns must be [turned, held, degrees]", 0.0)
    return straighten(scene, robot, turns)


# the skills the service may ask for besides rotations (`planhrc.vocabulary.Skill`), one module each
SKILLS: dict[str, Callable[[Scene, Robot, dict[str, Any]], SlideResult]] = {Skill.SLIDE: _slide,
                                                                            Skill.STRAIGHTEN: _straighten}


def perform_skill(scene: Scene, robot: Robot, skill: dict[str, Any]) -> str:
    """Do the robot skill the service asked for (`SKILLS`), and say what it did; the next perception shows where
    the object lies now."""
    name = str(skill.get("name"))
    if name not in SKILLS:
        log.warning("skill %r: not a skill of this worker", name)
        return f"{name}: not a skill of this worker"
    result = SKILLS[name](scene, robot, skill)
    log.info("skill %s: %s (%s)", name, result.outcome.value, result.message)
    return f"{name} {result.outcome.value}: {result.message}"
