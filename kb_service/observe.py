"""Watching the service: the outermost ASGI middleware (`Observe`) and the use cases' observer (`Observation`).

Every request gets a request id (the client's `X-Request-ID` when it sends a sensible one, else a new one; sent
back in the answer), the labels its log lines carry (`logs`), a server span continuing the client's `traceparent`
when tracing is on (`tracing`), and, when metrics are on, its count and time by route template and status
(`metrics`). It sits outside the guard, so refusals (401, 403, 413) are counted and traced too.
"""
from __future__ import annotations

import re
import time
import uuid
from contextlib import AbstractContextManager
from typing import Any, Mapping

from .guard import ASGIApp, HttpMiddleware, Message, Receive, Scope, Send, route_of
from .logs import RequestLabels, labelled
from .metrics import ServiceMetrics
from .tracing import Tracing, set_attributes

REQUEST_ID = re.compile(r"^[A-Za-z0-9._:-]{1,64}$")
OBJECT_PATH = re.compile(r"^/objects/([^/]+)")
UNMATCHED = "(unmatched)"  # the route label of a request no route takes: one series, not one per path


class Observation:
    """The use cases' observer (`usecases.Observer`): metrics (None: off) and spans."""

    def __init__(self, metrics: ServiceMetrics | None, tracing: Tracing) -> None:
        self.metrics = metrics
        self.tracing = tracing

    def decided(self, kind: str, timings: Mapping[str, float] | None) -> None:
        if self.metrics is not None:
            self.metrics.decided(kind, timings)

    def validated(self, accepted: bool, seconds: float, cpu_s: float | None) -> None:
        if self.metrics is not None:
            self.metrics.validated(accepted, seconds, cpu_s)

    def stored(self, seconds: float, replanned: bool) -> None:
        if self.metrics is not None:
            self.metrics.stored(seconds, replanned)

    def span(self, name: str, **attributes: Any) -> AbstractContextManager[Any]:
        return self.tracing.span(name, attributes)

    def carrier(self) -> dict[str, str]:
        return self.tracing.carrier()


class Observe(HttpMiddleware):
    """ASGI middleware: request id, log labels, the request's span and its metrics."""

    def __init__(self, app: ASGIApp, observation: Observation) -> None:
        super().__init__(app)
        self.observation = observation

    async def http(self, scope: Scope, receive: Receive, send: Send, headers: dict[str, str]) -> None:
        started = time.perf_counter()
        method = scope.get("method", "GET").upper()
        path = scope.get("path", "/")
        given = headers.get("x-request-id", "")
        request_id = given if REQUEST_ID.match(given) else uuid.uuid4().hex[:16]
        found = OBJECT_PATH.match(path)
        route = route_of(scope)
        template = route[0] if route is not None else UNMATCHED
        status = 500
        metrics, tracing = self.observation.metrics, self.observation.tracing
        answered: float | None = None

        async def sending(message: Message) -> None:
            nonlocal status, answered
            if message["type"] == "http.response.start":
                status = int(message["status"])
                answered = time.perf_counter()
                message.setdefault("headers", [])
                message["headers"] = [*message["headers"], (b"x-request-id", request_id.encode())]
            await send(message)

        parent = {"traceparent": headers["traceparent"]} if tracing.on and "traceparent" in headers else None
        with labelled(RequestLabels(request_id, found.group(1) if found else None)), \
                tracing.span(f"{method} {template}", {"http.request.method": method, "http.route": template,
                                                     "planhrc.request_id": request_id}, parent=parent,
                             server=True) as span:
            try:
                await self.app(scope, receive, sending)
            finally:
                set_attributes(span, **{"http.response.status_code": status})
                if metrics is not None:
                    end = answered if answered is not None else time.perf_counter()
                    metrics.answered(template, method, status, end - started)
