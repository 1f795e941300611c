"""The service's front door: untrusted input costs nothing before it is trusted.

A pure ASGI middleware, in front of FastAPI's routing and body parsing:

1. the bearer token is checked from the headers alone, before one byte of the body is read (writes always when
   a token is configured; reads of the knowledge base too with `protect_reads`, where a separate read-only token
   is also accepted);
2. a `Content-Length` over the limit is answered 413 without reading the body;
3. a body without a length (chunked) is read only up to the limit, and cut there with 413.

Refusals are JSON `{"detail": "..."}` like every other error of the service. Only the routes of the knowledge
base are guarded for reads (`/objects…`, `/plans…`, `/states…`, `/problems…`, `/ontology`, `/sparql` (by GET or
POST), `/reasoning…`); `/health`, the API
docs and the console's static page stay open so a person can reach the page that asks for the token.
"""
from __future__ import annotations

import hmac
import json
from dataclasses import dataclass
from typing import Any, Awaitable, Callable, MutableMapping

Scope = MutableMapping[str, Any]
Message = MutableMapping[str, Any]
Receive = Callable[[], Awaitable[Message]]
Send = Callable[[Message], Awaitable[None]]
ASGIApp = Callable[[Scope, Receive, Send], Awaitable[None]]

READ_METHODS = frozenset({"GET", "HEAD", "OPTIONS"})
DATA_PREFIXES = ("/objects", "/plans", "/states", "/problems", "/ontology", "/sparql", "/reasoning")
READ_POSTS = frozenset({"/sparql"})  # a SPARQL query by POST changes nothing: a read, with the read token too


@dataclass(frozen=True)
class GuardPolicy:
    """Who may do what, and how large a request body may be."""

    token: str | None
    read_token: str | None
    protect_reads: bool
    max_body_bytes: int


def token_matches(authorization: str | None, *tokens: str | None) -> bool:
    """True when `authorization` is `Bearer <t>` for one of the configured (non-empty) tokens."""
    if not authorization:
        return False
    scheme, _, value = authorization.partition(" ")
    if scheme.lower() != "bearer":
        return False
    given = value.strip().encode()
    return any(t and hmac.compare_digest(given, t.encode()) for t in tokens)


def is_data_path(path: str) -> bool:
    return any(path == p or path.startswith(p + "/") or path.startswith(p + "?") for p in DATA_PREFIXES)


class RequestGuard:
    """ASGI middleware applying a `GuardPolicy` before the application sees the request."""

    def __init__(self, app: ASGIApp, policy: GuardPolicy) -> None:
        self.app = app
        self.policy = policy

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        headers = {k.decode("latin-1").lower(): v.decode("latin-1") for k, v in scope.get("headers", [])}
        method = scope.get("method", "GET").upper()
        refusal = self._refuse_before_body(method, scope.get("path", "/"), headers)
        if refusal is not None:
            await _reply(send, *refusal)
            return
        if method in READ_METHODS:
            await self.app(scope, receive, send)
            return
        body, too_large = await _read_body(receive, self.policy.max_body_bytes)
        if too_large:
            await _reply(send, 413, f"request body: larger than the limit of {self.policy.max_body_bytes} bytes")
            return
        await self.app(scope, _replay(body, receive), send)

    def _refuse_before_body(self, method: str, path: str, headers: dict[str, str]) -> tuple[int, str] | None:
        policy = self.policy
        auth = headers.get("authorization")
        if method not in READ_METHODS and path not in READ_POSTS:
            if policy.token and not token_matches(auth, policy.token):
                return 401, "Authorization: this request changes the knowledge base and needs 'Bearer <token>'"
        elif policy.protect_reads and is_data_path(path):
            if not token_matches(auth, policy.token, policy.read_token):
                return 401, "Authorization: reads of the knowledge base need 'Bearer <token>' on this service"
        length = headers.get("content-length")
        if length is not None:
            if not length.strip().isdigit():
                return 400, "Content-Length: not a whole number of bytes"
            if int(length) > policy.max_body_bytes:
                return 413, f"request body: {int(length)} bytes, over the limit of {policy.max_body_bytes} bytes"
        return None


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
