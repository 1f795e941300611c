"""Simulated human co-workers: a visible body that acts on the object physically, in parallel with the robot, on
the physics clock (`Human`), and the choice of what it does for each scenario event (`robot_sim.scenarios` holds
the scenarios as data).
"""
from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field
from typing import Callable, Iterator, Mapping, Sequence

import numpy as np
import pybullet

from planhrc.geometry import PLANNING, configuration_feasible, rotated
from planhrc.robot_sim.handling import SWEEP_HAZARDS, joint_angles, shorter, turn_order, turn_path
from planhrc.robot_sim.errors import SimError
from planhrc.robot_sim.scenarios import HumanEvent
from planhrc.robot_sim.scene import (HAZARDS, TIME_STEP_S, Scene, baseline_problems, direction, eased, new_hazards,
                                    sweep_hazard, turn_hazard)

log = logging.getLogger(__name__)

# Where a hand goes at a tick: (table point, height, yaw in degrees), worked out when it gets there.
HandTarget = Callable[[], tuple[np.ndarray, float, float]]


# -- acting on the scene -------------------------------------------------------------------------------------


@dataclass(frozen=True)
class RobotTurn:
    """The robot's rotation under way: `turned` about its joint with `held` by `delta_deg` in all, from the
    configuration (`base_xy`, `theta`) it started from."""

    turned: int
    held: int
    delta_deg: float
    base_xy: tuple[float, float]
    theta: tuple[float, ...]


@dataclass
class HumanContext:
    """What a simulated human knows when acting: the orientation step, the goal, the robot's current work."""

    step_deg: float
    goal_differences: Mapping[int, float] = field(default_factory=dict)  # link K -> wanted theta_K - theta_(K-1)
    busy_links: tuple[int, ...] = ()  # links the robot is handling now
    partial: tuple[int, int, float] | None = None  # (turned link, held link, remaining degrees) of a stopped rotation
    next_planned: tuple[int, int, float] | None = None  # (turned link, held link, degrees) of the plan's next action
    robot_turn: RobotTurn | None = None  # the robot's rotation under way, if any


def goal_differences(formulation: str, joint_values: Mapping[int, float | None]) -> dict[int, float]:
    """Link K -> wanted theta_K - theta_(K-1) (theta_0 = 0, the table) from the goal's joint values.

    Absolute: joint jK carries theta_K. Bimanual: jK carries theta_(K+1) - theta_1 (l1 itself is free). Relative:
    jK carries theta_(K+1) - theta_K. None = free joint.
    """
    out: dict[int, float] = {}
    if formulation == "absolute":
        for k, v in joint_values.items():
            prev = 0.0 if k == 1 else joint_values.get(k - 1)
            if v is not None and prev is not None:
                out[k] = (float(v) - float(prev)) % 360.0
    elif formulation == "bimanual":
        for k, v in joint_values.items():
            prev = 0.0 if k == 1 else joint_values.get(k - 1)  # l1 measured from itself
            if v is not None and prev is not None:
                out[k + 1] = (float(v) - float(prev)) % 360.0
    else:
        for k, v in joint_values.items():
            if v is not None:
                out[k + 1] = float(v) % 360.0
    return out


def _difference(theta: Sequence[float], link: int) -> float:
    prev = 0.0 if link == 1 else theta[link - 2]
    return (theta[link - 1] - prev) % 360.0


def _move(link: int, delta: float, what: str) -> HumanMove:
    held = link - 1  # the human turns lK about pK: lK .. lN move, l(K-1) (or the table) stays
    return HumanMove(link, held, delta, f"{what} l{link} by {delta:+g} deg")


def _feasible_after(scene: Scene, link: int, delta: float, robot_turn: RobotTurn | None = None,
                    queued: Sequence[HumanMove] = ()) -> bool:
    """Whether turning `link` (after the human's `queued` moves) keeps the object on the table, clear of the
    robot's body and not overlapping, all the way (with the tolerance of a physical move,
    `planhrc.geometry.EXECUTION`), and leaves it feasible with the clearance the robot's plans keep
    (`planhrc.geometry.PLANNING`: 1.5 cm from the table's edges, so that the human's physical turn, a degree or two
    off, still ends on the table), together with the robot's rotation under way (`robot_turn`: its sweep, from
    where it started, with the human's turns made, and its end). A problem the object has already (judged the
    same way) does not stop a move. The human reaches anywhere; whether the robot can reach afterwards is the
    robot's matter."""
    base, theta = scene.configuration()
    cell = scene.spec.cell()
    geometry, values = scene.spec.geometry(base), tuple(theta)
    before = baseline_problems(geometry, values, cell)
    before_end = baseline_problems(geometry, values, cell, PLANNING)
    moves = [(m.turned, m.held, m.delta_deg) for m in queued]
    for turned, held, d in moves:
        geometry, values = rotated(geometry, values, turned, held, d)
    if sweep_hazard(geometry, values, cell, link, link - 1, delta, before) is not None:
        return False
    geometry, values = rotated(geometry, values, link, link - 1, delta)
    if robot_turn is not None:  # the turns commute: the robot's whole sweep, with the human's turns made first
        geometry, values = scene.spec.geometry(robot_turn.base_xy), robot_turn.theta
        for turned, held, d in [*moves, (link, link - 1, delta)]:
            geometry, values = rotated(geometry, values, turned, held, d)
        if sweep_hazard(geometry, values, cell, robot_turn.turned, robot_turn.held, robot_turn.delta_deg,
                        before) is not None:
            return False
        geometry, values = rotated(geometry, values, robot_turn.turned, robot_turn.held, robot_turn.delta_deg)
    return not any(r.code in HAZARDS and (r.code, r.link) not in before_end
                   for r in configuration_feasible(geometry, values, cell, tolerance=PLANNING).reasons)


def safe_way(scene: Scene, turned: int, held: int, delta_deg: float) -> float | None:
    """`delta_deg`, or the same turn the other way round when only that way is safe all along; None when
    neither is (see `turn_hazard`)."""
    if abs(delta_deg) < 1e-9 or turn_hazard(scene, turned, held, delta_deg) is None:
        return delta_deg
    other = delta_deg - math.copysign(360.0, delta_deg)
    return other if turn_hazard(scene, turned, held, other) is None else None


def choose_move(scene: Scene, event: HumanEvent, context: HumanContext,
                queued: Sequence[HumanMove] = ()) -> HumanMove | None:
    """What the human will do for `event` now, after the moves it has `queued` already, or None when there is
    nothing to do."""
    n = scene.n_links
    first_free = max(context.busy_links, default=0) + 1  # links the robot does not hold and does not move
    if event.kind == "rotate":
        if event.link is None:
            raise SimError("link: a rotate event names the link it turns")
        link = event.link if event.link > 0 else n + 1 + event.link
        if not 1 <= link <= n:
            raise SimError(f"link: {event.link} is not a link of a {n}-link object")
        delta = event.delta_deg if event.delta_deg is not None else event.direction * context.step_deg
        if not event.keep_workable:
            return _move(link, delta, "human turned")
        # a considerate human: this link or any other it may touch, either way, keeping the object feasible
        candidates = ([link] if link >= first_free else []) + [k for k in range(first_free, n + 1) if k != link]
        for k in candidates:
            for d in (delta, -delta):
                if _feasible_after(scene, k, d, context.robot_turn, queued):
                    return _move(k, d, "human turned")
        log.info("human: no move of l%d or any free link keeps the object feasible", link)
        return None
    if event.kind == "next_planned":
        if context.next_planned is None:
            log.info("human: the plan has no action after the robot's current one")
            return None
        turned, held, delta = context.next_planned
        context.next_planned = None
        return HumanMove(turned, held, delta, f"human did the plan's next action: l{turned} (holding l{held}) by {delta:+g} deg")
    if event.kind == "complete_partial":
        if context.partial is None:
            log.info("human: no partial rotation to complete")
            return None
        turned, held, remaining = context.partial
        context.partial = None
        return HumanMove(turned, held, remaining, f"human completed the rotation of l{turned} by {remaining:+g} deg")
    # toward_goal: the highest link beyond the robot's hands whose angle to its predecessor is off the goal
    _, theta = scene.configuration()
    for link in sorted(context.goal_differences, reverse=True):
        if link < first_free:
            continue
        off = (context.goal_differences[link] - _difference(theta, link) + 180.0) % 360.0 - 180.0
        if abs(off) >= context.step_deg / 2:
            delta = context.step_deg if off > 0 else -context.step_deg
            return _move(link, delta, "human turned (towards the goal)")
    log.info("human: no link to turn towards the goal")
    return None


def apply_event(human: Human, event: HumanEvent, context: HumanContext) -> str | None:
    """Start the human's move for `event` (it happens on the physics clock); its description, or None."""
    move = choose_move(human.scene, event, context, tuple(human.queue))
    if move is None:
        return None
    human.start(move)
    return move.label


CORRECTION_DEG = 2.0  # a human who looks at the result puts right a joint further off than this


def human_way(scene: Scene, turned: int, held: int, delta_deg: float) -> float | None:
    """`delta_deg`, or the same turn the other way round, whichever a human can make safely in one move (its sweep
    keeps the object on the table and clear of the robot, see `handling`; its end adds no problem, see
    `new_hazards`); None when neither."""
    base, theta = scene.configuration()
    geometry, cell = scene.spec.geometry(base), scene.spec.cell()
    baseline = baseline_problems(geometry, theta, cell)
    ways = (delta_deg,) if abs(delta_deg) < 1e-9 else (delta_deg, delta_deg - math.copysign(360.0, delta_deg))
    for way in ways:
        if sweep_hazard(geometry, theta, cell, turned, held, way, baseline, SWEEP_HAZARDS) is not None:
            continue
        if not new_hazards(scene, *rotated(geometry, theta, turned, held, way)):
            return way
    return None


def assist_failed_action(human: Human, turned_link: int, held_link: int, delta_deg: float) -> str | None:
    """The human performs the rotation the robot could not (the paper's cooperation model): in one move the way
    round that keeps the object safe, else through safe intermediate configurations to the same orientations
    (`bring_to`); None (nothing done) when there is no safe way."""
    scene = human.scene
    delta = human_way(scene, turned_link, held_link, delta_deg)
    if delta is None:
        base, theta = scene.configuration()
        _, end = rotated(scene.spec.geometry(base), theta, turned_link, held_link, delta_deg)
        done = bring_to(human, end, f"human did the robot's failed action (l{turned_link} by {delta_deg:+g} deg)")
        if done is None:
            log.info("human: turning l%d by %+g deg would harm the object, whichever way; not done", turned_link,
                     delta_deg)
            return None
        return "; ".join(done)
    move = HumanMove(turned_link, held_link, delta,
                     f"human did the robot's failed action: l{turned_link} (holding l{held_link}) by {delta:+g} deg")
    human.start(move)
    human.finish()
    return move.label


def help_turns(human: Human, requests: Sequence[tuple[int, float]]) -> list[str] | None:
    """What the robot asked for (`human_help_requested`): each link `link` pointing at `to_deg`, the links beyond
    carried along when a link before them turns, as if done upstream first (assumption A1); the labels of the
    moves made (empty when every link points there already), or None, nothing done, when that end would lie
    past the table's edge, inside the robot or folded, or there is no safe way there (see `bring_to`)."""
    _, theta = human.scene.configuration()
    end = tuple(theta)
    for link, to_deg in sorted((int(link), float(to_deg)) for link, to_deg in requests):
        end = rotated(human.scene.spec.geometry(), end, link, link - 1, shorter(to_deg - end[link - 1]))[1]
    return bring_to(human, end, "human helped")


def bring_to(human: Human, end: Sequence[float], what: str) -> list[str] | None:
    """Bring the object to the link orientations `end` (its base point where it lies): the labels of the moves
    made, or None, nothing done, when `end` would lie past the table's edge, inside the robot or folded, or no
    safe way there is found.

    The end fixes how much each joint turns; those turns commute, so the human makes them in an order, and each
    the way round, whose sweeps keep the object on the table and clear of the robot (`handling.turn_order`), or
    else through intermediate configurations (`handling.turn_path`). Unlike the robot, a human lifts a link
    over another and is not bound by reach. The human looks at the object itself, turns each joint by what it
    still lacks, and at the end puts right a joint left more than `CORRECTION_DEG` off."""
    scene = human.scene
    base, theta = scene.configuration()
    cell = scene.spec.cell()
    geometry, values = scene.spec.geometry(base), tuple(theta)
    harm = new_hazards(scene, geometry, end)
    if harm:
        log.info("human: the end asked for would have %s; not done", harm[0].message)
        return None
    wanted = joint_angles(end)
    now = joint_angles(values)
    turns = {k: shorter(wanted[k - 1] - now[k - 1]) for k in range(1, len(end) + 1)}
    turns = {k: d for k, d in turns.items() if abs(d) >= 1.0}
    baseline = baseline_problems(geometry, values, cell)
    moves = turn_order(geometry, values, cell, turns, baseline)
    if moves is None:
        moves = turn_path(geometry, values, cell, wanted, baseline)
    if moves is None:
        log.info("human: no way found to turn the joints %s keeping the object on the table and clear of the "
                 "robot; not done", {k: round(d) for k, d in turns.items()})
        return None
    labels: list[str] = []
    target = list(now)
    for link, way in moves:
        target[link - 1] = (target[link - 1] + way) % 360.0
        # what the joint still lacks now (earlier turns may have dragged it), the way round planned
        lacks = shorter(target[link - 1] - joint_angles(scene.link_orientations_deg())[link - 1])
        delta = min((lacks, lacks - 360.0, lacks + 360.0), key=lambda v: abs(v - way))
        if abs(delta) < 1.0:
            continue
        move = HumanMove(link, link - 1, delta, f"{what}: l{link} by {delta:+.0f} deg at its joint")
        human.start(move)
        human.finish()
        labels.append(move.label)
    for _ in range(2):  # look again; put right what the turns left off, upstream first
        for link in range(1, len(end) + 1):
            delta = shorter(wanted[link - 1] - joint_angles(scene.link_orientations_deg())[link - 1])
            if abs(delta) <= CORRECTION_DEG or turn_hazard(scene, link, link - 1, delta,
                                                           hazards=SWEEP_HAZARDS) is not None:
                continue
            move = HumanMove(link, link - 1, delta, f"human put l{link} right ({delta:+.0f} deg at its joint)")
            human.start(move)
            human.finish()
            labels.append(move.label)
    return labels


# -- the human's body: two hands that grasp and turn links on the physics clock --------------------------------
REST_XY = ((1.05, 0.25), (1.05, -0.25))  # where the hands wait, beyond the table's far edge
HAND_SPEED_M_S = 1.2
TURN_SPEED_DEG_S = 90.0  # the fastest a hand turns a link, half-way through a turn (`eased`)
HAND_FORCE_N = 30.0  # a firm human grip, weaker than the robot's


@dataclass(frozen=True)
class HumanMove:
    """Turn `turned` about its joint with `held` (0 = the table) by `delta_deg`; `label` says it in words."""

    turned: int
    held: int
    delta_deg: float
    label: str


class Human:
    """A visible human with two hands (forearm and hand boxes). A move is acted out on the physics clock as a
    ticker of the scene: the hands travel to the links, the holding hand fixes the link that stays (unless the
    robot already holds it), the turning hand grips the turned link once it touches it and carries it along
    the arc about the joint, then both let go and go back. Moves queue; `finish` steps the scene until the
    human is idle (the robot waiting)."""

    def __init__(self, scene: Scene) -> None:
        self.scene = scene
        c = scene.client
        self.hands: list[int] = []
        for xy in REST_XY:
            visual = c.createVisualShapeArray(
                shapeTypes=[pybullet.GEOM_BOX, pybullet.GEOM_BOX],
                halfExtents=[[0.045, 0.035, 0.015], [0.14, 0.03, 0.03]],
                visualFramePositions=[[0.0, 0.0, 0.0], [0.18, 0.0, 0.04]],  # the forearm reaches back to the human
                rgbaColors=[[0.87, 0.68, 0.55, 1], [0.55, 0.42, 0.62, 1]],
            )
            body = c.createMultiBody(baseMass=0, baseCollisionShapeIndex=-1, baseVisualShapeIndex=visual,
                                     basePosition=[xy[0], xy[1], scene.spec.table_top_z + 0.15])
            self.hands.append(body)
        self.queue: list[HumanMove] = []
        self.done: list[str] = []
        self._phase: Callable[[], bool] | None = None
        self._grips: list[int] = []
        scene.add_ticker(self._tick)

    @property
    def idle(self) -> bool:
        return self._phase is None and not self.queue

    def start(self, move: HumanMove) -> None:
        self.queue.append(move)

    def finish(self, max_steps: int = 2000) -> None:
        """Step the physics until every queued move is done (the robot waits)."""
        for _ in range(max_steps):
            if self.idle:
                return
            self.scene.step()
        log.warning("human: a move did not finish within %d steps", max_steps)

    def close(self) -> None:
        self.scene.remove_ticker(self._tick)

    # -- acting ------------------------------------------------------------------------------------------------
    def _tick(self, scene: Scene) -> None:
        if self._phase is None and self.queue:
            self._phase = self._plan(self.queue.pop(0))
        if self._phase is not None and self._phase():
            self._phase = None

    def _place(self, hand: int, xy: np.ndarray, z: float, theta_deg: float) -> None:
        quat = self.scene.client.getQuaternionFromEuler([0.0, 0.0, -math.radians(theta_deg)])
        self.scene.client.resetBasePositionAndOrientation(hand, [float(xy[0]), float(xy[1]), z], quat)

    def _plan(self, move: HumanMove) -> Callable[[], bool]:
        """A generator of per-tick actions for one move, wrapped as a callable returning True when done."""
        steps = self._acting(move)

        def advance() -> bool:
            try:
                next(steps)
                return False
            except StopIteration:
                return True

        return advance

    def _acting(self, move: HumanMove) -> Iterator[None]:
        s, c = self.scene, self.scene.client
        dt = TIME_STEP_S
        z_grip = s.link_center_z + s.spec.link_height_m
        z_high = s.spec.table_top_z + 0.15
        hold_hand, turn_hand = self.hands
        holds = move.held >= 1 and move.held not in s.gripped  # the robot may hold it already
        # turning l1 about its point on the table: the other hand holds that point down, or the chain dragged
        # along by l1 slides it (4.6 cm over a help request's turns of l1, in a random episode)
        pins = move.held == 0 and 1 not in s.gripped

        def hands_to(targets: list[tuple[int, HandTarget]]) -> Iterator[None]:
            starts = {h: np.asarray(c.getBasePositionAndOrientation(h)[0]) for h, _ in targets}
            goal = {h: f() for h, f in targets}
            distance = max(float(np.linalg.norm(np.append(goal[h][0], goal[h][1]) - starts[h])) for h, _ in targets)
            n = max(2, int(distance / (HAND_SPEED_M_S * dt)))
            for i in range(1, n + 1):
                for h, f in targets:
                    xy, z, theta = f()
                    p = starts[h] + (np.append(xy, z) - starts[h]) * (i / n)
                    self._place(h, p[:2], float(p[2]), theta)
                yield

        def over(link: int, z: float) -> HandTarget:
            return lambda: (s.link_center(link), z, s.link_orientations_deg()[link - 1])

        def rest(i: int) -> HandTarget:
            return lambda: (np.asarray(REST_XY[i]), z_high, 0.0)

        def at_base(z: float) -> HandTarget:
            return lambda: (s.joint_points()[0], z, s.link_orientations_deg()[0])

        def holding(z: float) -> list[tuple[int, HandTarget]]:
            return [(hold_hand, over(move.held, z))] if holds else [(hold_hand, at_base(z))] if pins else []

        yield from hands_to([(turn_hand, over(move.turned, z_high))] + holding(z_high))
        yield from hands_to([(turn_hand, over(move.turned, z_grip))] + holding(z_grip))
        # grip: a constraint from the world to each link the hands now touch
        grips = {}

        def grip(hand: int, link: int) -> None:
            position, quat = s.link_pose(link)
            hand_position = np.asarray(c.getBasePositionAndOrientation(hand)[0])
            if float(np.linalg.norm(hand_position[:2] - position[:2])) > 0.03:
                log.info("human: the hand missed link %d", link)
                return
            cid = c.createConstraint(s.body, s.object_link_index(link), -1, -1, pybullet.JOINT_FIXED, [0, 0, 0],
                                     [0, 0, 0], position.tolist(), [0, 0, 0, 1], quat)
            c.changeConstraint(cid, maxForce=HAND_FORCE_N)
            grips[hand] = (cid, link)
            self._grips.append(cid)

        grip(turn_hand, move.turned)
        if holds:
            grip(hold_hand, move.held)
        if pins and turn_hand in grips:  # the holding hand presses p1 onto the table: l1 turns about it
            p1 = s.joint_points()[0]
            cid = c.createConstraint(s.body, -1, -1, -1, pybullet.JOINT_POINT2POINT, [0, 0, 0],
                                     [-s.spec.link_length_m / 2.0, 0.0, 0.0], [float(p1[0]), float(p1[1]), s.link_center_z])
            c.changeConstraint(cid, maxForce=HAND_FORCE_N)
            self._grips.append(cid)
        if turn_hand in grips:
            cid = grips[turn_hand][0]
            theta0 = s.link_orientations_deg()
            reference0 = theta0[move.held - 1] if move.held >= 1 else 0.0
            relative0 = theta0[move.turned - 1] - reference0
            pivot0 = s.joint_points()[max(move.turned, move.held) - 1] if move.held == 0 else None
            n = max(2, int(math.pi / 2 * abs(move.delta_deg) / (TURN_SPEED_DEG_S * dt)))  # peak speed: TURN_SPEED
            half = s.spec.link_length_m / 2.0
            for i in range(1, n + 1):
                theta = s.link_orientations_deg()
                reference = theta[move.held - 1] if move.held >= 1 else 0.0
                wanted = reference + relative0 + move.delta_deg * eased(i / n)
                if move.held == 0:
                    assert pivot0 is not None  # set above whenever the table is held
                    pivot = pivot0
                else:
                    held_centre = s.link_center(move.held)
                    sign = 1.0 if move.turned > move.held else -1.0  # the joint at the held link's far or near end
                    pivot = held_centre + sign * half * direction(reference)
                sign = 1.0 if move.turned > move.held else -1.0
                centre = pivot + sign * half * direction(wanted)
                quat = c.getQuaternionFromEuler([0.0, 0.0, -math.radians(wanted)])
                c.changeConstraint(cid, [float(centre[0]), float(centre[1]), s.link_center_z], quat, maxForce=HAND_FORCE_N)
                self._place(turn_hand, centre, z_grip, wanted)
                if move.held >= 1 and hold_hand not in grips and move.held not in s.gripped:
                    # the robot let go of the link that should stay: the other hand takes it
                    self._place(hold_hand, s.link_center(move.held), z_grip, reference)
                    grip(hold_hand, move.held)
                if hold_hand in grips:
                    self._place(hold_hand, s.link_center(move.held), z_grip, s.link_orientations_deg()[move.held - 1])
                yield
            for _ in range(6):
                yield  # let the object settle under the hands
        for cid in self._grips:
            c.removeConstraint(cid)
        self._grips = []
        self.done.append(move.label)
        yield from hands_to([(turn_hand, rest(1)), (hold_hand, rest(0))])
