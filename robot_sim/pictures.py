"""Pictures of an episode that a person can read: the configuration panels, captioned camera frames, the GIF.

Everything here takes plain per-step values (`PictureStep`, numpy frames), not the worker's bookkeeping, so
the drawing does not depend on how the simulation is run.

* `draw_configurations`: one panel per decision, top view with the robot's forward axis up: the perceived
  configuration, the goal as a ghost, every link's angle, who changed the object since the previous decision
  (robot, human, both, nobody) and the action taken after the decision with its outcome
  (succeeded / failed / partial, in colour).
* `caption_frame`: a camera frame with the detected ArUco markers outlined and numbered, above a band that
  says step, decision, actor and action.
* `write_movie`: the captioned frames as an animated GIF.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

import cv2
import numpy as np

from planhrc.robot_sim.vision import MarkerFinder, grey_image
from planhrc.vocabulary import ActionOutcome, DecisionKind

OUTCOME_COLOURS = {ActionOutcome.SUCCEEDED: "#2e7d32", ActionOutcome.PARTIAL: "#e07b00",
                   ActionOutcome.FAILED: "#c62828"}
ACTOR_COLOURS = {"robot": "#1f5fbf", "human": "#b0368a", "robot and human": "#6a3d9a", "nobody": "#5f6b7a",
                 "start": "#5f6b7a"}
CAPTION_FONT_PX = 15


@dataclass(frozen=True)
class PictureStep:
    """One decision of an episode as the pictures show it."""

    step: int
    decision: DecisionKind
    configuration_deg: tuple[float, ...]  # link orientations when perceived (clockwise from the robot's +x)
    base_xy: tuple[float, float]  # where l1 starts on the table (robot frame, metres)
    actor: str  # who changed the object since the previous decision: robot, human, robot and human, nobody, start
    action: str | None = None  # the action taken after the decision, in words
    outcome: ActionOutcome | None = None
    human: tuple[str, ...] = ()  # what the human did, in words
    markers_seen: int | None = None  # links whose marker the camera found (None: not perceived by camera)


# What a bimanual plan's steps that turn nothing do, in words: {joint} is the joint, {pair} the two links it joins.
HAND_STEP_WORDS = {"movetocentre": "centre the hands on {joint} ({pair})", "grasplinks": "grasp {pair} at {joint}",
                   "releaselinks": "release {pair} at {joint}"}


def describe_action(action: dict[str, Any] | None) -> str | None:
    """`a_3 j2: turn l3 +90°, hold l2` from a next-action answer of the service; a bimanual plan's steps that turn
    nothing say what they do: `a_1 j2: centre the hands on j2 (l2 and l3)`, `grasp l2 and l3 at j2`,
    `release l2 and l3 at j2`."""
    if not action:
        return None
    held = "the table" if action.get("held_link_index") == 0 else f"l{action.get('held_link_index')}"
    step = action.get("step")
    last = action.get("last_step")
    steps = f"a_{step}" if last in (None, step) else f"a_{step}..a_{last}"
    joint = f"j{action.get('joint_index')}"
    words = HAND_STEP_WORDS.get(str(action.get("name")))
    if words is not None:
        pair = " and ".join(f"l{k}" for k in sorted({int(action.get("held_link_index") or 0),
                                                       int(action.get("turned_link_index") or 0)}) if k)
        return f"{steps} {joint}: {words.format(joint=joint, pair=pair)}"
    return (f"{steps} {joint}: turn l{action.get('turned_link_index')} "
            f"{int(action.get('delta_deg', 0)):+d}°, hold {held}")


def actor_between(robot_outcome: ActionOutcome | None, human_moves: Sequence[str]) -> str:
    """Who changed the object between two perceptions: a robot action that moved something (succeeded or
    partial), a human move, both, or nobody."""
    robot = robot_outcome in (ActionOutcome.SUCCEEDED, ActionOutcome.PARTIAL)
    human = bool(human_moves)
    return "robot and human" if robot and human else "robot" if robot else "human" if human else "nobody"


# -- configurations ------------------------------------------------------------------------------------------
def _chain(base_xy: Sequence[float], angles: Sequence[float], link_length_m: float) -> tuple[list[float], list[float]]:
    """Drawing coordinates of the joints: the robot's forward axis (+x) up, its right (-y) to the right."""
    x, y = float(base_xy[0]), float(base_xy[1])
    xs, ys = [-y], [x]
    for theta in angles:
        t = math.radians(theta)
        x, y = x + link_length_m * math.cos(t), y - link_length_m * math.sin(t)
        xs.append(-y)
        ys.append(x)
    return xs, ys


def draw_configurations(path: Path, steps: Sequence[PictureStep], link_length_m: float,
                        goal_deg: Sequence[float] | None = None, title: str = "") -> Path:
    """One panel per decision (see the module's docstring); returns `path`."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    n = max(len(steps), 1)
    cols = min(n, 4)
    rows = (n + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(3.6 * cols, 4.1 * rows + 0.6), squeeze=False)
    for ax in axes.ravel():
        ax.axis("off")
    for ax, s in zip(axes.ravel(), steps):
        xs, ys = _chain(s.base_xy, s.configuration_deg, link_length_m)
        all_x, all_y = list(xs), list(ys)
        if goal_deg is not None and len(goal_deg) == len(s.configuration_deg):
            gx, gy = _chain(s.base_xy, goal_deg, link_length_m)
            ax.plot(gx, gy, "-", color="#2e9e5b", linewidth=9, alpha=0.3, solid_capstyle="round")
            all_x += gx
            all_y += gy
        ax.plot(xs, ys, "-", color="#1f5fbf", linewidth=3)
        ax.plot(xs[1:-1], ys[1:-1], "o", color="black", markersize=3)
        ax.plot(xs[0], ys[0], "s", color="#20303f", markersize=5)
        for k in range(len(s.configuration_deg)):
            mx, my = (xs[k] + xs[k + 1]) / 2, (ys[k] + ys[k + 1]) / 2
            ax.annotate(f"l{k + 1} {s.configuration_deg[k] % 360:.0f}°", (mx, my), fontsize=7,
                        xytext=(4, 3), textcoords="offset points", color="#1d2733")
        # the object and its goal fill the panel (room above and below for the texts)
        half = max(max(all_x) - min(all_x), max(all_y) - min(all_y), 2 * link_length_m) / 2 * 1.35
        cx, cy = (max(all_x) + min(all_x)) / 2, (max(all_y) + min(all_y)) / 2
        ax.set_aspect("equal")
        ax.set_xlim(cx - half, cx + half)
        ax.set_ylim(cy - half, cy + half)
        ax.axis("on")
        ax.set_xticks([])
        ax.set_yticks([])
        ax.set_title(f"step {s.step}: {s.decision.replace('_', ' ')}", fontsize=10, fontweight="bold")
        who = f"changed by: {s.actor}" + (f" ({'; '.join(s.human)})" if s.human else "")
        ax.text(0.02, 0.98, _wrap(who, 44), transform=ax.transAxes, fontsize=7.5, va="top",
                color=ACTOR_COLOURS.get(s.actor, "#1d2733"))
        if s.action:
            colour = "#1d2733" if s.outcome is None else OUTCOME_COLOURS[s.outcome]
            ax.text(0.02, 0.02, _wrap(f"then {s.action}: {s.outcome or 'not done'}", 44), transform=ax.transAxes,
                    fontsize=7.5, va="bottom", color=colour, fontweight="bold")
        if s.markers_seen is not None and s.markers_seen < len(s.configuration_deg):
            ax.text(0.98, 0.98, f"markers outlined {s.markers_seen}/{len(s.configuration_deg)}",
                    transform=ax.transAxes, fontsize=7, va="top", ha="right", color="#c62828")
    legend = [Line2D([], [], color="#1f5fbf", linewidth=3, label="perceived configuration (true poses)"),
              Line2D([], [], color="#2e9e5b", linewidth=9, alpha=0.3, label="goal (ghost)"),
              Line2D([], [], color=OUTCOME_COLOURS[ActionOutcome.SUCCEEDED], label="action succeeded"),
              Line2D([], [], color=OUTCOME_COLOURS[ActionOutcome.PARTIAL], label="partial"),
              Line2D([], [], color=OUTCOME_COLOURS[ActionOutcome.FAILED], label="failed")]
    fig.legend(handles=legend, loc="lower center", ncol=5, fontsize=8, frameon=False)
    if title:
        fig.suptitle(title, fontsize=11)
    fig.tight_layout(rect=(0, 0.04, 1, 0.97 if title else 1))
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _wrap(text: str, width: int) -> str:
    import textwrap

    return "\n".join(textwrap.wrap(text, width)) or text


# -- camera frames ---------------------------------------------------------------------------------------------
def detect_markers(frame: np.ndarray, upscales: Sequence[int] = (2, 1, 3),
                   wanted: frozenset[int] | None = None) -> dict[int, np.ndarray]:
    """Marker id -> its 4 corners in frame pixels, found as the camera perception finds them (the markers are
    only ~20 px wide, so enlarged copies are searched too); only the `wanted` ids when given (the links', not the
    calibration board's)."""
    return MarkerFinder(upscales, refine=False).find(grey_image(frame), wanted)


def overlay_markers(frame: np.ndarray, markers: dict[int, np.ndarray]) -> np.ndarray:
    """A copy of `frame` with each marker outlined (corner 0 marked) and labelled with its link (marker i is
    on link l(i+1))."""
    out = np.ascontiguousarray(frame[..., :3]).copy()
    for marker_id, corners in sorted(markers.items()):
        pts = np.round(corners).astype(np.int32)
        cv2.polylines(out, [pts.reshape(-1, 1, 2)], True, (255, 40, 200), 2, cv2.LINE_AA)
        cv2.circle(out, tuple(int(v) for v in pts[0]), 3, (255, 230, 0), -1, cv2.LINE_AA)
        x, y = pts[:, 0].max() + 4, pts[:, 1].min()
        label = f"l{marker_id + 1}"
        cv2.putText(out, label, (int(x), int(y)), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 0, 0), 3, cv2.LINE_AA)
        cv2.putText(out, label, (int(x), int(y)), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 1, cv2.LINE_AA)
    return out


def caption_frame(frame: np.ndarray, lines: Sequence[str], width: int | None = None,
                  markers: dict[int, np.ndarray] | None = None) -> np.ndarray:
    """The frame (markers overlaid when given, scaled to `width`) above a white band with the caption lines."""
    from PIL import Image, ImageDraw, ImageFont

    image = overlay_markers(frame, markers) if markers else np.ascontiguousarray(frame[..., :3])
    picture = Image.fromarray(image)
    if width and picture.width != width:
        picture = picture.resize((width, round(picture.height * width / picture.width)), Image.Resampling.LANCZOS)
    try:
        font = ImageFont.load_default(size=CAPTION_FONT_PX)
    except TypeError:  # Pillow < 10.1 has one fixed-size default font
        font = ImageFont.load_default()
    line_px = CAPTION_FONT_PX + 5
    band = Image.new("RGB", (picture.width, 8 + line_px * len(lines)), "white")
    draw = ImageDraw.Draw(band)
    for i, text in enumerate(lines):
        draw.text((8, 4 + i * line_px), text, fill=(29, 39, 51), font=font)
    out = Image.new("RGB", (picture.width, picture.height + band.height), "white")
    out.paste(picture, (0, 0))
    out.paste(band, (0, picture.height))
    return np.asarray(out)


def step_caption(s: PictureStep, n_links: int) -> list[str]:
    """Caption lines of the frame perceived at a decision."""
    seen = "" if s.markers_seen is None else f"   markers outlined: {s.markers_seen}/{n_links}"
    who = s.actor + (f": {'; '.join(s.human)}" if s.human else "")
    lines = [f"step {s.step}   decision: {s.decision.replace('_', ' ')}{seen}", f"changed by: {who}"]
    if s.action:
        lines.append(f"next: {s.action} -> {s.outcome or 'not done'}")
    return lines


def write_movie(path: Path, frames: Sequence[np.ndarray], seconds_per_frame: float = 0.9) -> Path | None:
    """An animated GIF of the (captioned) frames; None when there are none."""
    from PIL import Image

    if not frames:
        return None
    height = max(f.shape[0] for f in frames)
    images = []
    for f in frames:
        image = Image.fromarray(f)
        if image.height != height:  # the GIF needs one size: pad short frames at the bottom
            padded = Image.new("RGB", (image.width, height), "white")
            padded.paste(image, (0, 0))
            image = padded
        images.append(image.convert("P", palette=Image.Palette.ADAPTIVE, colors=255))
    images[0].save(path, save_all=True, append_images=images[1:], duration=int(seconds_per_frame * 1000), loop=0)
    return path
