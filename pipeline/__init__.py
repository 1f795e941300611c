"""The planning pipeline, one stage after another, from values to a value:

    object, initial and goal states -> translate (TBox domain model -> PDDL domain, states -> PDDL problem)
      -> plan (a planner of the registry, then the fallback)
      -> order (for an object placed in the cell: an order of the actions that stays on the table, `ordering`)
      -> validate (VAL) -> expected states (replay with the paper's transition equations) -> `PlanOutcome`

Every call has a deadline (`PlanningConfig.deadline_s`, or the caller's `deadline_at`) that bounds planning and
VAL together: a task too large for it ends with status `timeout` instead of minutes of work.

`plan(...)` reads nothing from and writes nothing to the knowledge base: the caller (the service's use cases,
`planhrc solve`) stores what it returns, in one write. Planners are reached only through the registry.

| module | owns |
|---|---|
| `config` | the values: `PlanningConfig` (from the settings), `PlanOutcome`, the deadline |
| `stages` | `find_plan`, `expect`, and `plan` / `plan_moves` running the stages in order |
| `order` | an order of a plan's steps that stays on the table |
| `motion` | what a step means for the robot (`action_motion`), macro steps |
| `pieces` | a plan cut into pieces VAL checks one by one |
| `val_runs` | VAL runs on a plan: started now, judged later (`validate`: both at once) |
| `validation` | the service's owner of validation runs: armed VAL processes, the early answer, verdict handles |
| `later` | a plan's later pieces checked behind the service's answer (made and held by `validation`) |
| `gate` | the dispatch gate's logic over a record of VAL's verdicts on a plan's pieces (pure) |
| `replan` | a re-plan for the service in one call: the plan with a handle on VAL's verdict |
| `solve` | one request of `planhrc solve` through the pipeline |

This module only re-exports the public names.
"""
from __future__ import annotations

from .config import LaterSlide, PlanningConfig, PlanOutcome, config_from_settings, deadline_from, problem_name, time_left
from .motion import MacroStep, PlanStep, action_motion, first_motion_steps, merge_macro_steps, move_of, step_text
from .order import Ordered, Refusal, order_steps, steps_of
from .pieces import (MIN_PIECE_STEPS, ValPiece, early_answer_first_piece, early_pieces, piece_bounds, piece_of,
                     validation_pieces)
from .stages import Found, expect, find_plan, plan, plan_moves, planner_chain, run_planners
from .gate import GateAnswer, PieceRecord, PieceVerdict, Verdict, gate
from .replan import PlannedTurn, PlanningJob, ReplanRequest, plan_for_service, warm_up, warm_up_job
from .val_runs import ValCheck, validate
from .validation import EarlyAnswer, Validator, VerdictHandle

__all__ = [
    "MIN_PIECE_STEPS", "EarlyAnswer", "Found", "GateAnswer", "MacroStep", "Ordered", "PieceRecord", "PieceVerdict",
    "PlanOutcome", "PlanStep", "PlannedTurn", "PlanningConfig", "PlanningJob", "Refusal", "ReplanRequest",
    "ValCheck", "ValPiece", "Validator", "Verdict", "VerdictHandle", "action_motion", "config_from_settings",
    "deadline_from", "early_answer_first_piece", "early_pieces", "expect", "find_plan", "first_motion_steps", "gate",
    "merge_macro_steps", "move_of", "order_steps", "piece_bounds", "piece_of", "plan", "plan_for_service",
    "plan_moves", "planner_chain", "problem_name", "run_planners", "steps_of", "step_text", "time_left", "validate",
    "validation_pieces", "warm_up", "warm_up_job",
]
