"""Translator: TBox -> PDDL domain, object and states -> PDDL problem (relative, absolute and bimanual
formulations).

A pure function of values: `translate(obj, init, goal, read_domain_model(tbox, formulation), name)` returns the
PDDL texts; nothing here reads or writes the knowledge base.
"""
from .domain import domain_text, get_domain, read_domain_model
from .errors import TranslationError
from .problem import get_problem
from .translate import PddlTask, translate

__all__ = ["PddlTask", "TranslationError", "domain_text", "get_domain",
           "get_problem", "read_domain_model", "translate"]
