"""Bearer-token check for requests that change something; reads stay open."""
from __future__ import annotations

import hmac

from .store.errors import KBError


class AuthError(KBError):
    """The request changes something and does not carry the configured bearer token."""


def check_bearer(configured_token: str | None, authorization: str | None) -> None:
    """Raise AuthError unless no token is configured or `authorization` is `Bearer <token>`."""
    if not configured_token:
        return
    if not authorization:
        raise AuthError("Authorization: this request changes the knowledge base and needs 'Bearer <token>'")
    scheme, _, value = authorization.partition(" ")
    if scheme.lower() != "bearer" or not hmac.compare_digest(value.strip().encode(), configured_token.encode()):
        raise AuthError("Authorization: the bearer token is missing or wrong")
