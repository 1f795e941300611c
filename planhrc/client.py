"""The public HTTP client of the knowledge-base service (httpx): what the Baxter worker uses, and what anyone
embedding planhrc uses to drive the service from another process.

    from planhrc.client import KBClient

    with KBClient("http://127.0.0.1:8000", token="T") as kb:
        oid = kb.create_object("rod", links=4, orientations=4, formulation="relative")["id"]
        kb.set_goal(oid, link_orientations_deg=[0, 90, 90, 180])
        decision = kb.post_perception(oid, [0, 0, 0, 0])      # decision.decision: replan, continue, ...
        action = kb.next_action(oid)                          # marks it dispatched; None when there is none
        kb.post_feedback(oid, action["id"], "succeeded")

It imports only the bottom layer (`planhrc.vocabulary`) and httpx, never the service's code.
Connection errors and 5xx answers are retried with exponential backoff (the service may be restarting).
Every perception and every feedback carries an ``Idempotency-Key`` (uuid4) that stays the same across the
retries of that one request, so a request that reached the service before the connection dropped is not
applied twice. 4xx answers are not retried: they raise `ProtocolError` with the service's message.
"""
from __future__ import annotations

import json
import logging
import time
import uuid
from dataclasses import dataclass, field
from typing import Any, Callable, Iterator, Sequence
from urllib.parse import quote

import httpx

from planhrc.errors import PlanhrcError
from planhrc.vocabulary import ActionOutcome, DecisionKind, FailureReason

log = logging.getLogger(__name__)


# Errors no retry can fix: the URL itself is wrong. Other transport errors and 5xx answers are retried; 4xx
# answers are final too.
FINAL_TRANSPORT_ERRORS = (httpx.UnsupportedProtocol, httpx.InvalidURL, httpx.LocalProtocolError)


class ProtocolError(PlanhrcError):
    """Root of the client's errors: the service refused a request (4xx, `status` says which) or stayed
    unreachable after every retry."""

    def __init__(self, message: str, status: int | None = None) -> None:
        super().__init__(message)
        self.status = status


@dataclass(frozen=True)
class RetryPolicy:
    attempts: int = 10  # about 25 s in all: long enough for the KB service to restart
    initial_delay_s: float = 0.2
    factor: float = 2.0
    max_delay_s: float = 5.0

    def delays(self) -> list[float]:
        out, d = [], self.initial_delay_s
        for _ in range(self.attempts - 1):
            out.append(min(d, self.max_delay_s))
            d *= self.factor
        return out


@dataclass(frozen=True)
class Decision:
    """The service's answer to a perception (unknown keys are kept in `raw`)."""

    decision: DecisionKind
    plan_id: str | None
    next_action: dict[str, Any] | None
    matched_expected_step: int | None
    reason: str
    raw: dict[str, Any] = field(default_factory=dict, compare=False)
    help: list[dict[str, Any]] | None = None  # human_help_requested: [{"link", "to_deg", "sentence"}, ...]
    unseen_links: list[int] | None = None  # incomplete_perception: 1-based indices of the links not seen
    skill: dict[str, Any] | None = None  # robot_skill: {"name", "base_point_xy", "links", "sentence"}

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> "Decision":
        if "decision" not in data:
            raise ProtocolError("decision: missing from the service's answer")
        try:
            kind = DecisionKind(data["decision"])
        except ValueError:
            raise ProtocolError(f"decision: unknown kind {data['decision']!r} in the service's answer") from None
        return cls(
            decision=kind,
            plan_id=data.get("plan_id"),
            next_action=data.get("next_action"),
            matched_expected_step=data.get("matched_expected_step"),
            reason=str(data.get("reason", "")),
            raw=dict(data),
            help=data.get("help"),
            unseen_links=data.get("unseen_links"),
            skill=data.get("skill"),
        )


@dataclass(frozen=True)
class SparqlAnswer:
    media_type: str
    text: str
    rows: int  # solutions, triples, or 1 for ASK (the service's X-Result-Count)


class KBClient:
    """Calls of the KB service's cooperation API. Owns its `httpx.Client`; close it (or use `with`)."""

    def __init__(
        self,
        base_url: str,
        token: str | None = None,
        retry: RetryPolicy | None = None,
        timeout_s: float = 30.0,
        sleep: Callable[[float], None] = time.sleep,
        transport: httpx.BaseTransport | None = None,
    ) -> None:
        headers = {"Authorization": f"Bearer {token}"} if token else {}
        self._http = httpx.Client(base_url=base_url.rstrip("/"), headers=headers, timeout=timeout_s, transport=transport)
        self.retry = retry or RetryPolicy()
        self._sleep = sleep

    def close(self) -> None:
        self._http.close()

    def __enter__(self) -> "KBClient":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- transport with retries ------------------------------------------------------------------------------
    def _object(self, method: str, path: str, json: Any = None, idempotency_key: str | None = None
                ) -> dict[str, Any]:
        """`_request` for an answer that is a JSON object."""
        data = self._request(method, path, json, idempotency_key)
        if not isinstance(data, dict):
            raise ProtocolError(f"{method} {path}: expected a JSON object, got {type(data).__name__}")
        return data

    def _request(self, method: str, path: str, json: Any = None, idempotency_key: str | None = None) -> Any:
        headers = {"Idempotency-Key": idempotency_key} if idempotency_key else {}
        delays = self.retry.delays()
        for attempt in range(self.retry.attempts):
            try:
                response = self._http.request(method, path, json=json, headers=headers)
            except FINAL_TRANSPORT_ERRORS as exc:  # a bad URL stays bad: no retry
                raise ProtocolError(f"{method} {path}: cannot send to {self._http.base_url} "
                                    f"({type(exc).__name__}: {exc})") from None
            except httpx.TransportError as exc:  # connection refused, reset, timeout: the service may come back
                problem = f"{type(exc).__name__}: {exc}"
            else:
                if response.status_code < 400:
                    return response.json() if response.content else None
                if response.status_code < 500:
                    raise ProtocolError(f"{method} {path}: {response.status_code} {_detail(response)}", response.status_code)
                problem = f"{response.status_code} {_detail(response)}"
            if attempt < len(delays):
                log.warning("%s %s failed (%s); retry %d in %.1f s", method, path, problem, attempt + 1, delays[attempt])
                self._sleep(delays[attempt])
        raise ProtocolError(f"{method} {path}: gave up after {self.retry.attempts} attempts ({problem})")

    # -- the API ---------------------------------------------------------------------------------------------
    def create_object(self, name: str, links: int | Sequence[dict[str, Any]], orientations: int, formulation: str,
                      base_point_xy: Sequence[float] | None = None) -> dict[str, Any]:
        """Create an object; with `base_point_xy` ([x, y] metres) it is placed in the cell and checked geometrically."""
        body: dict[str, Any] = {"name": name, "links": links if isinstance(links, int) else list(links),
                                "orientations": orientations, "formulation": formulation}
        if base_point_xy is not None:
            body["base_point_xy"] = [float(v) for v in base_point_xy]
        return self._object("POST", "/objects", body)

    def set_goal(self, object_id: str, link_orientations_deg: Sequence[float] | None = None,
                 joint_angles_deg: Sequence[float | None] | None = None,
                 allow_infeasible: bool = False) -> dict[str, Any]:
        if (link_orientations_deg is None) == (joint_angles_deg is None):
            raise ProtocolError("goal: give exactly one of link_orientations_deg and joint_angles_deg")
        body: dict[str, Any] = (
            {"link_orientations_deg": list(link_orientations_deg)} if link_orientations_deg is not None
            else {"joint_angles_deg": list(joint_angles_deg or ())})
        if allow_infeasible:
            body["allow_infeasible"] = True
        return self._object("PUT", f"/objects/{object_id}/goal", body)

    def post_perception(self, object_id: str, link_orientations_deg: Sequence[float | None],
                        base_point_xy: Sequence[float] | None = None) -> Decision:
        """One perception (None = a link not seen), with the base point as measured ([x, y] metres) when known: a
        fresh idempotency key, reused by every retry of it."""
        key = str(uuid.uuid4())
        body: dict[str, Any] = {"link_orientations_deg": [None if v is None else float(v) for v in link_orientations_deg]}
        if base_point_xy is not None:
            body["base_point_xy"] = [float(v) for v in base_point_xy]
        return Decision.from_json(self._object("POST", f"/objects/{object_id}/perceptions", body, key))

    def next_action(self, object_id: str) -> dict[str, Any] | None:
        """Take the action to execute now (`POST /objects/{id}/actions/next`: the service marks it dispatched;
        asking again returns the same action), or None when there is none."""
        data: dict[str, Any] | None = self._request("POST", f"/objects/{object_id}/actions/next")
        return data

    def post_feedback(self, object_id: str, action_id: str, outcome: ActionOutcome | str,
                      message: str = "", reason: FailureReason | str | None = None,
                      measured_deg: float | None = None, refusal: dict[str, Any] | None = None,
                      hands_open: bool = False) -> dict[str, Any]:
        """Report the outcome of the dispatched action: succeeded, failed or partial, with why it failed (`reason`)
        and the turned link's measured orientation after release (`measured_deg`); for a turn refused before it
        moved, the geometric fact (`refusal`: code, link, against, distance_m, from_deg, base_point_xy); for a
        bimanual object, `hands_open` when the robot opened both hands after the action."""
        key = str(uuid.uuid4())
        body: dict[str, Any] = {"outcome": str(outcome)}
        if message:
            body["message"] = message
        if reason is not None:
            body["reason"] = str(reason)
        if measured_deg is not None:
            body["measured_deg"] = float(measured_deg)
        if refusal is not None:
            body["refusal"] = refusal
        if hands_open:
            body["hands_open"] = True
        return self._object("POST", f"/objects/{object_id}/actions/{action_id}/feedback", body, key)

    def give_up(self, object_id: str, reason: str, message: str) -> dict[str, Any]:
        """Tell the service the worker stopped working on the object (`reason` a short code, `message` a
        sentence); the service records it and answers `{"event_seq": ..., "decision": "human_help_requested",
        "reason": ..., "help": [...]}`: the help request the give-up became."""
        return self._object("POST", f"/objects/{object_id}/give-up", {"reason": reason, "message": message})

    def list_objects(self) -> list[dict[str, Any]]:
        return self._list("GET", "/objects")

    def read_object(self, object_id: str) -> dict[str, Any]:
        return self._object("GET", f"/objects/{object_id}")

    def read_plan(self, plan_id: str) -> dict[str, Any]:
        return self._object("GET", f"/plans/{plan_id}")

    def read_state(self, state_id: str) -> dict[str, Any]:
        return self._object("GET", f"/states/{state_id}")

    def read_events(self, object_id: str, after_seq: int = 0) -> list[dict[str, Any]]:
        """A page of the object's events after `after_seq` (decisions with their reasons), oldest first."""
        path = f"/objects/{object_id}/events" + (f"?after_seq={int(after_seq)}" if after_seq else "")
        return self._list("GET", path)

    def stream_events(self, object_id: str, after_seq: int = 0, timeout_s: float = 10.0) -> Iterator[dict[str, Any]]:
        """The object's events after `after_seq` as the service stores them (its Server-Sent Events stream), for
        up to `timeout_s` seconds; then the iterator ends and the caller goes on from the last `seq` it saw.
        Transport errors are not retried here: they raise ProtocolError, and the caller reconnects."""
        path = f"/objects/{object_id}/events/stream"
        params = {"after_seq": int(after_seq), "timeout_s": timeout_s}
        try:
            with self._http.stream("GET", path, params=params, timeout=timeout_s + 30.0) as response:
                if response.status_code >= 400:
                    response.read()
                    raise ProtocolError(f"GET {path}: {response.status_code} {_detail(response)}", response.status_code)
                for line in response.iter_lines():
                    if line.startswith("data:"):
                        event = json.loads(line[5:])
                        if not isinstance(event, dict):
                            raise ProtocolError(f"GET {path}: expected JSON objects, got {type(event).__name__}")
                        yield event
        except httpx.TransportError as exc:
            raise ProtocolError(f"GET {path}: {type(exc).__name__}: {exc}") from None

    def _list(self, method: str, path: str) -> list[dict[str, Any]]:
        """`_request` for a route that answers a JSON list of objects."""
        items = self._request(method, path)
        if not isinstance(items, list) or not all(isinstance(i, dict) for i in items):
            raise ProtocolError(f"{method} {path}: expected a JSON list of objects, got {type(items).__name__}")
        return items

    def health(self) -> dict[str, Any]:
        return self._object("GET", "/health")

    # -- the knowledge service -------------------------------------------------------------------------------
    def sparql(self, query: str, accept: str | None = None, default_graphs: Sequence[str] = (),
               named_graphs: Sequence[str] = ()) -> SparqlAnswer:
        """A SPARQL query (`POST /sparql`, a form): the answer in the format `accept` names. A query the service
        refuses (400) or stops at its time limit (503) raises ProtocolError with its message, without a retry: the
        same query would meet the same end."""
        form = {"query": query, "default-graph-uri": list(default_graphs), "named-graph-uri": list(named_graphs)}
        try:
            response = self._http.post("/sparql", data=form, headers={"Accept": accept} if accept else {})
        except httpx.TransportError as exc:
            raise ProtocolError(f"POST /sparql: {type(exc).__name__}: {exc}") from None
        if response.status_code >= 400:
            raise ProtocolError(f"POST /sparql: {response.status_code} {_detail(response)}", response.status_code)
        media = response.headers.get("content-type", "").split(";")[0].strip()
        return SparqlAnswer(media, response.text, int(response.headers.get("X-Result-Count", "0") or 0))

    def subsumption(self, state_id: str, by_state_id: str) -> dict[str, Any]:
        """Is D(state) ⊑ D(by)? `{"subsumed", "missing", "differs", ...}`."""
        return self._object("GET", f"/states/{quote(state_id, safe='')}/subsumed-by/{quote(by_state_id, safe='')}")

    def submit_reasoning(self, reasoner: str, object_id: str | None = None, scope: str | None = None
                         ) -> dict[str, Any]:
        """Start a reasoning job (`POST /reasoning`): its body, finished or not (`status`); follow an unfinished
        one with `read_reasoning`."""
        body: dict[str, Any] = {"reasoner": reasoner}
        if object_id is not None:
            body["object_id"] = object_id
        if scope is not None:
            body["scope"] = scope
        return self._object("POST", "/reasoning", body)

    def read_reasoning(self, job_id: str) -> dict[str, Any]:
        return self._object("GET", f"/reasoning/{quote(job_id, safe='')}")


def _detail(response: httpx.Response) -> str:
    try:
        data = response.json()
    except ValueError:
        return response.text[:200]
    return str(data.get("detail", data)) if isinstance(data, dict) else str(data)[:200]
