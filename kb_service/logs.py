"""The service's log lines: text (`%(asctime)s %(levelname)s %(name)s: %(message)s`) or, with `--log-format json`,
one JSON object a line, each with the request it belongs to (`request_id`, `object_id`: `observe`) and the trace's
id (`trace_id`) when the line was written inside a request or a traced job."""
from __future__ import annotations

import json
import logging
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass
from datetime import datetime, timezone
from typing import Iterator

from .tracing import current_trace_id

TEXT_FORMAT = "%(asctime)s %(levelname)s %(name)s: %(message)s"
LOG_FORMATS = ("text", "json")


@dataclass(frozen=True)
class RequestLabels:
    request_id: str
    object_id: str | None = None


_REQUEST: ContextVar[RequestLabels | None] = ContextVar("planhrc_request", default=None)


@contextmanager
def labelled(labels: RequestLabels) -> Iterator[None]:
    """Log lines written inside the block (the request's task and the thread pool's calls it makes) carry `labels`."""
    token = _REQUEST.set(labels)
    try:
        yield
    finally:
        _REQUEST.reset(token)


class JsonFormatter(logging.Formatter):
    """A record as one JSON line: time, level, logger, message, the request's labels and the trace id."""

    def format(self, record: logging.LogRecord) -> str:
        when = datetime.fromtimestamp(record.created, tz=timezone.utc).isoformat(timespec="milliseconds")
        line: dict[str, object] = {"time": when, "level": record.levelname.lower(), "logger": record.name,
                                   "message": record.getMessage()}
        labels = _REQUEST.get()
        if labels is not None:
            line["request_id"] = labels.request_id
            if labels.object_id is not None:
                line["object_id"] = labels.object_id
        trace_id = current_trace_id()
        if trace_id is not None:
            line["trace_id"] = trace_id
        if record.exc_info:
            line["exception"] = self.formatException(record.exc_info)
        return json.dumps(line, ensure_ascii=False)


def configure_logging(level: str, log_format: str) -> None:
    """The root logger's handler for the process: text or JSON lines on standard error (uvicorn's loggers too)."""
    handler = logging.StreamHandler()
    handler.setFormatter(JsonFormatter() if log_format == "json" else logging.Formatter(TEXT_FORMAT))
    root = logging.getLogger()
    root.handlers[:] = [handler]
    root.setLevel(logging.DEBUG if level == "trace" else level.upper())
    if log_format == "json":  # uvicorn's own loggers write through the root's handler, as JSON too
        for name in ("uvicorn", "uvicorn.error", "uvicorn.access"):
            logger = logging.getLogger(name)
            logger.handlers[:] = []
            logger.propagate = True
