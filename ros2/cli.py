"""`planhrc ros2-bridge`, and what every command of the ROS 2 layer shares: the check for rclpy and the bridge as
a child process.

rclpy lives in `.venv-ros2` only (`python3 ./run.py ros2-bridge ...` makes it). Run from an environment without
it, each command says so in one line and exits 2; it does not re-launch itself elsewhere, so what runs is always
what was typed.
"""
from __future__ import annotations

import argparse
import importlib.util
import logging
import os
import subprocess
import sys
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Iterator

from planhrc.cli_args import http_url, positive_float, SubParsers

log = logging.getLogger(__name__)

NO_RCLPY = ("needs ROS 2's rclpy, which stays out of this environment: run `python3 ./run.py ros2-bridge --kb URL` "
            "(it makes .venv-ros2), or run `.venv-ros2/bin/planhrc {command}`")


def rclpy_problem(command: str) -> str | None:
    if importlib.util.find_spec("rclpy") is None:
        return NO_RCLPY.format(command=command)
    return None


def add_bridge_parser(subparsers: SubParsers) -> None:
    p = subparsers.add_parser("ros2-bridge", help="serve a running KB service's objects on a ROS 2 graph",
                              description="A ROS 2 node between a running KB service (HTTP) and ROS 2 topics under "
                                          "/planhrc/objects/<id>/ (see docs/ros2.md).")
    p.add_argument("--kb", type=http_url, required=True, help="base URL of the KB service")
    p.add_argument("--key", "--token", dest="token", default=None,
                   help="the bridge's client key (`planhrc keys add NAME --role robot`; env PLANHRC_KEY), or the "
                   "service's token (env PLANHRC_TOKEN)")
    p.add_argument("--object", dest="object_ids", action="append", default=[], metavar="ID",
                   help="serve this object (repeatable); default: every object, and each one created later")
    p.add_argument("--poll", type=positive_float, default=1.0, metavar="S",
                   help="seconds between two reads of the service's object list (without --object)")
    p.add_argument("--frame-id", default="base", help="frame of the markers and trajectories (the cell's, REP 103)")
    p.set_defaults(func=run_bridge_cli)


def run_bridge_cli(args: argparse.Namespace) -> int:
    if problem := rclpy_problem("ros2-bridge"):
        print(f"planhrc ros2-bridge: {problem}", file=sys.stderr)
        return 2
    from .node import BridgeSettings, run_bridge

    settings = BridgeSettings(args.kb, args.token or os.environ.get("PLANHRC_KEY") or os.environ.get("PLANHRC_TOKEN"), tuple(args.object_ids),
                              args.poll, args.frame_id)

    def ready(bridge: Any) -> None:
        print(f"[ros2-bridge] serving {', '.join(sorted(bridge.channels)) or 'no object yet'} of {args.kb} "
              f"on ROS_DOMAIN_ID={os.environ.get('ROS_DOMAIN_ID', '0')}", file=sys.stderr, flush=True)

    run_bridge(settings, on_ready=ready)
    return 0


@contextmanager
def running_bridge(kb_url: str, token: str | None, object_ids: tuple[str, ...] = (),
                   log_path: Path | None = None) -> Iterator[subprocess.Popen[bytes]]:
    """`planhrc ros2-bridge` as a child process in its own process group (stopped with it afterwards; on Linux it
    also gets SIGTERM when this process dies)."""
    from planhrc.service_process import die_with_parent, stop_process_group

    command = [sys.executable, "-m", "planhrc.cli", "ros2-bridge", "--kb", kb_url]
    for object_id in object_ids:
        command += ["--object", object_id]
    env = {**os.environ, **({"PLANHRC_TOKEN": token} if token else {})}
    out = open(log_path, "ab") if log_path else subprocess.DEVNULL
    try:
        proc = subprocess.Popen(command, env=env, stdout=out, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                                start_new_session=True, preexec_fn=die_with_parent)
        try:
            yield proc
        finally:
            stop_process_group(proc)
    finally:
        if log_path:
            out.close()  # type: ignore[union-attr]
