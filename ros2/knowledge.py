"""The knowledge service on the ROS 2 graph (rclpy): SPARQL, subsumption and reasoning as request/answer topic
pairs under /planhrc/knowledge/ (JSON in `std_msgs/String`, a request id in each, as the bridge's other requests),
and "reason now" as a real service with a standard type (`std_srvs/srv/Trigger`).

The channel has a node of its own, spun on a thread of its own by a two-thread executor: a reasoning job (seconds)
holds one thread while queries go on on the other, and neither holds up the objects' perceptions on the main
thread. A request sent again with the same id is answered again (from memory) and not redone, so a reasoning job
is not started twice; a request without an id is always new.
"""
from __future__ import annotations

import logging
import threading
import time
from collections import OrderedDict
from typing import Any, Callable

from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.executors import MultiThreadedExecutor
from rclpy.node import Node
from std_msgs.msg import String
from std_srvs.srv import Trigger

from planhrc.client import KBClient, ProtocolError, RetryPolicy

from . import topics
from .channel import qos_of
from .errors import Ros2Error
from .knowledge_messages import (KnowledgeRequest, answer_text, graphs, read_request, refusal_text, request_id_of,
                                 sparql_answer_text)

log = logging.getLogger(__name__)

REMEMBERED_ANSWERS = 64  # per topic
JOB_POLL_S = 0.2
JOB_WAIT_S = 3600.0  # the service's own limit (reasoning_timeout_s) ends a job long before


class KnowledgeChannel:
    """The knowledge topics and the reason-now service on `node`."""

    def __init__(self, node: Node, kb: KBClient, stop: threading.Event) -> None:
        self.node, self.kb, self.stop = node, kb, stop
        group = ReentrantCallbackGroup()
        self.lock = threading.Lock()
        self.answers: dict[str, OrderedDict[str, str | None]] = {}  # topic -> request id -> answer (None: running)
        self.pub: dict[str, Any] = {}
        self.subs = []
        handlers: dict[str, Callable[[KnowledgeRequest], str]] = {
            "sparql": self._sparql, "subsumption": self._subsumption, "reasoning": self._reasoning}
        for request_spec, answer_spec in ((topics.SPARQL_REQUEST, topics.SPARQL_ANSWER),
                                          (topics.SUBSUMPTION_REQUEST, topics.SUBSUMPTION_ANSWER),
                                          (topics.REASONING_REQUEST, topics.REASONING_ANSWER)):
            name = request_spec.suffix.split("/")[0]
            self.answers[name] = OrderedDict()
            self.pub[name] = node.create_publisher(String, answer_spec.full_name, qos_of(answer_spec))
            self.subs.append(node.create_subscription(
                String, request_spec.full_name, self._on_request(name, handlers[name]), qos_of(request_spec),
                callback_group=group))
        self.service = node.create_service(Trigger, topics.REASON_NOW[0], self.on_reason_now, callback_group=group)
        self.counts = {"answered": 0, "refused": 0}

    def _on_request(self, name: str, handle: Callable[[KnowledgeRequest], str]) -> Callable[[String], None]:
        def on_message(msg: String) -> None:
            request_id = request_id_of(msg.data)
            with self.lock:
                known = self.answers[name]
                if request_id and request_id in known:
                    if known[request_id] is not None:  # answered: again; running: its answer will come
                        self.pub[name].publish(String(data=known[request_id]))
                    return
                if request_id:
                    known[request_id] = None
            try:
                text = handle(read_request(name, msg.data))
                self.counts["answered"] += 1
            except (Ros2Error, ProtocolError) as exc:
                log.warning("knowledge %s %r refused: %s", name, request_id, exc)
                text = refusal_text(request_id, exc)
                self.counts["refused"] += 1
            with self.lock:
                if request_id:
                    known[request_id] = text
                    while len(known) > REMEMBERED_ANSWERS:
                        known.popitem(last=False)
            self.pub[name].publish(String(data=text))
        return on_message

    # -- the three questions ------------------------------------------------------------------------------------
    def _sparql(self, request: KnowledgeRequest) -> str:
        f = request.fields
        answer = self.kb.sparql(f["query"], f.get("accept"), graphs(f.get("default_graph_uri")),
                                graphs(f.get("named_graph_uri")))
        return sparql_answer_text(request.request_id, answer)

    def _subsumption(self, request: KnowledgeRequest) -> str:
        body = self.kb.subsumption(request.fields["state_id"], request.fields["by_state_id"])
        return answer_text(request.request_id, body)

    def _reasoning(self, request: KnowledgeRequest) -> str:
        f = request.fields
        return answer_text(request.request_id, self._finished_job(f["reasoner"], f.get("object_id"), f.get("scope")))

    def _finished_job(self, reasoner: str, object_id: str | None, scope: str | None) -> dict[str, Any]:
        """Start a job and follow it to its end (the service runs jobs one at a time, each within its limit)."""
        job = self.kb.submit_reasoning(reasoner, object_id, scope)
        until = time.monotonic() + JOB_WAIT_S
        while job.get("status") in ("queued", "running"):
            if self.stop.wait(JOB_POLL_S) or time.monotonic() > until:
                raise Ros2Error(f"reasoning: job {job.get('id')} did not finish while the bridge waited")
            job = self.kb.read_reasoning(str(job["id"]))
        return job

    def on_reason_now(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        """Pellet on every object (scope states): success when the job finished and the ABox is consistent."""
        try:
            job = self._finished_job("pellet", None, None)
        except (Ros2Error, ProtocolError) as exc:
            response.success, response.message = False, refusal_text("", exc)
            return response
        response.success = job.get("status") == "done" and bool(job.get("consistent"))
        response.message = answer_text("", job)
        return response

    def destroy(self) -> None:
        for sub in self.subs:
            self.node.destroy_subscription(sub)
        for pub in self.pub.values():
            self.node.destroy_publisher(pub)
        self.node.destroy_service(self.service)


class KnowledgeThread:
    """The knowledge node spun on a thread of its own (two executor threads), until `close`."""

    def __init__(self, node: Node, kb_url: str, token: str | None, stop: threading.Event) -> None:
        # one attempt at a time: a query refused or past its time limit is not sent again
        self.kb = KBClient(kb_url, token=token, retry=RetryPolicy(attempts=2), timeout_s=60.0)
        self.node = node
        self.channel = KnowledgeChannel(node, self.kb, stop)
        self.executor = MultiThreadedExecutor(num_threads=2, context=node.context)
        self.executor.add_node(node)
        self.stop = stop
        self.thread = threading.Thread(target=self._spin, name="planhrc-knowledge", daemon=True)
        self.thread.start()

    def _spin(self) -> None:
        while not self.stop.is_set():
            try:
                self.executor.spin_once(timeout_sec=0.2)
            except Exception:  # a fault in one callback: logged, and the channel goes on
                if self.stop.is_set():
                    return
                log.exception("a knowledge callback failed")

    def close(self) -> None:
        self.stop.set()
        self.thread.join(timeout=2.0)
        self.executor.shutdown(timeout_sec=2.0)
        self.channel.destroy()
        self.node.destroy_node()
        self.kb.close()
