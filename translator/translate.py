"""ABox -> PDDL task: the translator's entry function."""
from __future__ import annotations

from typing import TYPE_CHECKING

from dataclasses import dataclass
from pathlib import Path

from planhrc.model import ArticulatedObject

from .domain import get_domain
from .problem import get_problem
from .symbols import SymbolTable


if TYPE_CHECKING:
    from planhrc.kb.store import KnowledgeBase


@dataclass(frozen=True)
class PddlTask:
    """PDDL texts of one problem: the planning domain, the paper's exact domain (for validation) and the problem."""

    object_id: str
    problem_id: str
    domain: str
    validation_domain: str
    problem: str
    symbols: SymbolTable


def symbols_for(obj: ArticulatedObject) -> SymbolTable:
    return SymbolTable.from_names(obj.all_links + obj.joints + obj.orientation_names)


def translate(kb: KnowledgeBase, problem_id: str, tbox_path: Path | str) -> PddlTask:
    """Write the PDDL domain (from the TBox) and problem (from the ABox: init and goal states) of a Problem."""
    problem = kb.get_problem(problem_id)
    obj = kb.get_object(problem.object_id)
    init = kb.get_state(problem.init_state_id)
    goal = kb.get_state(problem.goal_state_id)
    form = obj.formulation.value
    return PddlTask(
        object_id=obj.ident,
        problem_id=problem_id,
        domain=get_domain(tbox_path, form),
        validation_domain=get_domain(tbox_path, form, paper_exact=True),
        problem=get_problem(obj, init.atoms, goal.atoms, f"{obj.ident}-{problem_id}"),
        symbols=symbols_for(obj),
    )
