"""The service's front door: untrusted input costs nothing before it is trusted.

A pure ASGI middleware, in front of FastAPI's routing and body parsing:

1. the client is found from the headers alone, before one byte of the body is read: `Authorization: Bearer <key>`
   names a client of the store's registry (`clients`), or the `--token` shortcut's. What the route allows is the
   route's own declaration (`access`, one of `READ`, `OPEN` or a role), taken from the OpenAPI extension
   `x-planhrc-access` every route of the document carries (`check_routes` refuses to build an app with a route
   that has none): a route for a role answers 401 without a key and 403, naming the role it needs, to a client
   of another role; a read needs a key only with `protect_reads`; an open route (the health probes, the docs and
   the console's static page) never does. A service with no key at all and no token is open, as it was before
   clients;
2. a `Content-Length` over the limit is answered 413 without reading the body;
3. a body without a length (chunked) is read only up to the limit, and cut there with 413.

Refusals are JSON `{"detail": "..."}` like every other error of the service, and store nothing. The request then
runs as its client (`store.acting.acting_as`): every event it leads to records the client's name.
"""
from __future__ import annotations

from abc import ABC, abstractmethod
import json
import logging
from dataclasses import dataclass
from typing import Any, Awaitable, Callable, Iterable, MutableMapping

import anyio
from starlette.routing import BaseRoute, Match, Route

from .clients import Client, ClientRegistry, Role
from .store.acting import acting_as
from .store.errors import UnavailableError

log = logging.getLogger(__name__)

Scope = MutableMapping[str, Any]
Message = MutableMapping[str, Any]
Receive = Callable[[], Awaitable[Message]]
Send = Callable[[Message], Awaitable[None]]
ASGIApp = Callable[[Scope, Receive, Send], Awaitable[None]]

READ_METHODS = frozenset({"GET", "HEAD", "OPTIONS"})
ACCESS = "x-planhrc-access"  # the OpenAPI extension naming what a route allows
READ, OPEN = "read", "open"
ROUTE_KEY = "planhrc.route"  # where the scope keeps the matched route's (path template, access)


def access(what: Role | str) -> dict[str, Any]:
    """A route's `openapi_extra`: who may call it (a role, READ: any client, OPEN: anyone)."""
    return {ACCESS: str(what)}


@dataclass(frozen=True)
class GuardPolicy:
    """Whether reads need a key, and how large a request body may be."""

    protect_reads: bool
    max_body_bytes: int


def bearer(authorization: str | None) -> str | None:
    """The key of `Bearer <key>` (None: no such header, another scheme, or an empty key)."""
    if not authorization:
        return None
    scheme, _, value = authorization.partition(" ")
    value = value.strip()
    return value if scheme.lower() == "bearer" and value else None


def access_of(route: BaseRoute) -> str:
    """What a route allows: its declaration, or OPEN for a route the API document does not show (the console's
    page, the docs, a removed route's 410)."""
    extra = getattr(route, "openapi_extra", None) or {}
    declared = extra.get(ACCESS)
    return str(declared) if declared is not None else OPEN


def check_routes(routes: Iterable[BaseRoute]) -> None:
    """Every route the API document shows declares its access: a new route cannot be left open by omission."""
    from fastapi.routing import APIRoute

    missing = [f"{sorted(r.methods or ())} {r.path}" for r in routes
               if isinstance(r, APIRoute) and r.include_in_schema and ACCESS not in (r.openapi_extra or {})]
    if missing:
        raise RuntimeError(f"routes without a declared access ({ACCESS}): {', '.join(missing)}")
    for r in routes:
        if isinstance(r, APIRoute) and r.include_in_schema:
            declared = (r.openapi_extra or {})[ACCESS]
            if declared not in (READ, OPEN, *Role):
                raise RuntimeError(f"{r.path}: {ACCESS} {declared!r} is no role, {READ!r} or {OPEN!r}")


def route_table(routes: Iterable[BaseRoute]) -> tuple[tuple[BaseRoute, str, str], ...]:
    """(route, path template, access) of every route, in the order they are matched: the app keeps it
    (`app.state.routes`) for `route_of`."""
    return tuple((r, getattr(r, "path", ""), access_of(r) if isinstance(r, Route) else OPEN) for r in routes)


def route_of(scope: Scope) -> tuple[str, str] | None:
    """(path template, access) of the route the request goes to, None when no route takes it (404, 405); kept in
    the scope for the next middleware."""
    if ROUTE_KEY in scope:
        found: tuple[str, str] | None = scope[ROUTE_KEY]
        return found
    found = None
    app = scope.get("app")
    for route, template, allowed in getattr(getattr(app, "state", None), "routes", ()):
        match, _ = route.matches(scope)
        if match is Match.FULL:
            found = (template, allowed)
            break
    scope[ROUTE_KEY] = found
    return found


class HttpMiddleware(ABC):
    """An ASGI middleware of HTTP requests (`http`, with the request's headers, their names in lower case); anything
    else (lifespan, websockets) goes to the application untouched."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        headers = {k.decode("latin-1").lower(): v.decode("latin-1") for k, v in scope.get("headers", [])}
        await self.http(scope, receive, send, headers)

    @abstractmethod
    async def http(self, scope: Scope, receive: Receive, send: Send, headers: dict[str, str]) -> None:
        """The request, with its headers."""


class RequestGuard(HttpMiddleware):
    """ASGI middleware applying a `GuardPolicy` and the clients' roles before the application sees the request.
    `registry(scope)`: the service's client registry (None before the service has started: only its tokens)."""

    def __init__(self, app: ASGIApp, policy: GuardPolicy,
                 registry: Callable[[Scope], ClientRegistry | None]) -> None:
        super().__init__(app)
        self.policy = policy
        self.registry = registry

    async def http(self, scope: Scope, receive: Receive, send: Send, headers: dict[str, str]) -> None:
        method = scope.get("method", "GET").upper()
        try:
            client, refusal = await self._admit(scope, headers)
        except UnavailableError as exc:
            await _reply(send, 503, str(exc))
            return
        refusal = refusal or self._refuse_length(headers)
        if refusal is not None:
            await _reply(send, *refusal)
            return
        with acting_as(client.name if client is not None else None):
            if method in READ_METHODS:
                await self.app(scope, receive, send)
                return
            body, too_large = await _read_body(receive, self.policy.max_body_bytes)
            if too_large:
                await _reply(send, 413, f"request body: larger than the limit of {self.policy.max_body_bytes} bytes")
                return
            await self.app(scope, _replay(body, receive), send)

    async def _admit(self, scope: Scope, headers: dict[str, str]) -> tuple[Client | None, tuple[int, str] | None]:
        """The request's client, or why it is refused (401, 403)."""
        route = route_of(scope)
        allowed = route[1] if route is not None else OPEN
        if allowed == OPEN or (allowed == READ and not self.policy.protect_reads):
            return None, None  # nobody to name: such a request writes no event
        registry = self.registry(scope)
        if registry is not None:
            await _refreshed(registry)
        if allowed != READ and (registry is None or not registry.guarded()):
            return None, None  # no key anywhere: an open service, as before clients
        key = bearer(headers.get("authorization"))
        client = registry.client_of(key) if registry is not None and key is not None else None
        if client is None:
            what = "reads of the knowledge base need" if allowed == READ else f"this request (for role {allowed}) needs"
            said = "no key was sent" if key is None else "the key is unknown or revoked"
            return None, (401, f"Authorization: {what} 'Bearer <key>' of a client on this service; {said}")
        if allowed != READ and not client.may(Role(allowed)):
            roles = ", ".join(sorted(client.roles))
            return None, (403, f"Authorization: this request needs the role {allowed}; client {client.name!r} "
                               f"has the role {roles}")
        return client, None

    def _refuse_length(self, headers: dict[str, str]) -> tuple[int, str] | None:
        length = headers.get("content-length")
        if length is not None:
            if not length.strip().isdigit():
                return 400, "Content-Length: not a whole number of bytes"
            if int(length) > self.policy.max_body_bytes:
                return 413, f"request body: {int(length)} bytes, over the limit of {self.policy.max_body_bytes} bytes"
        return None


async def _refreshed(registry: ClientRegistry) -> None:
    """The registry's copy of the clients' table, read again when stale; when the database cannot be reached, the
    copy it has (an `UnavailableError` only when it never read the table)."""
    if not registry.stale():
        return
    try:
        await anyio.to_thread.run_sync(registry.refresh)
    except UnavailableError as exc:
        if not registry.read_once:
            raise
        log.warning("clients: %s; going on with the keys read before", exc)


async def _read_body(receive: Receive, limit: int) -> tuple[bytes, bool]:
    """The whole request body, or (partial, True) as soon as it passes `limit` bytes."""
    chunks: list[bytes] = []
    size = 0
    while True:
        message = await receive()
        if message["type"] == "http.disconnect":
            break
        chunk = message.get("body", b"")
        size += len(chunk)
        if size > limit:
            return b"", True
        chunks.append(chunk)
        if not message.get("more_body", False):
            break
    return b"".join(chunks), False


def _replay(body: bytes, receive: Receive) -> Receive:
    """A `receive` that hands the already-read body to the application once, then defers to the server."""
    sent = False

    async def replay() -> Message:
        nonlocal sent
        if not sent:
            sent = True
            return {"type": "http.request", "body": body, "more_body": False}
        return await receive()

    return replay


async def _reply(send: Send, status: int, detail: str) -> None:
    payload = json.dumps({"detail": detail}).encode()
    headers = [(b"content-type", b"application/json"), (b"content-length", str(len(payload)).encode())]
    if status == 401:
        headers.append((b"www-authenticate", b"Bearer"))
    await send({"type": "http.response.start", "status": status, "headers": headers})
    await send({"type": "http.response.body", "body": payload})
