"""The re-grasp skill: a turn whose arc the turning arm cannot follow to its end from the link's centre is grasped
nearer the joint (a shorter arc), else done in two grasps: the turning arm takes the link as far as it can, both let
go, and the rest of the turn is planned from there with every pairing of the arms: the other arm takes the turned
link over (a hand-over), or the same arm grasps it again (at its centre, else nearer the joint).

`regrasp_skill` plans without moving anything and returns the two grasps as one `Command` (STYLE: a command or
None); `perform_with_regrasp` plans the turn as one grasp first (`skills.rotate_skill`) and re-grasps only when the
arm cannot follow it, then executes and judges it as any turn (`skills.execute`).
"""
from __future__ import annotations

import logging
import math
from dataclasses import replace

from planhrc.robot_sim.scene import Scene
from planhrc.robot_sim.skills import (ActionResult, Command, Interrupt, Robot, RotationAction, Unreachable, execute,
                                      rotate_skill)

log = logging.getLogger(__name__)

SPLIT_STEP_DEG = 10.0  # where a turn may be split: every 10° of it


def regrasp_skill(scene: Scene, robot: Robot, action: RotationAction) -> Command | None:
    """The turn grasped nearer the joint, else as two grasps (see the module's note), splitting it as late as the
    first grasp can follow; None when nothing works."""
    nearer = rotate_skill(scene, robot, action, near_joint=True)
    if isinstance(nearer, Command):
        log.info("re-grasp: turning l%d holding it nearer the joint", action.turned_link)
        return nearer
    n = max(1, math.ceil(abs(action.delta_deg) / SPLIT_STEP_DEG))
    for k in range(n - 1, 0, -1):
        first_deg = action.delta_deg * k / n
        first = rotate_skill(scene, robot, replace(action, delta_deg=first_deg, macro_steps=1))
        if isinstance(first, Unreachable):
            continue
        rest_action = replace(action, delta_deg=action.delta_deg - first_deg, macro_steps=1)
        rest = rotate_skill(scene, robot, rest_action, turned_so_far=first_deg)
        if isinstance(rest, Unreachable):
            rest = rotate_skill(scene, robot, rest_action, turned_so_far=first_deg, near_joint=True)
        if isinstance(rest, Unreachable):
            continue
        log.info("re-grasp: turning l%d %+g deg, then %+g deg in a second grasp", action.turned_link, first_deg,
                 action.delta_deg - first_deg)
        return Command(first.primitives + rest.primitives, first.joint, first.turned, float(action.delta_deg),
                       action.turned_link, action.held_link)
    return None


def perform_with_regrasp(scene: Scene, robot: Robot, action: RotationAction, interrupt: Interrupt | None = None,
                         stop_fraction: float | None = None) -> ActionResult:
    """Plan the turn in one grasp, else in two (`regrasp_skill`), and execute it; a turn that cannot be planned
    either way is FAILED (`unreachable`, naming the link) and nothing moves."""
    command: Command | Unreachable | None = rotate_skill(scene, robot, action)
    if isinstance(command, Unreachable):
        command = regrasp_skill(scene, robot, action) or command
    return execute(scene, command, robot, interrupt, stop_fraction)
