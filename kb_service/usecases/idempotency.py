"""Idempotent requests: the answer to a request sent with an `Idempotency-Key` is remembered with a fingerprint of
the request, in the same write as everything the request stored; the same key and request get the same answer,
the same key with another request a conflict."""
from __future__ import annotations

import hashlib
import json
from typing import Any

from ..store import ConflictError
from ..store import KnowledgeStore


def fingerprint(body: dict[str, Any]) -> str:
    return hashlib.sha256(json.dumps(body, sort_keys=True).encode()).hexdigest()


def recall(store: KnowledgeStore, object_id: str, key: str | None, print_: str) -> dict[str, Any] | None:
    """The answer remembered under `key` for the same request (fingerprint `print_`), or None."""
    if not key:
        return None
    stored = store.recall_response(object_id, key)
    if stored is None:
        return None
    if stored.get("fingerprint") != print_:
        raise ConflictError(f"Idempotency-Key: {key!r} was already used with a different request")
    answer: dict[str, Any] = stored["response"]
    return answer


def remember(store: KnowledgeStore, object_id: str, key: str | None, print_: str, answer: dict[str, Any]) -> None:
    if key:
        store.remember_response(object_id, key, {"fingerprint": print_, "response": answer})
