"""The translator's entry function: values in (the object, the initial and goal atoms, the domain model read from
the TBox), PDDL text out. It never touches the knowledge base."""
from __future__ import annotations

from dataclasses import dataclass

from planhrc.model import ArticulatedObject, DomainModelSpec, Formulation, State

from .domain import domain_text
from .problem import get_problem


@dataclass(frozen=True)
class PddlTask:
    """PDDL texts of one problem: the planning domain, the paper's exact domain (for validation) and the problem."""

    domain: str
    validation_domain: str
    problem: str


def translate(obj: ArticulatedObject, init: State, goal: State, model: DomainModelSpec,
              problem_name: str) -> PddlTask:
    """Write the PDDL domain (from the TBox's domain model of the object's formulation) and the problem."""
    return PddlTask(
        domain=domain_text(model, paper_exact=False, absolute=obj.formulation is Formulation.ABSOLUTE),
        validation_domain=domain_text(model, paper_exact=True, absolute=obj.formulation is Formulation.ABSOLUTE),
        problem=get_problem(obj, init, goal, problem_name),
    )
