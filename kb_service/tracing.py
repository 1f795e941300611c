"""Traces (OpenTelemetry): one trace per request, through the route, the use case, the planning job (in the
service's planning pool or, through the PostgreSQL queue, in a `planhrc planning-worker` on any host), VAL and the
store.

Off unless asked: `planhrc serve --otlp-endpoint URL` (PLANHRC_OTLP_ENDPOINT), or OpenTelemetry's own variables
(OTEL_EXPORTER_OTLP_ENDPOINT, OTEL_EXPORTER_OTLP_TRACES_ENDPOINT, OTEL_TRACES_EXPORTER=otlp; OTEL_SDK_DISABLED=true
turns it off). Off, nothing of OpenTelemetry is imported and every span is `nullcontext()`. On, spans go in
batches over OTLP/HTTP (protobuf) to the endpoint, a collector's `/v1/traces` (the `tracing` extra).

Each process has its own `Tracing` (its own tracer provider; nothing global is set). A job handed to another
process carries its trace context as W3C `traceparent` text (`carrier`), from which the other process's span
continues the trace (`span(..., parent=carrier)`).
"""
from __future__ import annotations

import os
import random
from contextlib import AbstractContextManager, nullcontext
from typing import Any, Mapping

TRACES_PATH = "/v1/traces"


def tracing_wanted(endpoint: str | None) -> bool:
    """Whether this process should trace: an endpoint given, or OpenTelemetry's variables ask for OTLP."""
    env = os.environ
    if env.get("OTEL_SDK_DISABLED", "").strip().lower() == "true":
        return False
    exporter = env.get("OTEL_TRACES_EXPORTER", "").strip().lower()
    if exporter == "none":
        return False
    return bool(endpoint or env.get("OTEL_EXPORTER_OTLP_ENDPOINT") or env.get("OTEL_EXPORTER_OTLP_TRACES_ENDPOINT")
                or exporter == "otlp")


def traces_url(endpoint: str) -> str:
    """A collector's base URL (as OTEL_EXPORTER_OTLP_ENDPOINT names it) -> its traces URL."""
    endpoint = endpoint.rstrip("/")
    return endpoint if endpoint.endswith(TRACES_PATH) else endpoint + TRACES_PATH


class Tracing:
    """One process's spans: `Tracing.off()` or `Tracing.start(name, endpoint)`.

    A request is traced or not from its start (`span(..., server=True)`), before the SDK is asked: with `ratio`
    (`--trace-ratio`) a request without a trace context is traced with that chance, and whenever the sampler follows
    its parent's decision (ours does, as OpenTelemetry's default does), one whose client's `traceparent` says "not
    sampled" is not. A request not traced makes no span at all, neither for itself nor for its stages, and hands no
    trace context on (a job's span in another process needs a traced parent), so it costs nothing here."""

    def __init__(self, provider: Any = None, ratio: float | None = None) -> None:
        self._provider = provider
        self._ratio = ratio
        sampler = os.environ.get("OTEL_TRACES_SAMPLER", "").strip().lower()
        self._follows_parent = ratio is not None or not sampler or sampler.startswith("parentbased_")
        self._tracer = provider.get_tracer("planhrc") if provider is not None else None
        self._kinds: tuple[Any, Any] | None = None
        self._propagator: Any = None
        self._current: Any = None
        self.attach: Any = None
        self.detach: Any = None
        self.in_context: Any = None
        if provider is not None:  # what every span needs, looked up once
            from opentelemetry.context import attach, detach
            from opentelemetry.trace import SpanKind, get_current_span, set_span_in_context
            from opentelemetry.trace.propagation.tracecontext import TraceContextTextMapPropagator

            self._kinds = (SpanKind.INTERNAL, SpanKind.SERVER)
            self._propagator = TraceContextTextMapPropagator()
            self._current = get_current_span
            self.attach, self.detach, self.in_context = attach, detach, set_span_in_context

    @classmethod
    def off(cls) -> "Tracing":
        return cls(None)

    @classmethod
    def start(cls, service_name: str, endpoint: str | None, ratio: float | None = None) -> "Tracing":
        """On when `tracing_wanted(endpoint)`, else off. `ratio`: the share of traces started here that are
        recorded (a span whose parent was recorded always is); None: OTEL_TRACES_SAMPLER's, else all."""
        if not tracing_wanted(endpoint):
            return cls.off()
        from opentelemetry.exporter.otlp.proto.http.trace_exporter import OTLPSpanExporter
        from opentelemetry.sdk.resources import Resource
        from opentelemetry.sdk.trace import TracerProvider

        import planhrc

        from .otlp import span_processor

        resource = Resource.create({"service.name": os.environ.get("OTEL_SERVICE_NAME", service_name),
                                    "service.version": planhrc.__version__})
        sampler = None
        if ratio is not None:  # the share is drawn per request (`span`): what reaches the SDK is recorded
            from opentelemetry.sdk.trace.sampling import ALWAYS_ON, ParentBased

            sampler = ParentBased(ALWAYS_ON)
        provider = TracerProvider(resource=resource, sampler=sampler)
        exporter = OTLPSpanExporter(endpoint=traces_url(endpoint)) if endpoint else OTLPSpanExporter()
        provider.add_span_processor(span_processor(exporter))
        return cls(provider, ratio)

    @property
    def on(self) -> bool:
        return self._tracer is not None

    def span(self, name: str, attributes: Mapping[str, Any] | None = None, parent: Mapping[str, str] | None = None,
             server: bool = False) -> AbstractContextManager[Any]:
        """A span around a block: a request's (`server`, continuing a client's `parent` headers), or a stage's (the
        current span's child, or `parent`'s: a carrier from another process)."""
        if self._tracer is None:
            return _NOTHING
        assert self._kinds is not None
        if server:
            if not self._traced(parent):
                return _NOTHING
        elif not parent and not self._current().is_recording():
            return _NOTHING  # a stage of a request not traced, or a job handed on by one
        context = self._propagator.extract(parent) if parent else None
        return _Current(self, self._tracer, name, context, self._kinds[server], attributes)

    def _traced(self, headers: Mapping[str, str] | None) -> bool:
        """Whether a request with these headers is traced (see the class's note)."""
        header = headers.get("traceparent") if headers else None
        if header is not None and self._follows_parent:
            parts = header.strip().split("-")  # version-trace_id-parent_id-flags (W3C Trace Context)
            if len(parts) >= 4 and len(parts[1]) == 32 and len(parts[2]) == 16 and len(parts[3]) == 2:
                try:
                    return bool(int(parts[3], 16) & 1)
                except ValueError:
                    pass  # not a trace context: the request starts its own
        return self._ratio is None or random.random() < self._ratio

    def carrier(self) -> dict[str, str]:
        """The current trace context as W3C headers (empty when off or outside a span)."""
        if self._tracer is None:
            return {}
        carrier: dict[str, str] = {}
        self._propagator.inject(carrier)
        return carrier

    def flush(self, timeout_s: float = 2.0) -> None:
        if self._provider is not None:
            self._provider.force_flush(int(timeout_s * 1000))

    def close(self) -> None:
        """Send what is left and stop."""
        if self._provider is not None:
            self._provider.shutdown()


class _Current:
    """The span of a block, current inside it: what the SDK's `start_as_current_span` does (an exception leaving
    the block is recorded on the span and sets its status), without its generator-based context managers."""

    __slots__ = ("_tracing", "_tracer", "_name", "_context", "_kind", "_attributes", "_span", "_token")

    def __init__(self, tracing: Tracing, tracer: Any, name: str, context: Any, kind: Any,
                 attributes: Mapping[str, Any] | None) -> None:
        self._tracing, self._tracer, self._name, self._context, self._kind, self._attributes = \
            tracing, tracer, name, context, kind, attributes

    def __enter__(self) -> Any:
        tracing = self._tracing
        span = self._span = self._tracer.start_span(self._name, self._context, self._kind, self._attributes)
        self._token = tracing.attach(tracing.in_context(span))
        return span

    def __exit__(self, kind: type[BaseException] | None, error: BaseException | None, traceback: Any) -> None:
        span = self._span
        self._tracing.detach(self._token)
        if isinstance(error, Exception) and span.is_recording():  # as `use_span`: errors, not GeneratorExit & co.
            from opentelemetry.trace import Status, StatusCode

            span.record_exception(error)
            span.set_status(Status(StatusCode.ERROR, f"{type(error).__name__}: {error}"))
        span.end()


_NOTHING: AbstractContextManager[Any] = nullcontext()  # reusable: it keeps no state


def current_trace_id() -> str | None:
    """The current span's trace id (32 hex digits), None outside a span or when OpenTelemetry is not loaded."""
    import sys

    if "opentelemetry.trace" not in sys.modules:  # never imported: no span can be open
        return None
    from opentelemetry import trace

    context = trace.get_current_span().get_span_context()
    return format(context.trace_id, "032x") if context.is_valid else None


def set_attributes(span: Any, **attributes: Any) -> None:
    """Attributes on a span from `Tracing.span` (nothing when tracing is off)."""
    if span is not None:
        span.set_attributes({k: v for k, v in attributes.items() if v is not None})
