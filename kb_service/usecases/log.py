"""The object's event log as the service writes and reads it: each event's data is its kind's record
(`planhrc.event_log`), appended by `log_event` and read back by `read_event`; the dispatch gate's view of the
records (`piece_record_of`, `verdict_of`)."""
from __future__ import annotations

from dataclasses import dataclass

from planhrc.event_log import DATA, DecisionData, EventData, EventKind, ValVerdictData, data_of
from planhrc.json_record import RecordError
from planhrc.pipeline import PieceRecord, PieceVerdict, Verdict
from planhrc.pipeline.gate import ACCEPTED_BEFORE_THE_ANSWER

from ..store import DamagedStoreError, KBError, KnowledgeStore, StoredEvent


@dataclass(frozen=True)
class EventRead:
    """An event as the reads show it: its data the kind's record."""

    seq: int
    object_id: str
    kind: str
    reason: str
    data: EventData
    created_at: float
    client: str | None = None  # who caused it (`clients`); None: the service on its own


def log_event(store: KnowledgeStore, object_id: str, kind: str, reason: str, data: EventData) -> StoredEvent:
    """Append an event of `kind` (inside the caller's write): its data is the kind's record."""
    if type(data) is not DATA.get(kind):
        raise KBError(f"internal: an event of kind {kind!r} cannot hold a {type(data).__name__}")
    return store.add_event(object_id, kind, reason, data.to_data())


def read_event(event: StoredEvent) -> EventData:
    """The record a stored event holds; DamagedStoreError when it holds none."""
    try:
        return data_of(event.kind, event.data)
    except RecordError as exc:
        raise DamagedStoreError(f"event {event.seq} of {event.object_id}: {exc}") from None


def event_read(event: StoredEvent) -> EventRead:
    return EventRead(event.seq, event.object_id, event.kind, event.reason, read_event(event), event.created_at,
                     event.client)


def piece_record_of(data: DecisionData) -> PieceRecord | None:
    """The record the dispatch gate starts from for a plan answered early (None: the plan was checked whole)."""
    if not data.val_pieces or data.plan_id is None:
        return None
    accepted = Verdict(True, ACCEPTED_BEFORE_THE_ANSWER)
    return PieceRecord(data.plan_id, data.val_pieces, {number: accepted for number in data.val_accepted})


def verdict_of(data: ValVerdictData) -> Verdict:
    return Verdict(data.verdict == "accepted", data.reason)


def record_verdict(store: KnowledgeStore, object_id: str, plan_id: str, piece: PieceVerdict) -> None:
    """VAL's verdict on a piece of an object's plan, as an event: what the dispatch gate reads (through a
    restart too)."""
    verdict = piece.verdict
    words = "accepted" if verdict.accepted else f"refused ({verdict.reason})"
    log_event(store, object_id, EventKind.VAL_VERDICT,
              f"VAL {words} piece {piece.number} of plan {plan_id}: a_{piece.first}..a_{piece.last}",
              ValVerdictData(plan_id=plan_id, piece=piece.number, first_step=piece.first, last_step=piece.last,
                             verdict="accepted" if verdict.accepted else "refused", reason=verdict.reason,
                             seconds=round(piece.seconds, 6)))
