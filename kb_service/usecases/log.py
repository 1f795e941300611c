"""The object's event log as the use cases write and read it: the kinds of event besides the decisions
(`vocabulary.DecisionKind`), and the data of VAL's verdict on a piece of a plan."""
from __future__ import annotations

from enum import StrEnum
from typing import Any, Mapping

from planhrc.pipeline import PieceRecord, PieceVerdict, Verdict
from planhrc.pipeline.gate import ACCEPTED_BEFORE_THE_ANSWER

from ..store import KnowledgeStore


class EventKind(StrEnum):
    OBJECT_CREATED = "object_created"
    GOAL_SET = "goal_set"
    DISPATCHED = "dispatched"
    FEEDBACK = "feedback"
    WORKER_GAVE_UP = "worker_gave_up"
    VAL_VERDICT = "val_verdict"  # one per piece checked after the answer: data plan_id, piece, first_step, ...
    DISPATCH_WITHHELD = "dispatch_withheld"  # a step not sent: VAL refused (or has not decided on) its piece


ACCEPTED, REFUSED = "accepted", "refused"


def record_verdict(store: KnowledgeStore, object_id: str, plan_id: str, piece: PieceVerdict) -> None:
    """VAL's verdict on a piece of an object's plan, as an event: what the dispatch gate reads (through a
    restart too)."""
    verdict = piece.verdict
    words = "accepted" if verdict.accepted else f"refused ({verdict.reason})"
    store.add_event(object_id, EventKind.VAL_VERDICT,
                    f"VAL {words} piece {piece.number} of plan {plan_id}: a_{piece.first}..a_{piece.last}",
                    {"plan_id": plan_id, "piece": piece.number, "first_step": piece.first, "last_step": piece.last,
                     "verdict": ACCEPTED if verdict.accepted else REFUSED, "reason": verdict.reason,
                     "seconds": round(piece.seconds, 6)})


def verdict_of(data: Mapping[str, Any]) -> Verdict:
    """The verdict a `val_verdict` event's data records."""
    return Verdict(data.get("verdict") == ACCEPTED, str(data.get("reason", "")))


def piece_record_of(plan_id: str, data: Mapping[str, Any]) -> PieceRecord:
    """The record a plan's adoption event starts (`val_pieces`, `val_accepted`)."""
    pieces = tuple((int(a), int(b)) for a, b in data["val_pieces"])
    accepted = Verdict(True, ACCEPTED_BEFORE_THE_ANSWER)
    return PieceRecord(plan_id, pieces, {int(number): accepted for number in data.get("val_accepted", ())})
