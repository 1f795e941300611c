"""`planhrc worker`: the simulated Baxter worker's command line (arguments checked before anything starts)."""
from __future__ import annotations

import argparse
import json
import os
import sys
from typing import Any

from planhrc.cli_args import (SubParsers, float_tuple, http_url, non_negative_float, non_negative_int, positive_int,
                              writable_dir)
from planhrc.client import KBClient, ProtocolError
from planhrc.robot_sim.errors import SimError
from planhrc.robot_sim.recording import Recording
from planhrc.robot_sim.scene import SceneSpec
from planhrc.robot_sim.service_link import ServiceLink
from planhrc.robot_sim.worker import run_worker


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
    p.add_argument("--record", action="store_true",
                   help="write the episode as a rosbag2 bag (MCAP) in --out, on the bridge's topic names")
    p.set_defaults(func=run_worker_cli)
    return p


def run_worker_cli(args: argparse.Namespace, link: ServiceLink | None = None,
                   recording: Recording | None = None) -> int:
    """The worker's command; `link` is given by the ROS 2 layer for `--ros2`, `recording` for `--record`."""
    if args.kb is None and not args.ros2:
        print("planhrc worker: --kb: required (or --ros2, through a running ROS 2 bridge)", file=sys.stderr)
        return 2
    if args.ros2 and link is None:
        print("planhrc worker: --ros2: the ROS 2 link is made by `planhrc worker --ros2` in .venv-ros2", file=sys.stderr)
        return 2
    if args.record and recording is None:
        print("planhrc worker: --record: the bag is written by the ROS 2 layer (`planhrc worker --record`)",
              file=sys.stderr)
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
                             args.token, args.perception, args.goal, args.sigma, args.seed, kb=link,
                             recording=recording)
    except (ProtocolError, SimError) as exc:
        print(f"planhrc worker: {exc}", file=sys.stderr)
        return 1
    print(json.dumps({"reached_goal": summary.reached_goal, "stop_reason": summary.stop_reason,
                      "reason": summary.stop_message, "failure_reasons": summary.failure_reasons,
                      "unseen_links": summary.unseen_links,
                      "decisions": list(summary.decisions), "outcomes": list(summary.outcomes),
                      "steps": len(summary.steps), "wall_s": round(summary.wall_s, 2), "out_dir": summary.out_dir}))
    return 0 if summary.reached_goal else 1
