"""`planhrc perceive-calibrate` and `planhrc perceive-node`: their arguments, checked before anything starts (rclpy
is imported only when they run: `.venv-ros2`, docs/perception.md).

    planhrc perceive-calibrate --board board.json --out calibration.json       # the board lies on the table
    planhrc perceive-node --calibration calibration.json --object obj1=0-4     # then the object
"""
from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from planhrc.cli_args import (SubParsers, existing_file, float_in, non_negative_float, positive_float, positive_int,
                              writable_file)
from planhrc.robot_sim.camera import Board, Calibration
from planhrc.robot_sim.vision import Limits, ObjectMarkers

from .cli import rclpy_problem
from .perceive_messages import PerceiveSettings, PublishPolicy, parse_object

# the simulated cell's links: 15.5 cm long, their 3 cm markers' tops 15.5 mm above the board's markers
DEFAULT_LINK_LENGTH_M = 0.155
DEFAULT_MARKER_SIZE_M = 0.03
DEFAULT_MARKER_HEIGHT_M = 0.0155


def object_arg(text: str) -> tuple[str, tuple[int, ...]]:
    try:
        return parse_object(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _camera_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--image-topic", default="/camera/image_raw", help="sensor_msgs/Image: rgb8, bgr8 or mono8")
    p.add_argument("--camera-info-topic", default="/camera/camera_info", help="sensor_msgs/CameraInfo (its K, D)")
    p.add_argument("--best-effort", action="store_true",
                   help="subscribe to the camera best effort (a driver publishing with the sensor-data QoS)")


def add_calibrate_parser(subparsers: SubParsers) -> None:
    p = subparsers.add_parser("perceive-calibrate", help="the camera's pose on the table from the board's markers",
                              description="Watch a camera (ROS 2) until the calibration board's markers on the table "
                                          "show in enough images, fit the camera's pose in the cell's frame and "
                                          "write it to a file for `planhrc perceive-node`.")
    p.add_argument("--board", type=existing_file, required=True,
                   help="JSON: {markers: [{id, x, y, z, yaw_rad, size_m}]} in the cell's frame, metres")
    p.add_argument("--out", type=writable_file, required=True, help="the calibration file to write")
    _camera_args(p)
    p.add_argument("--frames", type=positive_int, default=5, help="images showing the board to fit the pose from")
    p.add_argument("--timeout", type=positive_float, default=30.0, metavar="S")
    p.add_argument("--frame-id", default="base", help="the cell's frame the board is given in")
    p.set_defaults(func=run_calibrate_cli)


def run_calibrate_cli(args: argparse.Namespace) -> int:
    board = Board.read(args.board)  # a bad file: one line naming the field (planhrc.cli)
    if problem := rclpy_problem("perceive-calibrate"):
        print(f"planhrc perceive-calibrate: {problem}", file=sys.stderr)
        return 2
    from .perceive import run_calibration

    calibration = run_calibration(board, args.image_topic, args.camera_info_topic, args.frames, args.timeout,
                                  args.frame_id, args.best_effort)
    calibration.write(args.out)
    x, y, z = calibration.pose.position
    print(f"[perceive-calibrate] camera at ({x:.3f}, {y:.3f}, {z:.3f}) m in {calibration.frame_id}, from board "
          f"markers {list(calibration.markers_used)} in {calibration.frames} images, reprojection "
          f"{calibration.reprojection_rms_px:.2f} px RMS; written to {args.out}")
    return 0


def add_node_parser(subparsers: SubParsers) -> None:
    p = subparsers.add_parser("perceive-node", help="a camera's images to the objects' perceived states (ROS 2)",
                              description="Read the links' markers in a camera's images and publish each object's "
                                          "perceived state on /planhrc/objects/<id>/perceived, for the bridge "
                                          "(docs/perception.md).")
    p.add_argument("--calibration", type=existing_file, required=True,
                   help="the camera's pose, written by `planhrc perceive-calibrate`")
    p.add_argument("--object", dest="objects", type=object_arg, action="append", required=True, metavar="ID=MARKERS",
                   help="an object and its links' marker ids, l1 first: obj1=0-4 or obj1=3,4,5 (repeatable)")
    _camera_args(p)
    p.add_argument("--link-length", type=positive_float, default=DEFAULT_LINK_LENGTH_M, metavar="M",
                   help="length of a link (m): the base point lies half a link behind l1's marker")
    p.add_argument("--marker-size", type=positive_float, default=DEFAULT_MARKER_SIZE_M, metavar="M",
                   help="side of the links' markers (m), the black border's outer edge")
    p.add_argument("--marker-height", type=float_in(-1.0, 1.0), default=DEFAULT_MARKER_HEIGHT_M, metavar="M",
                   help="height of the links' marker tops above the board's markers (m)")
    p.add_argument("--period", type=non_negative_float, default=1.0, metavar="S",
                   help="at most one perception of an object every S seconds")
    p.add_argument("--change-deg", type=positive_float, default=3.0,
                   help="a link turned by more than this is a new perception")
    p.add_argument("--every-image", action="store_true", help="publish a perception for every image")
    p.add_argument("--max-reprojection", type=positive_float, default=Limits().max_reprojection_px, metavar="PX",
                   help="a marker whose corners miss its fit by more (RMS) is reported unseen")
    p.add_argument("--max-sigma", type=positive_float, default=Limits().max_angle_sigma_deg, metavar="DEG",
                   help="a marker whose orientation's standard error is larger is reported unseen")
    p.set_defaults(func=run_node_cli)


def node_settings(args: argparse.Namespace) -> PerceiveSettings:
    """The node's settings from checked arguments (a bad calibration file: one line naming the field)."""
    calibration = Calibration.read(args.calibration)
    ids = [object_id for object_id, _ in args.objects]
    if len(set(ids)) != len(ids):
        raise argparse.ArgumentTypeError(f"--object: {ids} names an object twice")
    board_z = sum(m.z for m in calibration.board.markers) / len(calibration.board.markers)
    objects = tuple(ObjectMarkers(object_id, markers, args.link_length, args.marker_size,
                                  board_z + args.marker_height) for object_id, markers in args.objects)
    policy = PublishPolicy(period_s=args.period, change_deg=args.change_deg, every_image=args.every_image)
    return PerceiveSettings(calibration, objects, args.image_topic, args.camera_info_topic, policy,
                            Limits(args.max_reprojection, args.max_sigma), args.best_effort)


def run_node_cli(args: argparse.Namespace) -> int:
    try:
        settings = node_settings(args)
    except argparse.ArgumentTypeError as exc:
        print(f"planhrc perceive-node: {exc}", file=sys.stderr)
        return 2
    if problem := rclpy_problem("perceive-node"):
        print(f"planhrc perceive-node: {problem}", file=sys.stderr)
        return 2
    from .perceive import PerceiveNode, run_perceive_node

    def ready(node: PerceiveNode) -> None:
        names = ", ".join(o.object_id for o in settings.objects)
        print(f"[perceive-node] reading {names} from {settings.image_topic} with {Path(args.calibration).name} on "
              f"ROS_DOMAIN_ID={os.environ.get('ROS_DOMAIN_ID', '0')}", file=sys.stderr, flush=True)

    run_perceive_node(settings, on_ready=ready)
    return 0
