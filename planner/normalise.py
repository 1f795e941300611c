"""The copy of a domain and problem that the planners reading PDDL themselves are given: the text as VAL reads it.

Fast Downward's translator stops at ``?j -joint`` ("Got: -joint", exit code 31) and reads an action declared twice
as two actions, so its plans may use the later declaration, which VAL refuses. `for_external` hands such
planners the texts written again from what `planner.pddl` read (dash tokens split, later declarations of an
action dropped, names lower-cased, comments gone), and the original texts untouched when they need none of
this. The copy is the domain as VAL reads it, so a plan for it is a plan for the original, and a planner's
claim that its plan is optimal for the copy holds for the original too.
"""
from __future__ import annotations

from .errors import PlannerError
from .pddl import SExpr, format_sexpr, parse_sexpr, tokenize


def for_external(domain: str, problem: str) -> tuple[str, str]:
    """(domain, problem) as VAL reads them; each text unchanged when it needs no normalising."""
    return normalised(domain, "domain"), normalised(problem, "problem")


def normalised(text: str, what: str) -> str:
    """`text` written again when it has a dash-name token or an action declared twice, else `text` itself.

    Text that does not parse is returned unchanged: the planner reports what is wrong with it in its own words."""
    if not _needs_copy(text):
        return text
    try:
        tree = parse_sexpr(text, what)
    except PlannerError:
        return text
    return write_sexpr(_first_declarations(tree)) + "\n"


def _needs_copy(text: str) -> bool:
    lowered = text.lower()
    if any(_starts_with_dash_name(token) for token in lowered.replace("(", " ").replace(")", " ").split()):
        return True
    return lowered.count(":action") > 1 and _has_duplicate_action(tokenize(lowered))


def _starts_with_dash_name(token: str) -> bool:
    return len(token) > 1 and token[0] == "-" and (token[1].isalpha() or token[1] == "_")


def _has_duplicate_action(tokens: list[str]) -> bool:
    names = [tokens[i + 1] for i, token in enumerate(tokens[:-1]) if token == ":action"]
    return len(set(names)) != len(names)


def _first_declarations(tree: SExpr) -> SExpr:
    if not isinstance(tree, tuple):
        return tree
    seen: set[str] = set()
    kept: list[SExpr] = []
    for section in tree:
        if isinstance(section, tuple) and len(section) > 1 and section[0] == ":action" and isinstance(section[1], str):
            if section[1] in seen:
                continue
            seen.add(section[1])
        kept.append(section)
    return tuple(kept)


def write_sexpr(tree: SExpr) -> str:
    """A define form with one section per line (planners read one long line too; people read this better)."""
    if isinstance(tree, tuple) and tree and tree[0] == "define":
        return "(define " + "\n  ".join(format_sexpr(part) for part in tree[1:]) + ")"
    return format_sexpr(tree)
