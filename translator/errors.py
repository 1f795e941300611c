"""Errors of the translator package."""
from __future__ import annotations

from planhrc.errors import PlanhrcError


class TranslationError(PlanhrcError):
    """The ontology or a state cannot be written as PDDL; the message names what is missing or wrong."""
