"""What every use case is given: the store, the settings, the per-object locks, the planning pool, the owner of
validation runs and the per-object memory, in one value built once per service (`open_context`) and closed with
it (`close_context`). Nothing here is global: a test builds as many as it likes."""
from __future__ import annotations

from dataclasses import dataclass

from planhrc.pipeline import PlanningConfig, Validator, config_from_settings
from planhrc.pipeline.replan import LargeTaskPlanning
from planhrc.settings import Settings

from ..locks import ObjectLocks
from .memory import Memory, PlanViews
from .observing import QUIET, Observer
from ..store import KnowledgeStore


@dataclass(frozen=True)
class Context:
    store: KnowledgeStore
    settings: Settings
    planning: PlanningConfig
    locks: ObjectLocks  # one object's requests run one at a time, different objects' in parallel
    validator: Validator  # every VAL run: new plans, the later pieces behind an answer, the dispatch gate's
    memory: Memory  # what each object's event log says
    views: PlanViews  # the cooperation model's view of each object's plan
    pool: LargeTaskPlanning | None = None  # large tasks are planned there (`planning_pool`), the rest in this process
    observer: Observer = QUIET  # metrics and spans (`observe`)


def open_context(store: KnowledgeStore, settings: Settings, locks: ObjectLocks | None = None,
                 pool: LargeTaskPlanning | None = None, observer: Observer = QUIET) -> Context:
    planning = config_from_settings(settings)
    validator = Validator(planning, early_answer=settings.val_early_answer,
                          merge_macro_steps=settings.merge_macro_steps,
                          armed=settings.val_armed and settings.validate_plans)
    return Context(store, settings, planning, locks or ObjectLocks(), validator, Memory(), PlanViews(), pool, observer)


def close_context(context: Context) -> None:
    """Stop the VAL runs still checking plans' later pieces and the armed VAL processes (the service stops)."""
    context.validator.close()
