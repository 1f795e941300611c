"""Who is acting: the client whose request is being served, as the request guard (`guard`) names it, so that every
event the request leads to records it (`StoredEvent.client`). A context variable: each request's task (and the
thread pool's call it makes, which copies the context) sees its own; a thread of the service's own (VAL's checks
behind an answer) sees None."""
from __future__ import annotations

from contextlib import contextmanager
from contextvars import ContextVar
from typing import Iterator

_ACTING: ContextVar[str | None] = ContextVar("planhrc_acting_client", default=None)


def acting_client() -> str | None:
    return _ACTING.get()


@contextmanager
def acting_as(client: str | None) -> Iterator[None]:
    """Events written inside the block name `client`."""
    token = _ACTING.set(client)
    try:
        yield
    finally:
        _ACTING.reset(token)
