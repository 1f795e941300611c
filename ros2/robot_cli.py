"""`planhrc worker --ros2` and `planhrc demo --ros2`: the robot's own commands, with the worker's link to the
service made over the bridge's topics (`Ros2Link`) instead of HTTP. The demo starts a bridge for each episode's
object beside the service it starts, so its worker talks ROS 2 only. With `--record` (over HTTP or ROS 2) each
episode is written as a rosbag2 bag (`bag`: no rclpy needed).
"""
from __future__ import annotations

import argparse
import sys
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Iterator

from planhrc.cli_args import SubParsers
from planhrc.robot_sim.demo import add_demo_parser as add_robot_demo
from planhrc.robot_sim.demo import run_demo_cli as run_robot_demo
from planhrc.robot_sim.worker_cli import add_worker_parser as add_robot_worker
from planhrc.robot_sim.worker_cli import run_worker_cli as run_robot_worker

from .cli import rclpy_problem, running_bridge


def add_worker_parser(subparsers: SubParsers) -> None:
    add_robot_worker(subparsers).set_defaults(func=run_worker_cli)


def run_worker_cli(args: argparse.Namespace) -> int:
    from .bag import episode_bag

    recording = episode_bag if args.record else None
    if not args.ros2:
        return run_robot_worker(args, recording=recording)
    if problem := rclpy_problem("worker --ros2"):
        print(f"planhrc worker: --ros2: {problem}", file=sys.stderr)
        return 2
    from .link import Ros2Link

    with Ros2Link(args.object_id) as link:
        return run_robot_worker(args, link=link, recording=recording)


def add_demo_parser(subparsers: SubParsers) -> None:
    add_robot_demo(subparsers).set_defaults(func=run_demo_cli)


def run_demo_cli(args: argparse.Namespace) -> int:
    from .bag import episode_bag

    recording = episode_bag if args.record else None
    if not args.ros2:
        return run_robot_demo(args, recording=recording)
    if problem := rclpy_problem("demo --ros2"):
        print(f"planhrc demo: --ros2: {problem}", file=sys.stderr)
        return 2
    return run_robot_demo(args, worker_link=bridged_link, recording=recording)


@contextmanager
def bridged_link(kb_url: str, token: str | None, object_id: str, out_dir: Path) -> Iterator[Any]:
    """A bridge for one object and the worker's link through it: the demo's worker talks ROS 2 only."""
    from .link import Ros2Link

    out_dir.mkdir(parents=True, exist_ok=True)
    with running_bridge(kb_url, token, (object_id,), out_dir / "ros2-bridge.log"):
        with Ros2Link(object_id) as link:
            yield link
