"""Errors of the translator package."""


class TranslationError(Exception):
    """The ontology or a state cannot be written as PDDL; the message names what is missing or wrong."""


class SymbolError(TranslationError):
    """A name has no counterpart in the symbol table (IRI <-> PDDL name)."""
