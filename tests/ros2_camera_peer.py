"""A camera for the perception tests, run by `.venv-ros2/bin/python` in a process of its own.

It knows `planhrc perceive-node` only by its documented topics (nothing of planhrc is imported): it publishes kept
views (tests/data/perception/) as sensor_msgs/Image in their encoding, each after a sensor_msgs/CameraInfo with
the view's K, and prints one JSON line per answer. argv[1] is JSON:

    {"mode": "calibrate", "dir": D, "views": [file, ...], "until": PATH, "timeout": S}
        publish the views over and over (5 a second) until the file PATH exists
    {"mode": "perceive", "dir": D, "views": [file, ...], "object": ID, "timeout": S, "bad_first": bool}
        publish each view (stamp sec = 1000 + its index) until the object's perceived JointState with that stamp
        comes back (again every second: discovery may lose the first); print {"file", "names", "positions",
        "detail", "latency_ms"}. With bad_first, an image in an encoding the node does not read goes first, and
        the node's /diagnostics camera status is printed as {"diagnostics": ...}.

Then `{"done": true}`; a wait that times out exits 3.
"""
from __future__ import annotations

import json
import math
import sys
import time
from pathlib import Path

import cv2
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import CameraInfo, Image, JointState
from std_msgs.msg import String


def load(folder: Path, entry: dict) -> tuple[Image, CameraInfo]:
    encoding = entry["encoding"]
    if encoding == "mono8":
        pixels = cv2.imread(str(folder / entry["file"]), cv2.IMREAD_GRAYSCALE)
    else:
        pixels = cv2.imread(str(folder / entry["file"]), cv2.IMREAD_COLOR)  # BGR
        if encoding == "rgb8":
            pixels = cv2.cvtColor(pixels, cv2.COLOR_BGR2RGB)
    height, width = pixels.shape[:2]
    image = Image(height=height, width=width, encoding=encoding, is_bigendian=0,
                  step=width * (1 if pixels.ndim == 2 else 3), data=pixels.tobytes())
    camera = entry["truth"]["camera"]
    info = CameraInfo(height=height, width=width, distortion_model="plumb_bob", d=[0.0] * 5, k=camera["k"])
    info.header.frame_id = image.header.frame_id = "camera"
    return image, info


def main() -> int:
    spec = json.loads(sys.argv[1])
    folder = Path(spec["dir"])
    entries = {v["file"]: v for v in json.loads((folder / "views.json").read_text())["views"]}
    views = [load(folder, entries[name]) for name in spec["views"]]
    rclpy.init()
    node = Node("planhrc_test_camera")
    images = node.create_publisher(Image, "/camera/image_raw", QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE))
    infos = node.create_publisher(CameraInfo, "/camera/camera_info", 1)

    def send(image: Image, info: CameraInfo, sec: int) -> None:
        for msg in (info, image):
            msg.header.stamp.sec, msg.header.stamp.nanosec = sec, 0
        infos.publish(info)
        images.publish(image)

    deadline = time.monotonic() + float(spec.get("timeout", 60))
    try:
        if spec["mode"] == "calibrate":
            until = Path(spec["until"])
            i = 0
            while not until.exists():
                if time.monotonic() > deadline:
                    return 3
                send(*views[i % len(views)], 100 + i)
                i += 1
                rclpy.spin_once(node, timeout_sec=0.2)
        else:
            base = f"/planhrc/objects/{spec['object']}"
            states: dict[int, tuple[JointState, float]] = {}
            details: dict[int, dict] = {}
            health: list[dict] = []
            node.create_subscription(JointState, f"{base}/perceived",
                                     lambda m: states.setdefault(m.header.stamp.sec, (m, time.perf_counter())), 10)
            node.create_subscription(String, f"{base}/perception",
                                     lambda m: details.setdefault(json.loads(m.data)["stamp"][0], json.loads(m.data)), 10)
            node.create_subscription(DiagnosticArray, "/diagnostics", lambda m: health.extend(
                {"name": s.name, "message": s.message, "values": {v.key: v.value for v in s.values}} for s in m.status), 10)
            if spec.get("bad_first"):
                image, info = views[0]
                bad = Image(height=image.height, width=image.width, encoding="yuv422", step=image.width * 2,
                            data=bytes(image.width * image.height * 2))
                while not any("image.encoding" in h["message"] for h in health):
                    if time.monotonic() > deadline:
                        return 3
                    send(bad, info, 1)
                    rclpy.spin_once(node, timeout_sec=0.3)
                print(json.dumps({"diagnostics": next(h for h in health if "image.encoding" in h["message"])}))
            for index, (image, info) in enumerate(views):
                sec, sent = 1000 + index, -math.inf
                while sec not in states or sec not in details:
                    if time.monotonic() > deadline:
                        return 3
                    if time.monotonic() - sent > 1.0:
                        started, sent = time.perf_counter(), time.monotonic()
                        send(image, info, sec)
                    rclpy.spin_once(node, timeout_sec=0.05)
                state, received = states[sec]
                print(json.dumps({"file": spec["views"][index], "names": list(state.name),
                                  "positions": [None if math.isnan(p) else p for p in state.position],
                                  "frame_id": state.header.frame_id, "detail": details[sec],
                                  "latency_ms": (received - started) * 1000.0}))
        print(json.dumps({"done": True}), flush=True)
        return 0
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    sys.exit(main())
