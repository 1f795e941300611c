"""The robot worker: perceive -> report to the KB service -> execute the next action -> report the outcome.

Each cycle (a "step") the simulated human may act first (`before` events), the worker perceives the object
and posts the perception; the service's decision says whether the goal is reached or which action comes next.
The worker asks for that action (which dispatches it), runs the rotation skill physically — the human, a
visible body, may start acting half-way (`during` events) and goes on in parallel on the physics clock; the
turning gripper may lose its grasp part-way (faults) — and posts the outcome judged from the world, with its
reason and a sentence. In camera mode a link the head camera does not see is posted as unseen (null); the
simulator's truth is recorded only for evaluation (`true_deg`). A failed action is not retried the same way:
a macro step is split into single steps; a single step that failed again is handed to the human when the
scenario has one who helps (when the human finds no safe way either, the failure is reported and the service
decides anew, at most three times in a row), else the worker gives up and says so in the action's feedback.

Everything is recorded in `out_dir`: `summary.json` (decisions, actions, outcomes, timings), one camera frame
per perception (`frame_NNN.png`), `run.gif`, and `configurations.png` (top views of each successive
configuration, like the paper's Figs 10-12). The worker owns its PyBullet client; only `planhrc.client`
talks HTTP.
"""
from __future__ import annotations

import argparse
import json
import logging
import math
import os
import re
import sys
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
import pybullet
from pybullet_utils.bullet_client import BulletClient

from planhrc.cli_args import (SubParsers, float_tuple, http_url, non_negative_float, non_negative_int, positive_int,
                              writable_dir)
from planhrc.client import KBClient, ProtocolError
from planhrc.robot_sim.human import (Human, HumanContext, RobotTurn, apply_event, assist_failed_action,
                                     goal_differences, help_turns, safe_way)
from planhrc.robot_sim.perception import CameraPerception, FallbackPerception, Perceiver, Perception
from planhrc.robot_sim.pictures import (PictureStep, actor_between, caption_frame, describe_action, detect_markers,
                                       draw_configurations, step_caption, write_movie)
from planhrc.robot_sim.scenarios import HumanEvent, Scenario, get_scenario
from planhrc.robot_sim.errors import SimError
from planhrc.robot_sim.scene import Scene, SceneSpec, build_scene, turn_hazard
from planhrc.robot_sim.service_link import ServiceLink
from planhrc.robot_sim.acting import measured_pose, perform_parts, perform_skill, way_round
from planhrc.robot_sim.skills import Robot, RotationAction
from planhrc.vocabulary import ActionOutcome, DecisionKind, FailureReason, GiveUpReason, StopReason

log = logging.getLogger(__name__)


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


@dataclass
class _Run:
    """Mutable bookkeeping of one run (kept private to this module)."""

    records: list[StepRecord] = field(default_factory=list)
    frames: list[np.ndarray] = field(default_factory=list)  # one per perception (saved as PNG)
    # perceptions plus one frame half-way through each action: (step, "perceived" or "moving", frame)
    movie: list[tuple[int, str, np.ndarray]] = field(default_factory=list)
    configurations: list[tuple[float, ...]] = field(default_factory=list)
    base_points: list[tuple[float, float]] = field(default_factory=list)
    labels: list[str] = field(default_factory=list)
    applied: set[int] = field(default_factory=set)  # indices of scenario events already performed
    performed: int = 0  # scenario events the human actually carried out
    stop_message: str = ""
    final_help: tuple[str, ...] = ()  # the help request the last give-up became


def _joint_index(name: str) -> int:
    match = re.search(r"_j(\d+)$", name)
    if not match:
        raise ProtocolError(f"joint_values_deg: cannot read a joint index from {name!r}")
    return int(match.group(1))


def _read_goal_differences(kb: ServiceLink, obj: dict[str, Any]) -> dict[int, float]:
    """The goal as link K -> wanted theta_K - theta_(K-1), read from the service (empty when unknown)."""
    state_id = obj.get("goal_state_id")
    if not state_id:
        return {}
    try:
        state = kb.read_state(state_id)
    except ProtocolError as exc:
        log.warning("goal: cannot read state %s (%s); 'toward_goal' events will do nothing", state_id, exc)
        return {}
    values = {_joint_index(name): v for name, v in (state.get("joint_values_deg") or {}).items()}
    return goal_differences(str(obj.get("formulation", "relative")), values)


def _following_action(kb: ServiceLink, action: dict[str, Any]) -> tuple[int, int, float] | None:
    """(turned, held, delta) of the plan's action after `action`, or None."""
    plan_id, step = action.get("plan_id"), action.get("step")
    if not plan_id or step is None:
        return None
    try:
        plan = kb.read_plan(str(plan_id))
    except ProtocolError as exc:
        log.warning("plan %s: cannot read it (%s)", plan_id, exc)
        return None
    last = int(action.get("last_step") or step)
    for entry in plan.get("steps", []):
        if entry.get("step") == last + 1:
            return int(entry["turned_link_index"]), int(entry["held_link_index"]), float(entry["delta_deg"])
    return None


def _perceive(perceiver: Perceiver) -> Perception:
    """Look (the camera looks again with the head turned while markers are missing). An unseen link stays
    unseen: nothing fills it in."""
    seen = perceiver.look()
    if not seen.complete:
        log.warning("perception: links %s not seen", seen.missing_links)
    return seen


def run_worker(
    kb_url: str,
    object_id: str,
    scene_spec: SceneSpec | None = None,
    human_scenario: Scenario | str = "none",
    out_dir: str | Path = "worker-out",
    gui: bool = False,
    max_steps: int = 30,
    token: str | None = None,
    perception: str = "camera",
    goal_link_orientations_deg: Sequence[float] | None = None,
    sigma_deg: float = 1.0,
    seed: int = 0,
    kb: ServiceLink | None = None,
    record_motion: bool = True,
    record_frames: bool = True,
) -> WorkerSummary:
    """Run the cooperation loop against the KB service until the goal is reached, or it cannot go on.

    `record_frames=False` skips the camera frames and the GIF when perceiving without the camera (faster);
    `record_motion=False` leaves out the GIF's frames taken half-way through each action. `kb` is the link to
    the service (default: a `KBClient` on `kb_url`; the ROS 2 layer passes its link through the bridge's topics).
    """
    if perception not in ("camera", "fallback"):
        raise SimError(f"perception: must be 'camera' or 'fallback', got {perception!r}")
    start = time.perf_counter()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    own_kb = kb is None
    kb = kb if kb is not None else KBClient(kb_url, token=token)
    client = BulletClient(connection_mode=pybullet.GUI if gui else pybullet.DIRECT)
    scene: Scene | None = None
    try:
        if goal_link_orientations_deg is not None:
            kb.set_goal(object_id, link_orientations_deg=list(goal_link_orientations_deg))
        obj = kb.read_object(object_id)
        links = obj.get("links") or []
        spec = scene_spec or SceneSpec(n_links=len(links), link_length_m=float(links[0]["length_m"]))
        if spec.n_links != len(links):
            raise SimError(f"scene_spec.n_links: {spec.n_links}, but object {object_id} has {len(links)} links")
        scenario = human_scenario if isinstance(human_scenario, Scenario) else get_scenario(human_scenario, spec.n_links)
        scene = build_scene(client, spec)
        robot = Robot(scene, realtime_s=0.01 if gui else 0.0)
        camera = CameraPerception(client, scene)
        perceiver = camera if perception == "camera" else FallbackPerception(scene, sigma_deg=sigma_deg, seed=seed)
        human = Human(scene)
        context = HumanContext(step_deg=float(obj.get("step_deg") or 360 / int(obj["orientations"])),
                               goal_differences=_read_goal_differences(kb, obj))
        run = _Run()
        summary_reason = _loop(kb, object_id, scene, robot, camera, perceiver, human, scenario, context,
                               max_steps, run, record_motion=record_motion and record_frames,
                               record_frames=record_frames)
        reached = summary_reason is StopReason.GOAL_REACHED
        summary = WorkerSummary(
            object_id=object_id,
            scenario=scenario.name,
            reached_goal=reached,
            stop_reason=summary_reason,
            steps=tuple(run.records),
            configurations=tuple(run.configurations),
            base_points=tuple(run.base_points),
            out_dir=str(out),
            wall_s=time.perf_counter() - start,
            perception=perception,
            stop_message=run.stop_message,
            human_scheduled=len(scenario.events),
            human_performed=run.performed,
            final_help=run.final_help,
        )
        _save(out, summary, run, spec, goal_link_orientations_deg)
        return summary
    finally:
        if scene is not None:
            scene.close()
        client.disconnect()
        if isinstance(kb, KBClient) and own_kb:
            kb.close()


def _events(scenario: Scenario, run: _Run, step: int, when: str) -> list[tuple[int, HumanEvent]]:
    return [(i, e) for i, e in enumerate(scenario.events) if e.at_step == step and e.when == when and i not in run.applied]


def _act(human: Human, run: _Run, index: int, event: HumanEvent, context: HumanContext) -> str | None:
    run.applied.add(index)
    done = apply_event(human, event, context)
    if done is not None:
        run.performed += 1
    return done


def _signature(action: RotationAction) -> tuple[int, int, float, int]:
    return action.turned_link, action.held_link, round(action.delta_deg, 3), action.macro_steps


def _loop(kb: ServiceLink, object_id: str, scene: Scene, robot: Robot, camera: CameraPerception, perceiver: Perceiver,
          human: Human, scenario: Scenario, context: HumanContext, max_steps: int, run: _Run,
          record_motion: bool = True, record_frames: bool = True, max_unseen: int = 3) -> StopReason:
    """Perceive -> decide -> act until the goal; returns why it stopped.

    A failed action is not tried again the same way: a macro step that failed is split into its single steps;
    a single step that failed and comes again is done by the human when the scenario says the human helps (when
    the human cannot do it safely either, the failure is reported and the next perception decides; the third
    time in a row the worker gives up), else the worker gives up, and says so to the service in the feedback of
    that action."""
    step = 1
    unseen_in_a_row = 0
    helpless = 0  # help requests (or failed actions) in a row the human could do nothing about
    carried: list[str] = []  # human moves made while the robot idled at the goal, reported with the next step
    # signature of a failed action -> (its sentence, whether it was also tried in single steps)
    failed: dict[tuple[int, int, float, int], tuple[str, bool, FailureReason | None]] = {}
    while step <= max_steps:
        human_before, carried = carried, []
        for index, event in _events(scenario, run, step, "before"):
            if (done := _act(human, run, index, event, context)) is not None:
                human_before.append(done)
            human.finish()  # the robot waits until the human has let go; the next move starts from there

        t0 = time.perf_counter()
        seen = _perceive(perceiver)
        t1 = time.perf_counter()
        values = seen.link_orientations_deg
        # nothing seen at all says nothing the service could store: it is an incomplete perception here
        decision = (kb.post_perception(object_id, values, seen.base_point_xy)
                    if any(v is not None for v in values) else None)
        t2 = time.perf_counter()
        frame = seen.frame if seen.frame is not None or not record_frames else camera.render()
        if frame is not None:
            run.frames.append(frame)
            run.movie.append((step, "perceived", frame))
        base_xy, theta = scene.configuration()
        run.configurations.append(tuple(round(v, 3) for v in theta))
        run.base_points.append(base_xy)
        kind = DecisionKind.INCOMPLETE_PERCEPTION if decision is None else decision.decision
        run.labels.append(f"{step}: {kind}")
        base: dict[str, Any] = dict(step=step, human_before=tuple(human_before),
                    perceived_deg=tuple(None if v is None else round(v, 2) for v in values),
                    true_deg=tuple(round(v, 2) for v in theta), missing_links=seen.missing_links,
                    decision=kind, reason="no link seen (not posted)" if decision is None else decision.reason,
                    looks=seen.looks, matched_expected_step=None if decision is None else decision.matched_expected_step,
                    perception_s=t1 - t0, service_s=t2 - t1)
        if decision is None or decision.decision is DecisionKind.INCOMPLETE_PERCEPTION:
            # the head has turned to look again already; nothing is filled in from elsewhere
            unseen_in_a_row += 1
            run.records.append(StepRecord(**base))
            if unseen_in_a_row >= max_unseen:
                run.stop_message = f"links {list(seen.missing_links)} not seen in {max_unseen} perceptions"
                _give_up(kb, object_id, GiveUpReason.UNSEEN_LINKS, run.stop_message, run)
                return StopReason.UNSEEN_LINKS
            scene.step(30)  # a quarter of a second: whatever covers a marker may move away
            step += 1
            continue
        unseen_in_a_row = 0
        log.info("step %d: %s (%s)", step, decision.decision, decision.reason)

        if decision.decision is DecisionKind.HUMAN_HELP_REQUESTED:
            requests = tuple(str(item.get("sentence") or f"turn link {item.get('link')} to {item.get('to_deg')} deg")
                             for item in decision.help or ())
            if scenario.assists_after_failures is None:
                run.records.append(StepRecord(**base, help_requested=requests))
                run.stop_message = f"the robot asked for help and no human helps: {decision.reason}"
                _give_up(kb, object_id, GiveUpReason.NO_HUMAN_HELP, run.stop_message, run)
                return StopReason.NO_HUMAN_HELP
            helped = help_turns(human, [(int(item["link"]), float(item["to_deg"])) for item in decision.help or ()])
            run.records.append(StepRecord(**base, help_requested=requests, human_assist="; ".join(helped or ()) or None))
            helpless = 0 if helped else helpless + 1
            if helpless >= max_unseen:
                run.stop_message = f"the human could not do what was asked ({'; '.join(requests)})"
                _give_up(kb, object_id, GiveUpReason.HUMAN_COULD_NOT_HELP, run.stop_message, run)
                return StopReason.GAVE_UP
            step += 1
            continue

        if decision.decision is DecisionKind.ROBOT_SKILL:
            t3 = time.perf_counter()
            done = perform_skill(scene, robot, decision.skill or {})
            run.records.append(StepRecord(**base, skill=done, action_s=time.perf_counter() - t3))
            step += 1
            continue

        if decision.decision is DecisionKind.GOAL_REACHED:
            run.records.append(StepRecord(**base))
            # a move due now or earlier that found no robot action to go with happens now, while the robot idles
            late = [(i, e) for i, e in enumerate(scenario.events) if i not in run.applied and e.at_step <= step]
            pending = [e for i, e in enumerate(scenario.events) if i not in run.applied and e.at_step > step]
            if not late and not pending:
                return StopReason.GOAL_REACHED
            for index, event in late:
                if (done := _act(human, run, index, event, context)) is not None:
                    carried.append(done)
            # the robot is idle: the next scheduled human intervention happens now
            step = step + 1 if late else max(step + 1, min(e.at_step for e in pending))
            continue
        if decision.decision is DecisionKind.NO_PLAN:
            # never a silent stop: the service turns the give-up into a help request, which a human may do
            run.stop_message = decision.reason
            asked = _give_up(kb, object_id, GiveUpReason.NO_PLAN, decision.reason, run)
            if scenario.assists_after_failures is not None and asked and helpless + 1 < max_unseen:
                helped = help_turns(human, [(int(item["link"]), float(item["to_deg"])) for item in asked])
                run.records.append(StepRecord(**base, help_requested=run.final_help,
                                              human_assist="; ".join(helped or ()) or None))
                run.final_help, run.stop_message = (), ""
                helpless = 0 if helped else helpless + 1
                step += 1
                continue
            run.records.append(StepRecord(**base, help_requested=run.final_help))
            return StopReason.NO_PLAN

        data = kb.next_action(object_id)
        if data is None:
            run.records.append(StepRecord(**base))
            run.stop_message = "the service dispatched no action"
            _give_up(kb, object_id, GiveUpReason.NO_ACTION, run.stop_message, run)
            return StopReason.NO_ACTION
        action = RotationAction.from_api(data)
        context.busy_links = (action.turned_link, action.held_link)
        during_events = _events(scenario, run, step, "during")
        if any(e.kind == "next_planned" for _, e in during_events):
            context.next_planned = _following_action(kb, data)
        human_during: list[str] = []

        def interrupt(done: int, total: int) -> bool:
            if done == total // 2 and record_motion:
                run.movie.append((step, "moving", camera.render()))  # the arms at work
            if during_events and done >= total / 2:
                while during_events:  # the human starts now and acts while the robot goes on
                    index, event = during_events.pop(0)
                    if (what := _act(human, run, index, event, context)) is not None:
                        human_during.append(what)
            return False

        signature = _signature(action)
        fault = scenario.fault_at(step)
        t3 = time.perf_counter()
        assist = None
        previous = failed.get(signature)
        # the one judge's pose: the one posted with the perception, from which the service judged this motion
        pose = measured_pose(scene, values, seen.base_point_xy)
        final = bool(data.get("ends_plan", True))  # an older service does not say: judged as drawn at rest
        if previous is None:
            parts: tuple[RotationAction, ...] | None = (way_round(pose, scene.spec.cell(), action, final),)
        elif action.macro_steps > 1 and not previous[1]:
            # the macro motion failed: try its single steps
            parts = way_round(pose, scene.spec.cell(), action, final).split()
        else:
            parts = None  # tried every way the robot knows: not again
        if parts is not None:  # a human acting meanwhile takes the robot's whole rotation into account
            context.robot_turn = RobotTurn(action.turned_link, action.held_link, sum(p.delta_deg for p in parts),
                                           base_xy, tuple(theta))
        result = None if parts is None else perform_parts(scene, robot, pose, parts, final, interrupt,
                                                            fault.stop_fraction if fault else None)
        t4 = time.perf_counter()
        while during_events:  # the robot stopped before half-way: the human acts anyway
            index, event = during_events.pop(0)
            if (what := _act(human, run, index, event, context)) is not None:
                human_during.append(what)
        human.finish()
        context.busy_links, context.robot_turn = (), None
        if result is None:
            # the same single step failed before: do not try it the same way again
            sentence = failed[signature][0]
            if scenario.assists_after_failures is not None:
                # the paper: when the robot cannot do an action, the human does it on the robot's behalf
                assist = assist_failed_action(human, action.turned_link, action.held_link, action.delta_deg)
                if assist is None:
                    sentence = f"{sentence}; the human could not do it safely either"
            if assist is not None:
                message = f"robot did not retry ({sentence}); the human did it"
                reason = failed[signature][2]
                if action.action_id is not None:
                    _feedback(kb, object_id, action.action_id, ActionOutcome.FAILED, message, reason)
                failed.pop(signature)
                run.records.append(StepRecord(**base, action=dict(data), outcome=ActionOutcome.FAILED,
                                              outcome_reason=reason,
                                              outcome_message=message, human_during=tuple(human_during),
                                              human_assist=assist, action_s=t4 - t3))
                helpless = 0
                step += 1
                continue
            if scenario.assists_after_failures is not None and helpless + 1 < max_unseen:
                # the object may have changed since (a human's move): say so and let the service decide anew
                helpless += 1
                message = f"robot did not retry ({sentence})"
                reason = failed[signature][2]
                if action.action_id is not None:
                    _feedback(kb, object_id, action.action_id, ActionOutcome.FAILED, message, reason)
                run.records.append(StepRecord(**base, action=dict(data), outcome=ActionOutcome.FAILED,
                                              outcome_reason=reason,
                                              outcome_message=message, human_during=tuple(human_during),
                                              action_s=t4 - t3))
                step += 1
                continue
            run.stop_message = f"gave up on {action.name or 'the action'}: {sentence}"
            if action.action_id is not None:
                _feedback(kb, object_id, action.action_id, ActionOutcome.FAILED, f"worker gives up: {sentence}",
                          failed[signature][2])
            _give_up(kb, object_id, GiveUpReason.REPEATED_FAILURE, run.stop_message, run)
            run.records.append(StepRecord(**base, action=dict(data), outcome=ActionOutcome.FAILED,
                                          outcome_message=run.stop_message, human_during=tuple(human_during),
                                          action_s=t4 - t3))
            return StopReason.GAVE_UP
        if result.outcome is ActionOutcome.PARTIAL:
            context.partial = (action.turned_link, action.held_link, result.commanded_deg - result.reached_deg)
        message = result.message if result.reason is None else f"{result.reason.value}: {result.message}"
        measured = None
        if result.outcome is not ActionOutcome.SUCCEEDED:
            # where the turned link ended, as the robot sees it (the camera looks again; unseen stays None)
            again = perceiver.look()
            measured = again.link_orientations_deg[action.turned_link - 1]
        if action.action_id is not None:
            _feedback(kb, object_id, action.action_id, result.outcome, message, result.reason, measured,
                      result.refusal)
        if result.outcome is ActionOutcome.SUCCEEDED:
            failed.pop(signature, None)
        elif result.reason is not None:
            failed[signature] = (result.message, len(parts or ()) > 1 or action.macro_steps <= 1, result.reason)
        run.records.append(StepRecord(**base, action=dict(data), outcome=result.outcome,
                                      outcome_reason=result.reason,
                                      measured_deg=None if measured is None else round(measured, 2),
                                      outcome_message=result.message, reached_deg=round(result.reached_deg, 2),
                                      human_during=tuple(human_during), human_assist=assist, action_s=t4 - t3))
        log.info("step %d: %s -> %s (%s)", step, action, result.outcome.value, result.message)
        step += 1
    run.stop_message = f"the goal was not reached in {max_steps} steps"
    _give_up(kb, object_id, GiveUpReason.MAX_STEPS, run.stop_message, run)
    return StopReason.MAX_STEPS


def _feedback(kb: ServiceLink, object_id: str, action_id: str, outcome: ActionOutcome, message: str,
              reason: FailureReason | None = None, measured_deg: float | None = None,
              refusal: Mapping[str, Any] | None = None) -> None:
    """Post an action's outcome with its sentence and, for a failed or partial one, its reason and the turned
    link's measured orientation; for a turn not started, the geometric fact (`refusal`)."""
    if outcome is ActionOutcome.SUCCEEDED:
        reason, measured_deg, refusal = None, None, None
    if refusal is not None:
        kb.post_feedback(object_id, action_id, outcome.value, message, reason=reason, measured_deg=measured_deg,
                         refusal=dict(refusal))
    else:
        kb.post_feedback(object_id, action_id, outcome.value, message, reason=reason, measured_deg=measured_deg)


def _give_up(kb: ServiceLink, object_id: str, reason: GiveUpReason, message: str, run: _Run) -> list[dict[str, Any]]:
    """Tell the service the worker stops (it records the reason and dispatches nothing until a perception); the
    service answers with the help request the stop became, kept in the run's record (`final_help`)."""
    log.warning("giving up on %s: %s", object_id, message)
    answer = kb.give_up(object_id, reason, message[:500])
    asked = list(answer.get("help") or [])
    run.final_help = tuple(str(item.get("sentence")) for item in asked)
    if not asked and answer.get("decision") == DecisionKind.HUMAN_HELP_REQUESTED:
        run.final_help = (str(answer.get("reason")),)  # nothing seen to name links by: the object as a whole
    return asked


# -- records ---------------------------------------------------------------------------------------------
def _save(out: Path, summary: WorkerSummary, run: _Run, spec: SceneSpec,
          goal_deg: Sequence[float] | None = None) -> None:
    from PIL import Image

    data = asdict(summary)
    data["decisions"] = list(summary.decisions)
    data["outcomes"] = list(summary.outcomes)
    data["seen_links"] = summary.seen_links
    data["unseen_links"] = summary.unseen_links
    data["failure_reasons"] = summary.failure_reasons
    (out / "summary.json").write_text(json.dumps(data, indent=2, default=str))
    steps = picture_steps(run.records, run.configurations, run.base_points)
    by_step = {s.step: s for s in steps}
    markers = [detect_markers(frame) for frame in run.frames]
    if len(markers) == len(steps):  # what the pictures draw on each frame is what they report
        steps = [replace(s, markers_seen=len(m)) for s, m in zip(steps, markers)]
        by_step = {s.step: s for s in steps}
    for i, frame in enumerate(run.frames):
        lines = step_caption(steps[i], spec.n_links) if i < len(steps) else [f"perception {i + 1}"]
        Image.fromarray(caption_frame(frame, lines, markers=markers[i])).save(out / f"frame_{i:03d}.png")
    movie, perceived = [], 0
    for step, kind, frame in run.movie:
        s = by_step.get(step)
        if kind == "perceived":
            lines = step_caption(s, spec.n_links) if s else [f"step {step}"]
            seen = markers[perceived] if perceived < len(markers) else None
            perceived += 1
        else:
            lines = [f"step {step}   robot at work", f"{s.action if s else 'action'}", ""]
            seen = None
        movie.append(caption_frame(frame, lines, width=480, markers=seen))
    write_movie(out / "run.gif", movie)
    if steps:
        draw_configurations(out / "configurations.png", steps, spec.link_length_m, goal_deg,
                            title=f"{summary.object_id}, scenario {summary.scenario}: {summary.stop_reason}")


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


# -- command line ----------------------------------------------------------------------------------------
def display_problem() -> str | None:
    """Why PyBullet's GUI cannot open here, or None. On Linux it needs an X display, and without one it ends the
    whole process from native code (no cleanup), so the display is tried first, as PyBullet will."""
    if not sys.platform.startswith("linux"):
        return None
    display = os.environ.get("DISPLAY")
    if not display:
        return "no display (DISPLAY is not set); run without --gui"
    import ctypes
    import ctypes.util

    name = ctypes.util.find_library("X11")
    if name is None:
        return "libX11 is not installed; run without --gui"
    xlib = ctypes.CDLL(name)
    xlib.XOpenDisplay.restype = ctypes.c_void_p
    xlib.XOpenDisplay.argtypes = [ctypes.c_char_p]
    handle = xlib.XOpenDisplay(display.encode())
    if not handle:
        return f"cannot connect to the X display {display!r}; run without --gui"
    xlib.XCloseDisplay.argtypes = [ctypes.c_void_p]
    xlib.XCloseDisplay(handle)
    return None


def add_worker_parser(subparsers: SubParsers) -> argparse.ArgumentParser:
    p = subparsers.add_parser("worker", help="run the simulated Baxter worker against the KB service",
                              description="Perceive, ask the KB service for actions and execute them in PyBullet.")
    p.add_argument("--kb", type=http_url, default=None,
                   help="base URL of the KB service, e.g. http://127.0.0.1:8000 (required unless --ros2)")
    p.add_argument("--ros2", action="store_true",
                   help="talk to the service over ROS 2, through the topics of a running `planhrc ros2-bridge`")
    p.add_argument("--object", required=True, dest="object_id", help="object id in the KB service")
    p.add_argument("--gui", action="store_true", help="show the PyBullet GUI")
    p.add_argument("--token", default=None, help="bearer token for the service's writes")
    p.add_argument("--perception", choices=("camera", "fallback"), default="camera")
    p.add_argument("--scenario", default="none", help="human scenario: none, fig13, fig14 or random:SEED:N")
    p.add_argument("--out", type=writable_dir, default="worker-out", help="folder for frames, GIF, configurations.png, summary.json")
    p.add_argument("--max-steps", type=positive_int, default=30)
    p.add_argument("--initial", type=float_tuple, default=None,
                   help="initial link orientations, e.g. 90,90,90,90,90")
    p.add_argument("--base", type=float_tuple, default=None, help="base point x,y of the object on the table (m)")
    p.add_argument("--goal", type=float_tuple, default=None, help="goal link orientations to PUT before starting")
    p.add_argument("--sigma", type=non_negative_float, default=1.0, help="noise (deg) of the fallback perception")
    p.add_argument("--seed", type=non_negative_int, default=0)
    p.set_defaults(func=run_worker_cli)
    return p


def run_worker_cli(args: argparse.Namespace, link: ServiceLink | None = None) -> int:
    """The worker's command; `link` is given by the ROS 2 layer for `--ros2`."""
    if args.kb is None and not args.ros2:
        print("planhrc worker: --kb: required (or --ros2, through a running ROS 2 bridge)", file=sys.stderr)
        return 2
    if args.ros2 and link is None:
        print("planhrc worker: --ros2: the ROS 2 link is made by `planhrc worker --ros2` in .venv-ros2", file=sys.stderr)
        return 2
    if args.gui and (problem := display_problem()):
        print(f"planhrc worker: --gui: {problem}", file=sys.stderr)
        return 2
    if args.base is not None and len(args.base) != 2:
        print(f"planhrc worker: --base: expected x,y, got {len(args.base)} numbers", file=sys.stderr)
        return 2
    spec = None
    try:
        if args.initial is not None or args.base is not None:
            if link is not None:
                obj = link.read_object(args.object_id)
            else:
                with KBClient(args.kb, token=args.token) as kb:
                    obj = kb.read_object(args.object_id)
            links = obj["links"]
            kwargs: dict[str, Any] = {"n_links": len(links), "link_length_m": float(links[0]["length_m"])}
            if args.initial is not None:
                kwargs["initial_orientations_deg"] = args.initial
            if args.base is not None:
                kwargs["base_point_xy"] = tuple(args.base)
            spec = SceneSpec(**kwargs)
        summary = run_worker(args.kb or "", args.object_id, spec, args.scenario, args.out, args.gui, args.max_steps,
                             args.token, args.perception, args.goal, args.sigma, args.seed, kb=link)
    except (ProtocolError, SimError) as exc:
        print(f"planhrc worker: {exc}", file=sys.stderr)
        return 1
    print(json.dumps({"reached_goal": summary.reached_goal, "stop_reason": summary.stop_reason,
                      "reason": summary.stop_message, "failure_reasons": summary.failure_reasons,
                      "unseen_links": summary.unseen_links,
                      "decisions": list(summary.decisions), "outcomes": list(summary.outcomes),
                      "steps": len(summary.steps), "wall_s": round(summary.wall_s, 2), "out_dir": summary.out_dir}))
    return 0 if summary.reached_goal else 1
