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
A bimanual object's plan is carried out step by step by Baxter's two arms (`robot_sim.bimanual`: the hands move to
the centred joint, grasp, turn, release, and their grasps stay between steps).

Everything is recorded in `out_dir`: `summary.json` (decisions, actions, outcomes, timings), one camera frame
per perception (`frame_NNN.png`), `run.gif`, and `configurations.png` (top views of each successive
configuration, like the paper's Figs 10-12). The worker owns its PyBullet client; only `planhrc.client`
talks HTTP.
"""
from __future__ import annotations

import json
import logging
import re
import time
from dataclasses import asdict, dataclass, field, replace
from functools import partial
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import numpy as np
import pybullet
from pybullet_utils.bullet_client import BulletClient

from planhrc.client import KBClient, ProtocolError
from planhrc.robot_sim.human import (Human, HumanContext, RobotTurn, apply_event, assist_failed_action,
                                     goal_differences, help_turns)
from planhrc.robot_sim.camera import SIM_BOARD
from planhrc.robot_sim.cell_camera import CELL, HEAD, CellCamera, CellCameraSpec, TwoCameras
from planhrc.robot_sim.perception import CameraPerception, FallbackPerception, Perceiver, Perception
from planhrc.robot_sim.sightlines import SightCamera, Sightlines
from planhrc.robot_sim.pictures import caption_frame, detect_markers, draw_configurations, step_caption, write_movie
from planhrc.robot_sim.scenarios import HumanEvent, Scenario, get_scenario
from planhrc.robot_sim.episode import StepRecord, WorkerSummary, picture_steps
from planhrc.robot_sim.recording import EpisodeRecorder, Recording
from planhrc.robot_sim.errors import SimError
from planhrc.robot_sim.scene import Scene, SceneSpec, build_scene
from planhrc.robot_sim.service_link import ServiceLink
from planhrc.robot_sim.acting import measured_pose, perform_parts, perform_skill, way_round
from planhrc.robot_sim.bimanual import HAND_STEPS, RELEASE_LINKS, BothHands, single_steps
from planhrc.robot_sim.skills import Robot, RotationAction
from planhrc.vocabulary import ActionOutcome, DecisionKind, FailureReason, GiveUpReason, StopReason

log = logging.getLogger(__name__)


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
    cell_frames: list[tuple[int, np.ndarray]] = field(default_factory=list)  # (perception, the cell camera's image)


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


def _steps_after(kb: ServiceLink, action: dict[str, Any]) -> list[dict[str, Any]]:
    """The steps of `action`'s plan after it, in order (none when the action names no plan or it cannot be read)."""
    plan_id, step = action.get("plan_id"), action.get("step")
    if not plan_id or step is None:
        return []
    try:
        plan = kb.read_plan(str(plan_id))
    except ProtocolError as exc:
        log.warning("plan %s: cannot read it (%s)", plan_id, exc)
        return []
    last = int(action.get("last_step") or step)
    return sorted((e for e in plan.get("steps", []) if int(e.get("step", 0)) > last), key=lambda e: int(e["step"]))


def _following_action(kb: ServiceLink, action: dict[str, Any]) -> tuple[int, int, float] | None:
    """(turned, held, delta) of the plan's action after `action`, or None (also when that action turns nothing: a
    bimanual plan's centring, grasp or release is no move for a human)."""
    last = int(action.get("last_step") or action.get("step") or 0)
    entry = next(iter(_steps_after(kb, action)), None)
    if entry is None or int(entry["step"]) != last + 1 or not float(entry["delta_deg"]):
        return None
    return int(entry["turned_link_index"]), int(entry["held_link_index"]), float(entry["delta_deg"])


def _held_turn(kb: ServiceLink, action: dict[str, Any]) -> RotationAction | None:
    """The turn a bimanual plan makes with the hands that `action` (a centring or a grasp) puts on its links: the
    turns that follow it there up to the release, as one; None when the plan turns nothing there or cannot be
    read."""
    links = (int(action["turned_link_index"]), int(action["held_link_index"]))
    total, turning = 0.0, False
    for entry in _steps_after(kb, action):
        delta = float(entry.get("delta_deg") or 0.0)
        if (int(entry["turned_link_index"]), int(entry["held_link_index"])) != links or (turning and not delta):
            break
        if delta:
            total, turning = total + delta, True
        elif str(entry.get("name")) == RELEASE_LINKS:
            break
    return RotationAction(links[0], links[1], total, name="held turn") if total else None


def _perceive(perceiver: Perceiver, cameras: TwoCameras | None, run: _Run, ready: Perception | None = None,
              noted: Callable[[Perception], None] | None = None) -> Perception:
    """Look (the head camera, then the cell camera for the links it missed, then the head turned; `TwoCameras`),
    unless the look that ended the last step is `ready` (nothing moved since; `noted` records it as the perceiver
    records its own looks). An unseen link stays unseen: nothing fills it in."""
    if ready is not None and noted is not None:
        noted(ready)
    seen = ready if ready is not None else perceiver.look()
    if cameras is not None and cameras.last_cell_frame is not None:
        run.cell_frames.append((len(run.frames), cameras.last_cell_frame))
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
    recording: Recording | None = None,
    cell_camera: CellCameraSpec | None = CellCameraSpec(),
) -> WorkerSummary:
    """Run the cooperation loop against the KB service until the goal is reached, or it cannot go on.

    `record_frames=False` skips the camera frames and the GIF when perceiving without the camera (faster);
    `record_motion=False` leaves out the GIF's frames taken half-way through each action. `kb` is the link to
    the service (default: a `KBClient` on `kb_url`; the ROS 2 layer passes its link through the bridge's topics).
    `recording` makes the episode's recorder (`--record`: the ROS 2 layer's bag in `out_dir`). `cell_camera` is
    the cell's fixed camera with the camera perception (None: the head camera alone), calibrated from the board
    on the table (`camera.SIM_BOARD`) before the first look; the bimanual grasps then keep the markers in sight.
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
    recorder: EpisodeRecorder | None = None
    summary: WorkerSummary | None = None
    try:
        if goal_link_orientations_deg is not None:
            kb.set_goal(object_id, link_orientations_deg=list(goal_link_orientations_deg))
        obj = kb.read_object(object_id)
        links = obj.get("links") or []
        spec = scene_spec or SceneSpec(n_links=len(links), link_length_m=float(links[0]["length_m"]))
        if spec.n_links != len(links):
            raise SimError(f"scene_spec.n_links: {spec.n_links}, but object {object_id} has {len(links)} links")
        scenario = human_scenario if isinstance(human_scenario, Scenario) else get_scenario(human_scenario, spec.n_links)
        cell_camera = cell_camera if perception == "camera" else None  # without the camera nothing looks
        if cell_camera is not None and spec.board is None:
            spec = replace(spec, board=SIM_BOARD)  # the cell's calibration board lies on the table
        scene = build_scene(client, spec)
        served = kb
        robot = Robot(scene, realtime_s=0.01 if gui else 0.0)
        camera = CameraPerception(client, scene)
        cameras, sight = None, None
        if cell_camera is not None:
            cell = CellCamera(client, scene, cell_camera)
            cell.calibrate()  # once, the arms at home, as a cell's camera is calibrated when it is mounted
            scene.take_board_away()
            cameras = TwoCameras(camera, cell)
            sight = Sightlines(scene, [SightCamera(HEAD, camera.pose, camera.intrinsics),
                                       SightCamera(CELL, cell.pose, cell.intrinsics)])
        eyes: Perceiver = cameras or camera
        perceiver: Perceiver = (eyes if perception == "camera"
                                else FallbackPerception(scene, sigma_deg=sigma_deg, seed=seed))
        noted: Callable[[Perception], None] | None = None
        if recording is not None:
            recorder = recording(out, obj, goal_link_orientations_deg)
            served, perceiver = recorder.link(kb), recorder.perceiver(perceiver, camera)
            noted = partial(recorder.look, camera=camera)
        human = Human(scene)
        # a bimanual plan's grasps stay across its steps: the worker's hands remember them
        # with the cameras, a grasp or a held turn is looked at before it counts (`BothHands`): a grasp that hides
        # a link is taken again elsewhere; the look is the next perception when nothing moves in between (recorded
        # then, as a perception)
        both = (BothHands(scene, robot, sight, look=eyes.look if perception == "camera" else None)
                if obj.get("formulation") == "bimanual" else None)
        context = HumanContext(step_deg=float(obj.get("step_deg") or 360 / int(obj["orientations"])),
                               goal_differences=_read_goal_differences(kb, obj))
        run = _Run()
        summary_reason = _loop(served, object_id, scene, robot, camera, perceiver, human, scenario, context,
                               max_steps, run, record_motion=record_motion and record_frames,
                               record_frames=record_frames, both=both, cameras=cameras, noted=noted)
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
        if recorder is not None:
            recorder.close(summary)
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


def _signature(action: RotationAction) -> tuple[int, int, float, int, str]:
    return action.turned_link, action.held_link, round(action.delta_deg, 3), action.macro_steps, action.name


def _loop(kb: ServiceLink, object_id: str, scene: Scene, robot: Robot, camera: CameraPerception, perceiver: Perceiver,
          human: Human, scenario: Scenario, context: HumanContext, max_steps: int, run: _Run,
          record_motion: bool = True, record_frames: bool = True, max_unseen: int = 3,
          both: BothHands | None = None, cameras: TwoCameras | None = None,
          noted: Callable[[Perception], None] | None = None) -> StopReason:
    """Perceive -> decide -> act until the goal; returns why it stopped.

    A failed action is not tried again the same way: a macro step that failed is split into its single steps;
    a single step that failed and comes again is done by the human when the scenario says the human helps (when
    the human cannot do it safely either, the failure is reported and the next perception decides; the third
    time in a row the worker gives up), else the worker gives up, and says so to the service in the feedback of
    that action. A bimanual object's steps go to `both` (its hands hold across steps); a step that turns nothing
    (centre, grasp, release) is planned anew from where the links lie, so it is tried once more before it counts
    as tried every way, and no human does it for the robot's hands."""
    step = 1
    unseen_in_a_row = 0
    helpless = 0  # help requests (or failed actions) in a row the human could do nothing about
    carried: list[str] = []  # human moves made while the robot idled at the goal, reported with the next step
    # signature of a failed action -> (its sentence, whether it was also tried in single steps)
    failed: dict[tuple[int, int, float, int, str], tuple[str, bool, FailureReason | None]] = {}
    ready: Perception | None = None  # the look that ended the last step, when nothing has moved since
    while step <= max_steps:
        human_before, carried = carried, []
        for index, event in _events(scenario, run, step, "before"):
            if (done := _act(human, run, index, event, context)) is not None:
                human_before.append(done)
            human.finish()  # the robot waits until the human has let go; the next move starts from there

        t0 = time.perf_counter()
        seen = _perceive(perceiver, cameras, run, None if human_before else ready, noted)
        ready = None
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
                    looks=seen.looks, seen_by=seen.sources,
                    matched_expected_step=None if decision is None else decision.matched_expected_step,
                    perception_s=t1 - t0, service_s=t2 - t1)
        if decision is None or decision.decision is DecisionKind.INCOMPLETE_PERCEPTION:
            # the head has turned to look again already; nothing is filled in from elsewhere
            unseen_in_a_row += 1
            run.records.append(StepRecord(**base))
            if unseen_in_a_row >= max_unseen:
                run.stop_message = f"links {list(seen.missing_links)} not seen in {max_unseen} perceptions"
                _give_up(kb, object_id, GiveUpReason.UNSEEN_LINKS, run.stop_message, run)
                return StopReason.UNSEEN_LINKS
            if both is not None and both.step_back():
                log.info("step %d: the open hands step back out of the camera's view", step)
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
            held = both.held_links() if both is not None else ()
            if both is not None and held:
                both.let_go()  # a slide takes its own links: the hands let go first, as the plan has them do
                context.busy_links = ()
            done = perform_skill(scene, robot, decision.skill or {})
            if held:
                done = f"let go of links {' and '.join(map(str, held))}, then {done}"
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
        hand_step = both is not None and action.name in HAND_STEPS
        if previous is None:
            # held links turn only the planned way: the planner, not the worker, answers a refused turn
            parts: tuple[RotationAction, ...] | None = (
                (action,) if both is not None else (way_round(pose, scene.spec.cell(), action, final),))
        elif hand_step and not previous[1]:
            parts = (action,)  # planned anew from where the links lie now: not the same way
        elif action.macro_steps > 1 and not previous[1]:
            # the macro motion failed: try its single steps
            parts = single_steps(action) if both is not None else way_round(pose, scene.spec.cell(), action,
                                                                            final).split()
        else:
            parts = None  # tried every way the robot knows: not again
        if parts is not None and not hand_step:
            # a human acting meanwhile takes the robot's whole rotation into account
            context.robot_turn = RobotTurn(action.turned_link, action.held_link, sum(p.delta_deg for p in parts),
                                           base_xy, tuple(theta))
        stop_fraction = fault.stop_fraction if fault else None
        if parts is None:
            result = None
        elif both is not None:
            then = _held_turn(kb, data) if hand_step and action.name != RELEASE_LINKS and both.sight else None
            result = both.perform(parts, data, pose, final, interrupt, stop_fraction, then)
        else:
            result = perform_parts(scene, robot, pose, parts, final, interrupt, stop_fraction)
        t4 = time.perf_counter()
        ready = both.take_look() if both is not None else None
        while during_events:  # the robot stopped before half-way: the human acts anyway
            index, event = during_events.pop(0)
            if (what := _act(human, run, index, event, context)) is not None:
                human_during.append(what)
        human.finish()
        if human_during:
            ready = None  # a human moved during the step (a move may end after the look): the next perception looks
        # the links still held stay the robot's: a human leaves them alone
        context.busy_links, context.robot_turn = (both.held_links() if both is not None else ()), None
        if result is None:
            # the same single step failed before: do not try it the same way again
            sentence = failed[signature][0]
            if both is not None:  # whatever follows is a failed feedback: the service then counts on open hands
                both.let_go()
                context.busy_links = ()
            if scenario.assists_after_failures is not None and not hand_step:
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
                      result.refusal, result.hands_open)
        if result.outcome is ActionOutcome.SUCCEEDED:
            failed.pop(signature, None)
        elif result.reason is not None:
            tried_all = previous is not None if hand_step else len(parts or ()) > 1 or action.macro_steps <= 1
            failed[signature] = (result.message, tried_all, result.reason)
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
              refusal: Mapping[str, Any] | None = None, hands_open: bool = False) -> None:
    """Post an action's outcome with its sentence and, for a failed or partial one, its reason and the turned
    link's measured orientation; for a turn not started, the geometric fact (`refusal`); `hands_open` when the
    hands let go after a succeeded step."""
    if outcome is ActionOutcome.SUCCEEDED:
        reason, measured_deg, refusal = None, None, None
    extra: dict[str, Any] = {"hands_open": True} if hands_open and outcome is ActionOutcome.SUCCEEDED else {}
    if refusal is not None:
        extra["refusal"] = dict(refusal)
    kb.post_feedback(object_id, action_id, outcome.value, message, reason=reason, measured_deg=measured_deg, **extra)


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
    links = frozenset(range(spec.n_links))  # link K carries marker K-1; the board's markers are not the object's
    markers = [detect_markers(frame, wanted=links) for frame in run.frames]
    for i, frame in run.cell_frames:  # what the cell camera saw when the head camera missed links
        Image.fromarray(caption_frame(frame, [f"perception {i + 1}: the cell camera", "", ""],
                                      markers=detect_markers(frame, wanted=links))).save(out / f"cell_{i:03d}.png")
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
