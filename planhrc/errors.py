"""The root of the errors of planhrc's own modules (model, transition, cooperation, data files, client).

Each package keeps one root: `PlanhrcError` here, `TranslationError` in the translator, `PlannerError` in the
planner, `KBError` in the service. HTTP status codes are chosen only in the service's API layer."""
from __future__ import annotations


class PlanhrcError(Exception):
    """Root of the errors of planhrc's core modules; the message names the field or value at fault."""
