"""`planhrc bag-picture`: one picture of a recorded episode, drawn from its bag's own messages (read with
`rosbags`, nothing else): the camera's frames at the perceptions, each link's perceived orientation over time (a
gap where it was not seen) against the goal, and the decisions and actions on one time line, each action named by
what it does and coloured by its outcome.
"""
from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from planhrc.cli_args import SubParsers, positive_int, writable_file
from planhrc.robot_sim.pictures import OUTCOME_COLOURS, describe_action

from .errors import Ros2Error


def read_episode(bag: Path) -> dict[str, Any]:
    """The bag's messages by kind (times in seconds from its first message)."""
    import cv2
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    if not (bag / "metadata.yaml").exists():
        raise Ros2Error(f"bag: {bag} has no metadata.yaml (a rosbag2 folder is expected)")
    out: dict[str, Any] = {"images": [], "perceived": [], "goal": None, "decisions": [], "actions": [],
                           "feedback": [], "object_id": None}
    with AnyReader([bag], default_typestore=get_typestore(Stores.ROS2_KILTED)) as reader:
        start = reader.start_time
        for connection, t, raw in reader.messages():
            topic, at = connection.topic, (t - start) / 1e9
            msg: Any = reader.deserialize(raw, connection.msgtype)
            if topic.endswith("/compressed"):
                frame = cv2.imdecode(np.frombuffer(bytes(msg.data), np.uint8), cv2.IMREAD_COLOR)
                if frame is not None:
                    out["images"].append((at, np.asarray(frame)[:, :, ::-1]))
            elif topic.endswith("/perceived"):
                out["object_id"] = topic.split("/")[3]
                out["perceived"].append((at, list(msg.name), [float(v) for v in msg.position]))
            elif topic.endswith("/goal"):
                out["goal"] = [(-math.degrees(v)) % 360.0 for v in msg.position]
            elif topic.endswith("/decision"):
                out["decisions"].append((at, json.loads(msg.data)))
            elif topic.endswith("/next_action"):
                out["actions"].append(at)
            elif topic.endswith("/feedback"):
                out["feedback"].append((at, json.loads(msg.data)))
    return out


def draw_episode(bag: Path, path: Path, frames: int = 6, title: str = "") -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    episode = read_episode(bag)
    images = episode["images"]
    if not images:
        raise Ros2Error(f"bag: {bag} holds no camera image")
    chosen = [images[round(i * (len(images) - 1) / max(frames - 1, 1))] for i in range(min(frames, len(images)))]
    fig = plt.figure(figsize=(13, 8.4))
    grid = fig.add_gridspec(3, len(chosen), height_ratios=[1.05, 1.3, 0.75], hspace=0.35, wspace=0.05)
    decisions = episode["decisions"]
    for i, (at, frame) in enumerate(chosen):
        ax = fig.add_subplot(grid[0, i])
        ax.imshow(frame)
        ax.set_xticks([])
        ax.set_yticks([])
        kind = next((d["decision"] for t, d in decisions if t >= at), "")
        ax.set_title(f"t = {at:.1f} s\n{kind.replace('_', ' ')}", fontsize=8)
    angles = fig.add_subplot(grid[1, :])
    names = [n for n in episode["perceived"][0][1] if n.startswith("l")] if episode["perceived"] else []
    colours = plt.get_cmap("tab10")
    for k, name in enumerate(names):
        times = [t for t, _, _ in episode["perceived"]]
        values = [(-math.degrees(p[k])) % 360.0 if not math.isnan(p[k]) else np.nan for _, _, p in episode["perceived"]]
        angles.step(times, values, where="post", color=colours(k), linewidth=1.8, label=name)
        angles.plot(times, values, "o", color=colours(k), markersize=3)
        if episode["goal"] is not None and k < len(episode["goal"]):
            angles.axhline(episode["goal"][k], color=colours(k), linestyle=":", linewidth=1)
    angles.set_ylabel("perceived orientation (°, clockwise)\ndotted: goal")
    angles.set_ylim(-10, 370)
    angles.set_yticks(range(0, 361, 45))
    angles.legend(loc="upper left", ncol=len(names), fontsize=8, frameon=False)
    angles.grid(alpha=0.3)
    line = fig.add_subplot(grid[2, :], sharex=angles)
    for t, d in decisions:
        line.plot([t], [1.0], "v", color="#1d2733")
        line.annotate(d["decision"].replace("_", " "), (t, 1.0), xytext=(0, 6), textcoords="offset points",
                      fontsize=7, rotation=30, ha="left")
    for start in episode["actions"]:  # each action: from its dispatch to its feedback, named by the decision before
        end, feedback = next(((t, f) for t, f in episode["feedback"] if t >= start), (start + 0.3, {}))
        decision: dict[str, Any] = next((d for t, d in reversed(decisions) if t <= start), {})
        colour = OUTCOME_COLOURS.get(feedback.get("outcome"), "#5f6b7a")  # type: ignore[call-overload]
        line.barh(0.35, end - start, left=start, height=0.35, color=colour, alpha=0.8)
        words = describe_action(decision.get("next_action"))
        if words:
            line.annotate(words.split(": ", 1)[-1], (start, 0.1), fontsize=6.5, rotation=-25, ha="left", va="top")
    line.set_ylim(-0.9, 1.9)
    line.set_yticks([0.35, 1.0], ["actions", "decisions"])
    line.set_xlabel("seconds from the bag's first message")
    fig.suptitle(title or f"{episode['object_id']}: an episode as its bag recorded it", fontsize=11)
    fig.savefig(path, dpi=100, bbox_inches="tight")
    plt.close(fig)
    return path


def add_bag_picture_parser(subparsers: SubParsers) -> None:
    p = subparsers.add_parser("bag-picture", help="a picture of an episode drawn from its recorded bag",
                              description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("bag", help="the episode's bag folder (with metadata.yaml), e.g. demo-out/episode-001/bag")
    p.add_argument("--out", type=writable_file, required=True, help="the PNG to write")
    p.add_argument("--frames", type=positive_int, default=6, help="camera frames shown")
    p.add_argument("--title", default="")
    p.set_defaults(func=run_bag_picture_cli)


def run_bag_picture_cli(args: argparse.Namespace) -> int:
    draw_episode(Path(args.bag), Path(args.out), args.frames, args.title)
    print(f"[bag-picture] {args.out}")
    return 0
