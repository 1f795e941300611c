"""Idempotent requests: the answer to a request sent with an `Idempotency-Key` is remembered with a fingerprint of
the request, in the same write as everything the request stored; the same key and request get the same answer,
the same key with another request a conflict."""
from __future__ import annotations

import hashlib
import json
from typing import Any, TypeVar

from planhrc.json_record import JsonRecord, RecordError

from ..store import ConflictError, DamagedStoreError, KnowledgeStore

R = TypeVar("R", bound=JsonRecord)


def fingerprint(body: dict[str, Any]) -> str:
    return hashlib.sha256(json.dumps(body, sort_keys=True).encode()).hexdigest()


def recall(store: KnowledgeStore, object_id: str, key: str | None, print_: str, answer: type[R]) -> R | None:
    """The answer (an `answer`) remembered under `key` for the same request (fingerprint `print_`), or None."""
    if not key:
        return None
    stored = store.recall_response(object_id, key)
    if stored is None:
        return None
    if stored.get("fingerprint") != print_:
        raise ConflictError(f"Idempotency-Key: {key!r} was already used with a different request")
    try:
        return answer.of_data(stored["response"])
    except RecordError as exc:
        raise DamagedStoreError(f"the answer remembered under Idempotency-Key {key!r}: {exc}") from None


def remember(store: KnowledgeStore, object_id: str, key: str | None, print_: str, answer: JsonRecord) -> None:
    """Remember `answer` under `key` with the request's fingerprint (inside the request's write)."""
    if key:
        store.remember_response(object_id, key, {"fingerprint": print_, "response": answer.to_data()})
