"""planhrc: human-robot cooperative manipulation of articulated objects.

The library API, for programs that embed planhrc (every name is imported on first use, so `import planhrc` and
`import planhrc.model` stay cheap):

    from planhrc import make_object, plan
    rod = make_object("rod", "relative", links=4, orientations=4)
    start, goal = rod.state([0, 0, 0]), rod.configuration_atoms([90, 0, 270])
    result = plan(rod, start, goal)
    print(result.status, [step.params for step in result.actions])

* the object model: `ArticulatedObject`, `make_object`, `Formulation`, `Atom`, `State`, `perceive`, `is_subsumed`;
* the translator: `translate`, `read_domain_model`, `PddlTask`;
* planning: `plan(obj, init, goal, config=None)` -> `PlanOutcome`, `PlanningConfig`, `config_from_settings`;
* the cooperation model: `decide`, `PlanView`, `Decision`, and the vocabulary (`DecisionKind`, ...);
* the HTTP client of the knowledge-base service: `KBClient` (`planhrc.client`);
* the errors: `PlanhrcError`, the root of every package's errors, and `DeadlineExceeded`.
"""
from __future__ import annotations

from importlib import import_module
from typing import Any

__version__ = "0.1.0"

# public name -> module that defines it
_EXPORTS: dict[str, str] = {
    **dict.fromkeys(["ArticulatedObject", "Atom", "Formulation", "ModelError", "Perception", "State",
                     "is_subsumed", "make_object", "perceive"], "planhrc.model"),
    **dict.fromkeys(["PddlTask", "TranslationError", "read_domain_model", "translate"], "planhrc.translator"),
    **dict.fromkeys(["PlanOutcome", "PlanningConfig", "config_from_settings", "plan"], "planhrc.pipeline"),
    **dict.fromkeys(["Decision", "PlanView", "decide"], "planhrc.cooperation"),
    **dict.fromkeys(["ActionOutcome", "DecisionKind", "ExecutionStatus", "FailureReason", "PlanningStatus",
                    "PlanStatus"], "planhrc.vocabulary"),
    **dict.fromkeys(["KBClient", "ProtocolError", "RetryPolicy"], "planhrc.client"),
    **dict.fromkeys(["Settings", "get_settings", "make_settings"], "planhrc.settings"),
    **dict.fromkeys(["DeadlineExceeded", "PlanhrcError"], "planhrc.errors"),
}

__all__ = sorted(_EXPORTS) + ["__version__"]


def __getattr__(name: str) -> Any:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'planhrc' has no attribute {name!r}")
    value = getattr(import_module(module), name)
    globals()[name] = value  # later lookups skip this function
    return value


def __dir__() -> list[str]:
    return __all__
