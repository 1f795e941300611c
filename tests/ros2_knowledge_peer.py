"""A ROS 2 peer of the bridge's knowledge topics and service, run by `.venv-ros2/bin/python` in a process of its own.

It knows the bridge only by the documented names, types and QoS (nothing of planhrc is imported). argv[1] is a JSON
list of steps, run in order:

    {"ask": "sparql" | "subsumption" | "reasoning", "request": {...}, "timeout": S}
        publish the request on /planhrc/knowledge/<ask>/request, again every second until the answer with its
        request_id comes on /planhrc/knowledge/<ask>/answer (a request sent again is answered again, not redone)
    {"call": "reason_now", "timeout": S}
        call the std_srvs/srv/Trigger service /planhrc/knowledge/reason_now

and prints one JSON line per answer (`{"ask": ..., "answer": {...}, "sent": n}` or `{"call": ..., "success": ...,
"message": ...}`), then `{"done": true}`. A step that times out exits 3.
"""
from __future__ import annotations

import json
import sys
import time

import rclpy
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import String
from std_srvs.srv import Trigger

BASE = "/planhrc/knowledge"


def main() -> int:
    steps = json.loads(sys.argv[1])
    rclpy.init()
    node = Node("planhrc_knowledge_peer")
    volatile = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)
    latched = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
    answers: list[dict] = []
    pubs = {}
    for ask in ("sparql", "subsumption", "reasoning"):
        pubs[ask] = node.create_publisher(String, f"{BASE}/{ask}/request", volatile)
        node.create_subscription(String, f"{BASE}/{ask}/answer",
                                 lambda msg, ask=ask: answers.append({"ask": ask, "answer": json.loads(msg.data)}),
                                 latched)
    client = node.create_client(Trigger, f"{BASE}/reason_now")

    def spin_for(seconds: float) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            rclpy.spin_once(node, timeout_sec=0.05)

    out: list[dict] = []
    for step in steps:
        timeout = step.get("timeout", 60.0)
        end = time.monotonic() + timeout
        if "ask" in step:
            ask, request = step["ask"], step["request"]
            sent = 0
            found = None
            while found is None and time.monotonic() < end:
                pubs[ask].publish(String(data=json.dumps(request)))
                sent += 1
                until = min(end, time.monotonic() + 1.0)
                while found is None and time.monotonic() < until:
                    rclpy.spin_once(node, timeout_sec=0.05)
                    found = next((a for a in answers if a["ask"] == ask
                                  and a["answer"].get("request_id") == request.get("request_id")), None)
            if found is None:
                print(json.dumps({"error": f"no answer to {step}", "seen": answers[-5:]}), flush=True)
                return 3
            out.append({**found, "sent": sent})
        else:
            if not client.wait_for_service(timeout_sec=timeout):
                print(json.dumps({"error": "the reason_now service is not there"}), flush=True)
                return 3
            future = client.call_async(Trigger.Request())
            rclpy.spin_until_future_complete(node, future, timeout_sec=max(0.1, end - time.monotonic()))
            if not future.done():
                print(json.dumps({"error": "reason_now did not answer"}), flush=True)
                return 3
            result = future.result()
            out.append({"call": "reason_now", "success": bool(result.success), "message": json.loads(result.message)})
        spin_for(0.05)
    for line in out:
        print(json.dumps(line), flush=True)
    print(json.dumps({"done": True}), flush=True)
    node.destroy_node()
    rclpy.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
