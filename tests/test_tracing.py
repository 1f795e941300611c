"""Tracing's own parts, in one process with OpenTelemetry's SDK (the `tracing` extra): the span of a block
(`Tracing.span`) behaves as the SDK's `start_as_current_span` (parents, the current span, an exception recorded),
a request not sampled makes no stage spans and hands on a context that says so, and `otlp.encode_spans` writes the
very message OpenTelemetry's own OTLP encoder builds (byte for byte), for spans with every kind of field, and the
service's batches reach a collector over OTLP/HTTP as that message. The spans of a real service, across
processes, are tests/test_observability.py's."""
from __future__ import annotations

import threading
import time
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import Any

import pytest

pytest.importorskip("opentelemetry.sdk", reason="tracing needs the `tracing` extra")

from opentelemetry.exporter.otlp.proto.common.trace_encoder import encode_spans as reference_encoding  # noqa: E402
from opentelemetry.exporter.otlp.proto.http.trace_exporter import OTLPSpanExporter  # noqa: E402
from opentelemetry.proto.collector.trace.v1.trace_service_pb2 import ExportTraceServiceRequest  # noqa: E402
from opentelemetry.sdk.resources import Resource  # noqa: E402
from opentelemetry.sdk.trace import SpanLimits, SpanProcessor, TracerProvider  # noqa: E402
from opentelemetry.sdk.trace.export import SimpleSpanProcessor  # noqa: E402
from opentelemetry.sdk.trace.export.in_memory_span_exporter import InMemorySpanExporter  # noqa: E402
from opentelemetry.sdk.trace.sampling import ALWAYS_ON, ParentBased, TraceIdRatioBased  # noqa: E402
from opentelemetry.trace import Link, SpanContext, SpanKind, Status, StatusCode, TraceFlags, TraceState  # noqa: E402

from planhrc.kb_service.otlp import SpanBatches, encode_spans, span_processor  # noqa: E402
from planhrc.kb_service.tracing import Tracing  # noqa: E402

SERVER_SPAN = "POST /objects/{object_id}/perceptions"


class Counted(SpanProcessor):
    """Counts the spans the SDK was asked to start (a span not recorded included)."""

    def __init__(self) -> None:
        self.started = 0

    def on_start(self, span: Any, parent_context: Any = None) -> None:
        self.started += 1


def kept(sampler: Any = None, ratio: float | None = None) -> tuple[Tracing, InMemorySpanExporter]:
    memory = InMemorySpanExporter()
    provider = TracerProvider(resource=Resource.create({"service.name": "planhrc-test", "service.version": "1"}),
                              sampler=sampler)
    provider.add_span_processor(SimpleSpanProcessor(memory))
    return Tracing(provider, ratio), memory


def request(tracing: Tracing, fail: bool = False, parent: dict[str, str] | None = None) -> None:
    """The spans of a re-planning perception, as the service makes them."""
    with tracing.span(SERVER_SPAN, {"http.request.method": "POST", "http.route": "/objects/{object_id}/perceptions",
                                    "planhrc.request_id": "r-1"}, parent=parent, server=True) as root:
        with tracing.span("perceive", {"object_id": "obj-1"}) as perceive:
            with tracing.span("plan"):
                pass
            with tracing.span("val"), tracing.span("store"):
                if fail:
                    raise RuntimeError("the store is away")
            if perceive is not None:
                perceive.set_attribute("decision", "replan")
        if root is not None:
            root.set_attributes({"http.response.status_code": 200})


def test_a_block_s_span_is_current_inside_it_and_a_child_of_the_span_around_it():
    tracing, memory = kept()
    request(tracing)
    spans = {s.name: s for s in memory.get_finished_spans()}
    assert set(spans) == {SERVER_SPAN, "perceive", "plan", "val", "store"}
    parent_of = {name: s.parent.span_id if s.parent else None for name, s in spans.items()}
    ids = {s.context.span_id: name for name, s in spans.items()}
    assert parent_of[SERVER_SPAN] is None and spans[SERVER_SPAN].kind is SpanKind.SERVER
    assert {name: ids.get(p) for name, p in parent_of.items() if p} == {
        "perceive": SERVER_SPAN, "plan": "perceive", "val": "perceive", "store": "val"}
    assert len({s.context.trace_id for s in spans.values()}) == 1
    assert spans["perceive"].attributes["decision"] == "replan"
    assert spans[SERVER_SPAN].attributes["http.response.status_code"] == 200
    assert tracing.carrier() == {}  # outside every block: nothing is current any more


def test_an_exception_leaving_a_block_is_recorded_on_every_span_it_leaves():
    tracing, memory = kept()
    with pytest.raises(RuntimeError):
        request(tracing, fail=True)
    spans = {s.name: s for s in memory.get_finished_spans()}
    for name in ("store", "val", "perceive", SERVER_SPAN):
        assert spans[name].status.status_code is StatusCode.ERROR, name
        assert spans[name].status.description == "RuntimeError: the store is away"
        assert [e.name for e in spans[name].events] == ["exception"]
    assert spans["plan"].status.status_code is StatusCode.UNSET and not spans["plan"].events


def test_a_request_not_sampled_makes_no_stage_span_and_says_so_to_the_next_process():
    tracing, memory = kept(ParentBased(TraceIdRatioBased(0.0)))
    carriers = []
    with tracing.span(SERVER_SPAN, server=True):
        with tracing.span("perceive") as perceive:
            assert perceive is None  # nothing is made for it
            carriers.append(tracing.carrier())
    assert memory.get_finished_spans() == ()
    flags = int(carriers[0]["traceparent"].rsplit("-", 1)[1], 16)
    assert not flags & 1  # not sampled: a worker's span of the job is not either
    # a client's sampled trace is followed all the same
    request(tracing, parent={"traceparent": "00-0af7651916cd43dd8448eb211c80319c-b7ad6b7169203331-01"})
    spans = memory.get_finished_spans()
    assert len(spans) == 5 and {format(s.context.trace_id, "032x") for s in spans} == {
        "0af7651916cd43dd8448eb211c80319c"}


def test_with_a_ratio_a_request_is_traced_or_not_before_the_sdk_is_asked():
    """`--trace-ratio`: the requests not drawn, and those whose client's context says "not sampled", make no span of
    any kind (the SDK is not asked) and hand no context on; a client's sampled context is always followed."""
    memory = InMemorySpanExporter()
    started = Counted()
    provider = TracerProvider(sampler=ParentBased(ALWAYS_ON))
    provider.add_span_processor(started)
    provider.add_span_processor(SimpleSpanProcessor(memory))
    never, half = Tracing(provider, 0.0), Tracing(provider, 0.5)
    for _ in range(20):
        with never.span(SERVER_SPAN, server=True) as root, never.span("perceive") as stage:
            assert root is None and stage is None and never.carrier() == {}
    assert started.started == 0
    unsampled = {"traceparent": "00-0af7651916cd43dd8448eb211c80319c-b7ad6b7169203331-00"}
    request(Tracing(provider, 1.0), parent=unsampled)
    assert started.started == 0
    request(never, parent={"traceparent": "00-0af7651916cd43dd8448eb211c80319c-b7ad6b7169203331-01"})
    request(never, parent={"traceparent": "not a trace context"})  # a request of its own: not drawn
    assert started.started == 5 and len(memory.get_finished_spans()) == 5
    for _ in range(400):
        request(half)
    traced = (len(memory.get_finished_spans()) - 5) // 5
    assert 120 < traced < 280  # about half of 400 (the chance of leaving this band is below 1e-9)
    assert started.started == 5 + 5 * traced


def test_a_job_handed_on_continues_its_request_s_trace_and_one_of_a_request_not_traced_makes_none():
    """A planning job carries `carrier()` to another process (the planning pool, the PostgreSQL queue's worker),
    whose `planning_job` span continues the request's trace; a job of a request not traced carries nothing and
    makes no span there (the other process's sampler would have started a trace of its own)."""
    provider = TracerProvider(sampler=ParentBased(ALWAYS_ON))
    worker, worker_spans = kept()
    carriers = []
    for service in (Tracing(provider, 1.0), Tracing(provider, 0.0)):
        with service.span(SERVER_SPAN, server=True) as root, service.span("plan"):
            carriers.append((root, service.carrier()))
    (root, carrier), (untraced, nothing) = carriers
    assert untraced is None and nothing == {}
    for handed in (carrier, nothing):
        with worker.span("planning_job", {"queue": "pool"}, parent=handed):
            pass
    [job] = worker_spans.get_finished_spans()
    assert job.context.trace_id == root.get_span_context().trace_id and job.parent.is_remote


def every_kind_of_span() -> list[Any]:
    """Spans with every field OTLP has: attributes of each type, events, links, a remote parent, a trace state,
    statuses, counts of what the limits dropped, two instrumentation scopes."""
    memory = InMemorySpanExporter()
    provider = TracerProvider(resource=Resource.create({"service.name": "planhrc-test", "n": 3},
                                                       schema_url="https://opentelemetry.io/schemas/1.21.0"),
                              span_limits=SpanLimits(max_span_attributes=12, max_events=1, max_links=1))
    provider.add_span_processor(SimpleSpanProcessor(memory))
    tracer = provider.get_tracer("planhrc")
    other = provider.get_tracer("other", "2.0", schema_url="https://example.org/s", attributes={"scope.k": "v"})
    remote = SpanContext(0x0AF7651916CD43DD8448EB211C80319C, 0xB7AD6B7169203331, is_remote=True,
                         trace_flags=TraceFlags(1), trace_state=TraceState([("vendor", "x1"), ("b", "2")]))
    from opentelemetry.trace import NonRecordingSpan, set_span_in_context

    attributes = {"s": "text é", "b": True, "f": False, "i": 7, "neg": -5, "big": 2**62, "d": 0.25, "e": "",
                  "zero": 0, "strings": ("a", "b"), "ints": (1, -2), "floats": (1.5,), "bools": (True, False)}
    with tracer.start_as_current_span("root", kind=SpanKind.SERVER, attributes=attributes,
                                      context=set_span_in_context(NonRecordingSpan(remote))) as root:
        root.add_event("something", {"k": 1})
        root.add_event("bare")
        with other.start_as_current_span("child", kind=SpanKind.CLIENT,
                                         links=[Link(remote, {"why": "retry"}), Link(remote)]) as child:
            child.set_status(Status(StatusCode.OK))
        try:
            with tracer.start_as_current_span("fails", kind=SpanKind.PRODUCER):
                raise ValueError("bad")
        except ValueError:
            pass
    for kind in (SpanKind.CONSUMER, SpanKind.INTERNAL):
        tracer.start_span(f"alone {kind.name}", kind=kind).end()
    return list(memory.get_finished_spans())


def test_our_encoding_is_the_message_opentelemetry_s_encoder_builds():
    spans = every_kind_of_span()
    ours = ExportTraceServiceRequest.FromString(encode_spans(spans))
    theirs = reference_encoding(spans)
    assert ours == theirs
    assert encode_spans(spans) == theirs.SerializeToString()  # byte for byte: fields written in the same order
    written = [span for r in ours.resource_spans for s in r.scope_spans for span in s.spans]
    assert len(written) == len(spans) == 5
    root = next(span for span in written if span.name == "root")
    assert (root.dropped_attributes_count, root.dropped_events_count) == (1, 1)  # over the limits
    assert next(span for span in written if span.name == "child").dropped_links_count == 1
    assert encode_spans([]) == b""


def test_batches_of_encoded_spans_reach_a_collector_over_otlp_http(monkeypatch):
    """The service's processor (`span_processor` over OpenTelemetry's OTLP/HTTP exporter: the pinned version has
    the client it posts with): a batch sent when full, the rest when flushed, each the message OpenTelemetry's
    encoder builds for the same spans; at shutdown nothing more is accepted."""
    bodies: list[bytes] = []

    class Collector(BaseHTTPRequestHandler):
        def do_POST(self) -> None:  # noqa: N802 (the handler's name)
            if self.headers["Content-Type"] == "application/x-protobuf":
                bodies.append(self.rfile.read(int(self.headers["Content-Length"])))
            self.send_response(200)
            self.send_header("Content-Length", "0")
            self.end_headers()

        def log_message(self, *args: Any) -> None:
            pass

    monkeypatch.setenv("OTEL_BSP_MAX_EXPORT_BATCH_SIZE", "5")
    monkeypatch.setenv("OTEL_BSP_SCHEDULE_DELAY", "60000")  # only a full batch or a flush sends
    server = ThreadingHTTPServer(("127.0.0.1", 0), Collector)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    try:
        processor = span_processor(OTLPSpanExporter(endpoint=f"http://127.0.0.1:{server.server_address[1]}/v1/traces"))
        assert isinstance(processor, SpanBatches)
        memory = InMemorySpanExporter()
        provider = TracerProvider(resource=Resource.create({"service.name": "planhrc-test"}))
        provider.add_span_processor(processor)
        provider.add_span_processor(SimpleSpanProcessor(memory))
        tracing = Tracing(provider)
        request(tracing)  # five spans: a full batch
        deadline = time.monotonic() + 30
        while not bodies and time.monotonic() < deadline:
            time.sleep(0.05)
        assert len(bodies) == 1
        with tracing.span(SERVER_SPAN, server=True), tracing.span("perceive"):
            pass
        assert len(bodies) == 1  # two spans wait for their batch
        tracing.flush()
        assert len(bodies) == 2
        tracing.close()
        with tracing.span(SERVER_SPAN, server=True):
            pass
        assert processor.force_flush() and len(bodies) == 2  # closed: nothing more taken
    finally:
        server.shutdown()
        server.server_close()
    spans = memory.get_finished_spans()
    assert [ExportTraceServiceRequest.FromString(b) for b in bodies] == [reference_encoding(spans[:5]),
                                                                          reference_encoding(spans[5:7])]
