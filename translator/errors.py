"""Errors of the translator package."""


class TranslationError(Exception):
    """The ontology or a state cannot be written as PDDL; the message names what is missing or wrong."""
