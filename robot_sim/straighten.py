"""The straighten skill: links a turn dragged off the orientation grid turned back onto it, the service's turns in
order (`planhrc.vocabulary.Skill.STRAIGHTEN`; the service judged each from the measured pose, as it judges a rotation
it dispatches), each grasped and turned as a rotation is (`robot_sim.regrasp`)."""
from __future__ import annotations

from typing import Sequence

from planhrc.robot_sim.regrasp import perform_with_regrasp
from planhrc.robot_sim.scene import Scene
from planhrc.robot_sim.skills import Robot, RotationAction
from planhrc.robot_sim.slide import SlideResult
from planhrc.vocabulary import ActionOutcome


def straighten(scene: Scene, robot: Robot, turns: Sequence[tuple[int, int, float]]) -> SlideResult:
    """Make `turns` (turned link, held link, 0 = the table, degrees) one after the other; the first that does not
    succeed ends the skill with its outcome."""
    if not turns:
        return SlideResult(ActionOutcome.FAILED, None, "straighten: no turns", 0.0)
    done = []
    for turned, held, delta in turns:
        result = perform_with_regrasp(scene, robot, RotationAction(turned, held, delta, name="straighten"))
        if result.outcome is not ActionOutcome.SUCCEEDED:
            return SlideResult(result.outcome, result.reason, f"straighten: link {turned}: {result.message}", 0.0)
        done.append(f"link {turned} {result.reached_deg:+.1f} deg of {delta:+.1f}")
    return SlideResult(ActionOutcome.SUCCEEDED, None, "straightened: " + ", ".join(done), 0.0)
