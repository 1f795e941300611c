"""A ROS 2 peer for the bridge's tests, run by `.venv-ros2/bin/python` in a process of its own.

It knows the bridge only by the documented topic names, types and QoS (nothing of planhrc is imported), runs the
steps given as JSON in argv[1] and prints every message it received as one JSON line
`{"topic": ..., "msg": ...}`, then `{"done": true}`. Steps:

    {"publish": "perceived" | "goal", "names": [...], "positions": [...], "stamp": [sec, nanosec]}
    {"publish": "feedback" | "give_up", "data": {...}}
    {"wait": TOPIC, "match": {"a.b": value, ...}, "timeout": S}   # a String topic's JSON with those values
    {"wait": TOPIC, "count": N, "timeout": S}                      # N messages on TOPIC
    {"wait": TOPIC, "count": N, "fresh": true}                     # N messages on TOPIC received from now on
    {"sleep": S}

TOPIC is a suffix under /planhrc/objects/<id>/ or "/diagnostics". A wait that times out exits 3.
"""
from __future__ import annotations

import json
import math
import sys
import time

import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from trajectory_msgs.msg import JointTrajectory
from visualization_msgs.msg import MarkerArray


def qos(depth: int, latched: bool) -> QoSProfile:
    return QoSProfile(depth=depth, reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE)


def seconds(duration) -> float:
    return duration.sec + duration.nanosec * 1e-9


def as_json(topic: str, msg) -> object:
    if isinstance(msg, String):
        return json.loads(msg.data)
    if isinstance(msg, JointTrajectory):
        return {"frame_id": msg.header.frame_id, "joint_names": list(msg.joint_names),
                "points": [{"positions": list(p.positions), "time_from_start": seconds(p.time_from_start)}
                           for p in msg.points]}
    if isinstance(msg, MarkerArray):
        return {"markers": [{"ns": m.ns, "id": m.id, "action": m.action, "type": m.type,
                             "frame_id": m.header.frame_id, "points": [[p.x, p.y, p.z] for p in m.points]}
                            for m in msg.markers]}
    if isinstance(msg, DiagnosticArray):
        return {"status": [{"name": s.name, "level": int.from_bytes(s.level, "little") if isinstance(s.level, bytes)
                            else int(s.level), "message": s.message, "values": {v.key: v.value for v in s.values}}
                           for s in msg.status]}
    raise TypeError(topic)


def get_path(data: object, path: str) -> object:
    """`a.b` of nested JSON objects (None where a key is missing)."""
    for key in path.split("."):
        data = data.get(key) if isinstance(data, dict) else None
    return data


def main() -> int:
    object_id, steps = sys.argv[1], json.loads(sys.argv[2])
    rclpy.init()
    node = Node("planhrc_test_peer")
    base = f"/planhrc/objects/{object_id}"
    received: list[dict] = []

    def keep(topic: str):
        return lambda msg: received.append({"topic": topic, "msg": as_json(topic, msg)})

    for suffix, msg_type, depth, latched in (("decision", String, 10, True), ("next_action", JointTrajectory, 10, False),
                                             ("markers", MarkerArray, 1, True), ("help", String, 1, True),
                                             ("plan", String, 1, True), ("object", String, 100, True)):
        node.create_subscription(msg_type, f"{base}/{suffix}", keep(suffix), qos(depth, latched))
    node.create_subscription(DiagnosticArray, "/diagnostics", keep("/diagnostics"), qos(10, False))
    pubs = {"perceived": node.create_publisher(JointState, f"{base}/perceived", qos(10, False)),
            "goal": node.create_publisher(JointState, f"{base}/goal", qos(10, False)),
            "feedback": node.create_publisher(String, f"{base}/feedback", qos(10, False)),
            "give_up": node.create_publisher(String, f"{base}/give_up", qos(10, False))}

    def spin_until(ready, timeout: float) -> bool:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if ready():
                return True
            rclpy.spin_once(node, timeout_sec=0.05)
        return ready()

    # Matched both ways: the bridge subscribes to our inputs, and its latched object topic reached us. A writer can
    # see the reader before the reader sees the writer; what is sent in between is lost, so wait a little more.
    if not spin_until(lambda: all(p.get_subscription_count() > 0 for p in pubs.values())
                      and any(r["topic"] == "object" for r in received), 30.0):
        print(json.dumps({"error": "the bridge does not serve the object's topics"}), flush=True)
        return 3
    spin_until(lambda: False, 0.5)
    for step in steps:
        if "publish" in step:
            topic = step["publish"]
            if topic in ("perceived", "goal"):
                msg = JointState(name=step["names"], position=[math.nan if p is None else float(p)
                                                               for p in step["positions"]])
                msg.header.stamp.sec, msg.header.stamp.nanosec = step.get("stamp", [0, 0])
            else:
                msg = String(data=step["data"] if isinstance(step["data"], str) else json.dumps(step["data"]))
            pubs[topic].publish(msg)
        elif "wait" in step:
            topic, match, count = step["wait"], step.get("match"), step.get("count", 1)
            since = len(received) if step.get("fresh") else 0  # fresh: only what arrives from now on

            def ready() -> bool:
                found = [r for r in received[since:] if r["topic"] == topic and (
                    match is None or all(get_path(r["msg"], k) == v for k, v in match.items()))]
                return len(found) >= count

            if not spin_until(ready, step.get("timeout", 30.0)):
                for r in received:
                    print(json.dumps(r), flush=True)
                print(json.dumps({"error": f"timed out waiting for {step}"}), flush=True)
                return 3
        elif "sleep" in step:
            spin_until(lambda: False, step["sleep"])
    for r in received:
        print(json.dumps(r), flush=True)
    print(json.dumps({"done": True}), flush=True)
    node.destroy_node()
    rclpy.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
