"""What the use cases tell whoever watches the service (`Observer`): the decisions taken with their stage times,
VAL's verdicts, the writes' times, and spans around their stages. The service's observer (`observe.Observation`)
turns them into Prometheus metrics and OpenTelemetry spans; `QUIET` ignores them (tests, the command line)."""
from __future__ import annotations

from contextlib import AbstractContextManager, nullcontext
from typing import Any, Mapping, Protocol


class Observer(Protocol):
    def decided(self, kind: str, timings: Mapping[str, float] | None) -> None:
        """A perception was decided (`kind`), with its re-plan's stage times when it re-planned."""

    def validated(self, accepted: bool, seconds: float, cpu_s: float | None) -> None:
        """VAL's verdict on a new plan or on a piece of one: its time, and the CPU of its VAL runs (None: not
        known)."""

    def stored(self, seconds: float, replanned: bool) -> None:
        """A perception's write took `seconds` (a re-plan's write: `replanned`)."""

    def span(self, name: str, **attributes: Any) -> AbstractContextManager[Any]:
        """A span around a stage (the request's trace)."""

    def carrier(self) -> dict[str, str]:
        """The current trace context, for a job handed to another process."""


class _Quiet:
    def decided(self, kind: str, timings: Mapping[str, float] | None) -> None:
        pass

    def validated(self, accepted: bool, seconds: float, cpu_s: float | None) -> None:
        pass

    def stored(self, seconds: float, replanned: bool) -> None:
        pass

    def span(self, name: str, **attributes: Any) -> AbstractContextManager[Any]:
        return nullcontext()

    def carrier(self) -> dict[str, str]:
        return {}


QUIET: Observer = _Quiet()
