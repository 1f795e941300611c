"""Checks of the values a request brings, before anything is read or written: a bad value is refused with a
ValidationError whose message names the field."""
from __future__ import annotations

import math
from typing import Sequence

from planhrc.geometry import GeometryError, ObjectGeometry
from planhrc.model import ArticulatedObject
from planhrc.vocabulary import ActionOutcome, FailureReason, one_of

from ..store import ValidationError


def measured_base(value: Sequence[float] | None) -> tuple[float, float] | None:
    """A measured base point as [x, y] metres, validated (ValidationError naming the field), or None."""
    if value is None:
        return None
    try:
        if len(value) == 2:
            return ObjectGeometry((1.0,), (value[0], value[1])).base_point_xy
    except (GeometryError, IndexError, TypeError):
        pass
    raise ValidationError(f"base_point_xy: expected [x, y], two finite numbers in metres, got {value!r}")


def check_finite(values: Sequence[float | None], field: str) -> None:
    for i, v in enumerate(values):
        if v is not None and (isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v)):
            raise ValidationError(f"{field}[{i}]: must be a finite number, got {v!r}")


def check_count(obj: ArticulatedObject, values: Sequence[float | None], field: str) -> None:
    if len(values) != obj.n_links:
        raise ValidationError(f"{field}: expected {obj.n_links} values (one per link), got {len(values)}")


def allowed(obj: ArticulatedObject, values: Sequence[float | None], field: str) -> list[int | None]:
    """Each value as one of the object's allowed orientations (None stays None)."""
    orientations = set(obj.orientation_degrees)
    out: list[int | None] = []
    for i, v in enumerate(values):
        if v is None:
            out.append(None)
            continue
        if float(v) % 360 not in orientations:
            raise ValidationError(f"{field}[{i}]: {v} is not one of the allowed orientations {sorted(orientations)}")
        out.append(int(float(v) % 360))
    return out


def action_outcome(value: str) -> ActionOutcome:
    if value not in set(ActionOutcome):
        raise ValidationError(f"outcome: must be {one_of(ActionOutcome)}, got {value!r}")
    return ActionOutcome(value)


def failure_reason(outcome: ActionOutcome, reason: str | None) -> FailureReason | None:
    if reason is None:
        return None
    if reason not in set(FailureReason):
        raise ValidationError(f"reason: must be {one_of(FailureReason)} or null, got {reason!r}")
    if outcome == ActionOutcome.SUCCEEDED:
        raise ValidationError(f"reason: must be null when the outcome is succeeded, got {reason!r}")
    return FailureReason(reason)


def finite_or_none(value: float | None, field: str) -> float | None:
    if value is not None and (isinstance(value, bool) or not isinstance(value, (int, float))
                              or not math.isfinite(value)):
        raise ValidationError(f"{field}: must be a finite number, got {value!r}")
    return value
