"""Spans in OTLP's protobuf, and the batches that send them.

`encode_spans` writes finished spans straight to the bytes of OTLP's message (the `ExportTraceServiceRequest`
OpenTelemetry's own encoder builds, byte for byte: tests/test_tracing.py compares them), without a protobuf object
per span, attribute and value on the way: about half the encoder's cost. `SpanBatches` sends them in batches, as
the SDK's `BatchSpanProcessor` does. Imported only when tracing is on (the `tracing` extra).

The message, by field number (opentelemetry-proto's trace.proto, common.proto, resource.proto):
ExportTraceServiceRequest{1 resource_spans} ResourceSpans{1 resource, 2 scope_spans, 3 schema_url}
Resource{1 attributes, 2 dropped_attributes_count} ScopeSpans{1 scope, 2 spans, 3 schema_url}
InstrumentationScope{1 name, 2 version, 3 attributes, 4 dropped_attributes_count}
Span{1 trace_id, 2 span_id, 3 trace_state, 4 parent_span_id, 5 name, 6 kind, 7 start (fixed64), 8 end (fixed64),
9 attributes, 10 dropped_attributes_count, 11 events, 12 dropped_events_count, 13 links, 14 dropped_links_count,
15 status, 16 flags (fixed32)} Event{1 time (fixed64), 2 name, 3 attributes, 4 dropped_attributes_count}
Link{1 trace_id, 2 span_id, 3 trace_state, 4 attributes, 5 dropped_attributes_count, 6 flags (fixed32)}
Status{2 message, 3 code} KeyValue{1 key, 2 value} AnyValue{1 string, 2 bool, 3 int, 4 double, 5 array, 6 kvlist,
7 bytes} ArrayValue{1 values} KeyValueList{1 values}.
"""
from __future__ import annotations

import logging
import os
import struct
import threading
import weakref
from collections.abc import Mapping, Sequence
from typing import Any

from opentelemetry.exporter.otlp.proto.http.trace_exporter import OTLPSpanExporter
from opentelemetry.sdk.trace import ReadableSpan, SpanProcessor
from opentelemetry.sdk.trace.export import BatchSpanProcessor

log = logging.getLogger(__name__)

_FIXED64 = struct.Struct("<Q").pack
_FIXED32 = struct.Struct("<I").pack
_DOUBLE = struct.Struct("<d").pack
_SMALL = tuple(bytes((n,)) for n in range(128))
# Span.flags: the parent's remoteness is known (always), and whether it was remote (SpanFlags)
_HAS_IS_REMOTE, _IS_REMOTE = 0x100, 0x200


def _varint(n: int) -> bytes:
    if 0 <= n < 128:
        return _SMALL[n]
    if n < 0:
        n += 1 << 64  # int64 as protobuf writes it: two's complement, ten bytes
    out = bytearray()
    while n > 0x7F:
        out.append((n & 0x7F) | 0x80)
        n >>= 7
    out.append(n)
    return bytes(out)


def _field(tag: bytes, payload: bytes) -> bytes:
    """A length-delimited field (a string, bytes or a message) with its tag."""
    return tag + _varint(len(payload)) + payload


def _value(value: Any) -> bytes:
    """An AnyValue's content."""
    if value is None:
        return b""
    if isinstance(value, bool):
        return b"\x10\x01" if value else b"\x10\x00"
    if isinstance(value, str):
        return _field(b"\x0a", value.encode())
    if isinstance(value, int):
        return b"\x18" + _varint(value)
    if isinstance(value, float):
        return b"\x21" + _DOUBLE(value)
    if isinstance(value, bytes):
        return _field(b"\x3a", value)
    if isinstance(value, Sequence):
        return _field(b"\x2a", b"".join(_field(b"\x0a", _value(v)) for v in value))
    if isinstance(value, Mapping):
        return _field(b"\x32", b"".join(_field(b"\x0a", _key_value(str(k), v)) for k, v in value.items()))
    raise TypeError(f"a span attribute of type {type(value).__name__}")


def _key_value(key: str, value: Any) -> bytes:
    return _field(b"\x0a", key.encode()) + _field(b"\x12", _value(value))


def _attributes(tag: bytes, attributes: Mapping[str, Any] | None) -> bytes:
    """Repeated KeyValue fields (an attribute that cannot be written is left out, as OpenTelemetry's encoder does)."""
    if not attributes:
        return b""
    out = []
    for key, value in attributes.items():
        try:
            out.append(_field(tag, _key_value(key, value)))
        except (TypeError, UnicodeError) as exc:
            log.warning("span attribute %s left out: %s", key, exc)
    return b"".join(out)


def _count(tag: bytes, n: int) -> bytes:
    return tag + _varint(n) if n else b""


def _string(tag: bytes, text: str | None) -> bytes:
    return _field(tag, text.encode()) if text else b""


def _flags(parent: Any) -> int:
    return _HAS_IS_REMOTE | _IS_REMOTE if parent is not None and parent.is_remote else _HAS_IS_REMOTE


def _trace_state(state: Any) -> str | None:
    return ",".join(f"{k}={v}" for k, v in state.items()) if state else None


def _span(span: Any) -> bytes:
    context, parent, status = span.context, span.parent, span.status
    out = [b"\x0a\x10", context.trace_id.to_bytes(16, "big"), b"\x12\x08", context.span_id.to_bytes(8, "big"),
           _string(b"\x1a", _trace_state(context.trace_state))]
    if parent is not None:
        out += (b"\x22\x08", parent.span_id.to_bytes(8, "big"))
    out += (_string(b"\x2a", span.name), _count(b"\x30", span.kind.value + 1),  # SpanKind counts from 0, OTLP's from 1
            b"\x39", _FIXED64(span.start_time or 0), b"\x41", _FIXED64(span.end_time or 0),
            _attributes(b"\x4a", span.attributes), _count(b"\x50", span.dropped_attributes))
    for event in span.events:
        out.append(_field(b"\x5a", b"\x09" + _FIXED64(event.timestamp) + _string(b"\x12", event.name)
                          + _attributes(b"\x1a", event.attributes) + _count(b"\x20", event.dropped_attributes)))
    out.append(_count(b"\x60", span.dropped_events))
    for link in span.links:
        out.append(_field(b"\x6a", b"\x0a\x10" + link.context.trace_id.to_bytes(16, "big") + b"\x12\x08"
                          + link.context.span_id.to_bytes(8, "big") + _attributes(b"\x22", link.attributes)
                          + _count(b"\x28", link.dropped_attributes) + b"\x35" + _FIXED32(_flags(link.context))))
    out.append(_count(b"\x70", span.dropped_links))
    if status is not None:
        out.append(_field(b"\x7a", _string(b"\x12", status.description) + _count(b"\x18", status.status_code.value)))
    out += (b"\x85\x01", _FIXED32(_flags(parent)))
    return b"".join(out)


def _scope(scope: Any) -> bytes:
    if scope is None:
        return b""
    return (_string(b"\x0a", scope.name) + _string(b"\x12", scope.version)
            + _attributes(b"\x1a", scope.attributes))


def encode_spans(spans: Sequence[Any]) -> bytes:
    """Finished spans (the SDK's `ReadableSpan`s) as one serialized `ExportTraceServiceRequest`, grouped by their
    resource and instrumentation scope (one each in a process of ours: found by identity, not hashed per span)."""
    groups: dict[tuple[int, int], tuple[Any, Any, list[bytes]]] = {}
    for span in spans:
        resource, scope = span.resource, span.instrumentation_scope
        key = (id(resource), id(scope))
        group = groups.get(key)
        if group is None:
            group = groups[key] = (resource, scope, [])
        group[2].append(_field(b"\x12", _span(span)))
    by_resource: dict[int, tuple[Any, list[bytes]]] = {}
    for resource, scope, encoded in groups.values():
        scopes = by_resource.setdefault(id(resource), (resource, []))[1]
        scopes.append(_field(b"\x12", _field(b"\x0a", _scope(scope)) + b"".join(encoded)
                             + _string(b"\x1a", scope.schema_url if scope is not None else None)))
    return b"".join(_field(b"\x0a", _field(b"\x0a", _attributes(b"\x0a", resource.attributes)) + b"".join(scopes)
                           + _string(b"\x1a", resource.schema_url)) for resource, scopes in by_resource.values())


class SpanBatches(SpanProcessor):
    """A batching span processor, as the SDK's `BatchSpanProcessor` (OTEL_BSP_SCHEDULE_DELAY, _MAX_EXPORT_BATCH_SIZE,
    _MAX_QUEUE_SIZE), whose thread writes each batch with `encode_spans` and posts it with OpenTelemetry's own
    OTLP/HTTP exporter's client (its endpoint, headers, compression, timeout and retries). A finished span costs
    the request that made it an append; its batch is written at once, in one loop, where the encoder's code and
    data stay in the processor's caches (in a request, between the service's own work, writing one span took the
    service about twice as long)."""

    def __init__(self, exporter: OTLPSpanExporter) -> None:
        self._exporter = exporter
        self._send = exporter._client.export  # noqa: SLF001 (see `span_processor`)
        environ = os.environ
        self._delay_s = _setting(environ, "OTEL_BSP_SCHEDULE_DELAY", 5000) / 1000
        self._batch = _setting(environ, "OTEL_BSP_MAX_EXPORT_BATCH_SIZE", 512)
        self._limit = max(_setting(environ, "OTEL_BSP_MAX_QUEUE_SIZE", 2048), self._batch)
        self._lock = threading.Lock()
        self._wake = threading.Event()
        self._spans: list[ReadableSpan] = []
        self._dropped = 0
        self._thread: threading.Thread | None = None
        self._closed = False
        forget = weakref.WeakMethod(self._forget)  # the registration outlives this processor: it must not keep it
        os.register_at_fork(after_in_child=lambda: _call(forget))

    def on_end(self, span: ReadableSpan) -> None:
        if self._closed or not span.context.trace_flags.sampled:
            return
        with self._lock:
            spans = self._spans
            if len(spans) >= self._limit:
                self._dropped += 1
                return
            spans.append(span)
            full = len(spans) >= self._batch
            if self._thread is None:
                self._thread = threading.Thread(target=self._run, name="planhrc-span-export", daemon=True)
                self._thread.start()
        if full:
            self._wake.set()

    def _run(self) -> None:
        while not self._closed:
            self._wake.wait(self._delay_s)
            self._wake.clear()
            self._export()

    def _export(self) -> bool:
        with self._lock:
            spans, self._spans = self._spans, []
            dropped, self._dropped = self._dropped, 0
        if dropped:
            log.warning("%d spans dropped: more than %d waited to be exported", dropped, self._limit)
        if not spans:
            return True
        try:
            return bool(self._send(encode_spans(spans)).success)
        except Exception as exc:  # the exporter's thread goes on; the batch is lost, as the SDK's would be
            log.warning("spans not exported: %s", exc)
            return False

    def force_flush(self, timeout_millis: int = 30000) -> bool:
        return self._export()

    def shutdown(self) -> None:
        self._closed = True
        self._wake.set()
        if self._thread is not None:
            self._thread.join(timeout=10)
        self._export()
        self._exporter.shutdown()  # type: ignore[no-untyped-call]

    def _forget(self) -> None:
        """In a child this process forked: no thread, no lock held, nothing of the parent's to send."""
        self._lock = threading.Lock()
        self._wake = threading.Event()
        self._spans, self._thread = [], None


def _call(method: weakref.WeakMethod[Any]) -> None:
    bound = method()
    if bound is not None:
        bound()


def _setting(environ: Mapping[str, str], name: str, default: int) -> int:
    try:
        value = int(environ.get(name, default))
    except ValueError:
        log.warning("%s is not a whole number: %d is used", name, default)
        return default
    return value if value > 0 else default


def span_processor(exporter: OTLPSpanExporter) -> SpanProcessor:
    """`SpanBatches` over the exporter's HTTP client; should a version of the exporter no longer have that client
    (a private part: tests/test_tracing.py checks the pinned version has it), the SDK's batches and encoding."""
    if callable(getattr(getattr(exporter, "_client", None), "export", None)):
        return SpanBatches(exporter)
    log.warning("OTLP exporter without its HTTP client: spans are encoded by OpenTelemetry's encoder")
    return BatchSpanProcessor(exporter)
