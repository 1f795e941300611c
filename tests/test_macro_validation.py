"""Macro plans checked through what they stand for, on the bimanual authors' published files (`tests/data/bimanual`,
MIT, see its README): the once-per-domain proof that a macro is its sequence of steps (`planner.macros`), the
route of a plan to VAL on its expansion or as given (`planner.checking`), both verdicts side by side on published
plans and on broken ones each validator must reject, and a plan no validator finished on answered `unvalidated`."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from planhrc.planner import checking
from planhrc.planner.chain import plan_with_fallback
from planhrc.planner.checking import CheckedBy, check_as_given, check_plan, route
from planhrc.planner.cli import main as cli_main
from planhrc.planner.errors import PlannerError
from planhrc.planner.macros import macro_report
from planhrc.planner.pddl import parse_problem
from planhrc.planner.plan_file import parse_plan_text
from planhrc.vocabulary import PlanStatus

DATA = Path(__file__).parent / "data" / "bimanual"
MACROS, PRIMITIVE = (DATA / "domain_m_25_B.pddl").read_text(), (DATA / "domain_m_0.pddl").read_text()
INC, DEC = "increase_angle_first_child", "decrease_angle_first_child"
ONE_MACRO = "batch1000_4_24_00523"  # its published plan turns one joint 45 degrees in one macro step (step 7)


def problem(name: str) -> str:
    return (DATA / f"{name}.pddl").read_text()


def published(name: str) -> tuple[str, ...]:
    return parse_plan_text((DATA / f"{name}.plan").read_text())


def test_the_45_degree_macros_are_proved_three_steps_each_and_nothing_else_is_a_macro():
    """In the published macro domain each 45-degree turn is three one-step turns of the same joint through the
    intermediate angles (every way the parameters may coincide included); `link-to-central-grasp` is no macro
    there (the file has no action moving the centre alone); the macro-free domain has none. The premises name
    the successor relation and the angle variables. Once the macro-free actions are added, the grasp is proved
    to be the move then the grasp."""
    report = macro_report(MACROS)
    assert set(report.faithful) == {f"{INC}_45", f"{DEC}_45"} and not report.unfaithful
    steps = report.faithful[f"{INC}_45"].expand(["l2", "l1", "j1", "a0", "a15", "a30", "a45", "gl", "gr"])
    assert steps == (f"({INC} l2 l1 j1 a0 a15 gl gr)", f"({INC} l2 l1 j1 a15 a30 gl gr)",
                     f"({INC} l2 l1 j1 a30 a45 gl gr)")
    assert [relation for relation, _ in report.bijections] == ["angle-before"]
    assert ("angle_joint", 0, frozenset({"angle"})) in report.variables
    assert not macro_report(PRIMITIVE).faithful
    both = macro_report((DATA / "domain_m_0-with-macros.pddl").read_text())
    assert set(both.faithful) == {"link-to-central-grasp", f"{INC}_45", f"{DEC}_45"}
    assert [name for name, _ in both.faithful["link-to-central-grasp"].steps] == ["move-link-to-central",
                                                                                 "take-links-to-move"]


@pytest.mark.parametrize("variant, why", [
    ("moves-two", "the macro moves each along angle-before angle-before where (affected ?o ?link1 ?joint), its "
                  "expansion moves each along angle-before angle-before angle-before"),
    ("no-grasp", "its expansion needs (grasp ?g1 ?link1), which the macro does not"),
])
def test_a_macro_that_is_not_its_sequence_is_reported_and_its_plans_go_to_val_as_given(variant, why):
    """A changed copy of the macro domain: the changed macro is reported with the difference, the other one is
    still proved, and a plan using the changed one goes to VAL as it is (one using only the other is expanded)."""
    domain = (DATA / f"domain_m_25_B-{variant}.pddl").read_text()
    report = macro_report(domain)
    assert set(report.faithful) == {f"{DEC}_45"} and set(report.unfaithful) == {f"{INC}_45"}
    assert why in report.unfaithful[f"{INC}_45"]
    plan = published(ONE_MACRO)
    assert any(step.startswith(f"({INC}_45") for step in plan)
    assert route(domain, problem(ONE_MACRO), plan).by is CheckedBy.VAL
    assert route(MACROS, problem(ONE_MACRO), plan).by is CheckedBy.VAL_EXPANSION


def test_val_refuses_the_plan_of_an_unfaithful_macro_that_its_expansion_would_pass():
    """Why only proved macros are expanded: with the macro that moves the other joints two steps, the published
    plan fails (a later step finds its joint where the macro left it), which VAL as given says; the expansion
    into three one-step turns would have passed it."""
    domain = (DATA / "domain_m_25_B-moves-two.pddl").read_text()
    plan, task = published(ONE_MACRO), problem(ONE_MACRO)
    checked = check_plan(domain, task, plan, 120.0)
    assert checked.by is CheckedBy.VAL and not checked.valid and "unsatisfied precondition" in checked.reason
    naive = macro_report(MACROS).expand(plan)
    assert naive is not None and check_plan(domain, task, naive.steps, 60.0).valid


def test_published_plans_are_validated_through_their_expansion():
    """Every published plan here (up to 8 macro steps each, up to 32 steps) is valid by VAL on its expansion,
    saying so; a plan without macro steps goes to VAL as given."""
    for name in ("batch1000_4_24_00503", ONE_MACRO, "batch2000_4_24_01133", "batch4000_4_24_02517"):
        plan = published(name)
        checked = check_plan(MACROS, problem(name), plan, 60.0)
        assert checked.valid, (name, checked.reason)
        uses = any("_45 " in step for step in plan)
        assert checked.by is (CheckedBy.VAL_EXPANSION if uses else CheckedBy.VAL), name
        if uses:
            assert "proved faithful" in checked.note


BROKEN = {  # a published plan broken three ways: what each validator must reject
    "the macro step from the wrong angle": lambda plan: plan[:6] + (
        plan[6].replace("angle300 angle315 angle330 angle345", "angle315 angle330 angle345 angle0"),) + plan[7:],
    "a step after the macro from where the macro did not leave its joint": lambda plan: plan[:9] + (
        plan[9].replace("angle315 angle330", "angle300 angle315"),) + plan[10:],
    "the last step missing": lambda plan: plan[:-1],
}


@pytest.mark.slow
@pytest.mark.parametrize("how", [None, *BROKEN])
def test_both_validators_agree_on_a_published_plan_and_on_its_broken_copies(how):
    """The published plan with one macro step, and copies of it broken each way: VAL on the expansion and VAL on
    the plan as given (expanding the macro's quantified effect: seconds and about a gigabyte) give the same
    verdict. A refusal of the expansion names the plan step its failing step stands for."""
    plan = published(ONE_MACRO)
    assert plan[6].startswith(f"({INC}_45 ") and "angle300 angle315 angle330 angle345" in plan[6]
    plan = plan if how is None else BROKEN[how](plan)
    expanded = check_plan(MACROS, problem(ONE_MACRO), plan, 120.0)
    given = check_as_given(MACROS, problem(ONE_MACRO), plan, 300.0)
    assert expanded.by is CheckedBy.VAL_EXPANSION and given is not None
    assert expanded.valid == given.valid == (how is None), (expanded.reason, given.reason)
    if how == "the macro step from the wrong angle":
        assert "part 1 of the expansion of plan step 7" in expanded.reason


def test_a_problem_that_breaks_the_premises_goes_to_val_as_given():
    """The proof holds where the successor relation is a bijection of the angles and each joint has one angle:
    a problem with an extra successor fact, or a joint with two angles, sends the plan to VAL as it is, saying
    why."""
    text = problem(ONE_MACRO)
    plan = published(ONE_MACRO)
    forked = text.replace("(angle-before angle0 angle15)", "(angle-before angle0 angle15)\n    (angle-before angle0 angle30)")
    way = route(MACROS, forked, plan)
    assert way.by is CheckedBy.VAL and "angle-before does not give every angle exactly one next" in way.note
    init = parse_problem(text).init
    angle = next(a for a in init if a[0] == "angle_joint" and a[2] == "joint1")
    twice = text.replace(f"(angle_joint {angle[1]} joint1)", f"(angle_joint {angle[1]} joint1) (angle_joint angle0 joint1)"
                         if angle[1] != "angle0" else "(angle_joint angle0 joint1) (angle_joint angle15 joint1)")
    way = route(MACROS, twice, plan)
    assert way.by is CheckedBy.VAL and "two values for joint1" in way.note


def test_the_command_answers_a_published_problem_validated_and_says_by_which_check(tmp_path):
    """`planhrc plan` on a published problem of each domain file, as a process: solved, the plan validated, by VAL
    on the expansion where the plan has macro steps, never longer than the authors' published plan (for the
    macro-free domain: than its expansion into that domain's actions)."""
    with_macros = macro_report((DATA / "domain_m_0-with-macros.pddl").read_text())
    for domain in ("domain_m_25_B.pddl", "domain_m_0.pddl"):
        for name in ("batch1000_4_24_00503", "batch4000_4_24_02517"):
            run = subprocess.run([sys.executable, "-m", "planhrc.cli", "plan", str(DATA / domain),
                                  str(DATA / f"{name}.pddl"), "--json", "--timeout", "120"],
                                 capture_output=True, text=True, timeout=300)
            assert run.returncode == 0, run.stderr
            answer = json.loads(run.stdout)
            assert answer["status"] == "solved" and answer["validated"] is True
            macros = any("_45 " in step for step in answer["plan"])
            assert answer["checked_by"] == ("val-expansion" if macros else "val"), answer
            theirs = published(name)
            if domain == "domain_m_0.pddl":
                expanded = with_macros.expand(theirs)
                theirs = expanded.steps if expanded is not None else theirs
            assert len(answer["plan"]) <= len(theirs), (domain, name)


def test_a_plan_no_validator_finished_on_is_answered_unvalidated_with_its_own_exit_status(monkeypatch, capsys):
    """VAL that does not answer in the time left (made so here, isolating the chain from VAL) leaves the plan
    printed with status `unvalidated` and the reason, exit status 3; the chain still tries the next planner first,
    and the answer lists both attempts. Never "timeout" for a task a planner solved."""
    def no_answer(*args, **kwargs):
        raise PlannerError("VAL did not answer within the time left")

    monkeypatch.setattr(checking, "validate_plan", no_answer)
    small = DATA.parent  # a relative 3 x 4 task, which Fast Downward plans in a fraction of a second
    result = plan_with_fallback((small / "domain-relative.pddl").read_text(),
                                (small / "problem-relative-3x4.pddl").read_text(), ["inproc", "fd-lama"], 60.0)
    assert result.status is PlanStatus.UNVALIDATED and result.plan and not result.validated
    assert result.planner == "inproc" and "no validator finished" in result.message
    assert "VAL did not answer" in result.message
    assert [(a.planner, a.status) for a in result.attempts] == [("inproc", PlanStatus.UNVALIDATED),
                                                                ("fd-lama", PlanStatus.UNVALIDATED)]
    args = ["plan", str(DATA / "domain_m_25_B.pddl"), str(DATA / f"{ONE_MACRO}.pddl"), "--no-fallback"]
    assert cli_main([*args, "--json"]) == 3
    answer = json.loads(capsys.readouterr().out)
    assert answer["status"] == "unvalidated" and answer["plan"] and answer["checked_by"] is None
    assert cli_main(args) == 3
    text = capsys.readouterr().out
    assert ": unvalidated in" in text and "no validator finished" in text and "(release-links" in text


@pytest.mark.slow
def test_both_validators_agree_on_random_plans_and_random_breakages_where_val_expands_macros_cheaply():
    """On the project's own macro variant at K = 8 (VAL expands a macro there in milliseconds: 8^4 instances per
    joint), shortest plans of random tasks and copies broken at random (a step dropped, two steps swapped, a turn
    from the wrong angle): VAL on the expansion and VAL on the plan as given agree on every one."""
    import random

    from planhrc.bench.bimanual_tasks import domain_text, make_instances, problem_text
    from planhrc.planner.inproc import InprocPlanner

    domain = domain_text("macros")
    assert macro_report(domain).faithful
    rng = random.Random(11)
    seen = {True: 0, False: 0}
    for inst in make_instances([4, 5], [8], 3, "macros"):
        task = problem_text(inst)
        plan = InprocPlanner().solve(domain, task, 60.0).plan
        assert any("-3 " in step for step in plan) or len(plan) < 3
        copies = [plan]
        for _ in range(3):
            steps = list(plan)
            how = rng.choice(("drop", "swap", "angle"))
            i = rng.randrange(len(steps))
            if how == "drop":
                del steps[i]
            elif how == "swap" and len(steps) > 1:
                j = rng.randrange(len(steps))
                steps[i], steps[j] = steps[j], steps[i]
            else:
                words = steps[i].strip("()").split()
                angles = [k for k, w in enumerate(words) if w.startswith("a") and w[1:].isdigit()]
                if angles:
                    words[angles[0]] = "a" + str((int(words[angles[0]][1:]) + 45) % 360)
                steps[i] = "(" + " ".join(words) + ")"
            copies.append(tuple(steps))
        for steps in copies:
            expanded = check_plan(domain, task, steps, 120.0)
            given = check_as_given(domain, task, steps, 120.0)
            assert given is not None and expanded.valid == given.valid, (steps, expanded.reason, given.reason)
            seen[expanded.valid] += 1
    assert seen[True] >= 6 and seen[False] >= 6  # both verdicts seen often enough to mean something
