"""Translator: TBox -> PDDL domain, ABox -> PDDL problem (relative and absolute formulations)."""
from .domain import get_domain, read_domain_model
from .errors import SymbolError, TranslationError
from .problem import get_problem
from .symbols import SymbolTable

__all__ = ["get_domain", "read_domain_model", "get_problem", "SymbolTable", "TranslationError", "SymbolError"]
