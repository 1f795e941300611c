"""PDDL read as VAL reads it (dash tokens, actions declared twice), the same reading for every planner, and the
chain's VAL step: no plan VAL refuses is answered as solved."""
import json
import sys
import tempfile
import time
from pathlib import Path

import pytest

from planhrc.planner import PlanResult, PlanStatus, plan_files, plan_with_fallback, validate_plan
from planhrc.planner.cli import main as cli_main
from planhrc.planner.fast_downward import LAMA_FIRST, fast_downward_script
from planhrc.planner.normalise import for_external, normalised
from planhrc.planner.pddl import parse_domain, parse_problem, split_dash, tokenize
from planhrc.planner.plan_file import read_best_plan
from planhrc.planner.process import run_limited
from planhrc.planner.registry import PLANNERS

DATA = Path(__file__).parent / "data"
STYLES = DATA / "styles"
ORIENTED = (STYLES / "domain-oriented-duplicates.pddl").read_text()
ORIENTED_PROBLEM = (STYLES / "problem-oriented-4x8.pddl").read_text()
TWICE = (STYLES / "domain-twice.pddl").read_text()
TWICE_PROBLEM = (STYLES / "problem-twice.pddl").read_text()
RELATIVE = (DATA / "domain-relative.pddl").read_text()
RELATIVE_PROBLEM = (DATA / "problem-relative-3x4.pddl").read_text()


# -- reading ----------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("token, parts", [
    ("-joint", ("-", "joint")), ("-_x", ("-", "_x")), ("-", ("-",)), ("angle-before", ("angle-before",)),
    ("?j-joint", ("?j-joint",)), ("-5", ("-5",)),
])
def test_a_dash_touching_a_name_is_a_dash_and_a_name(token, parts):
    assert split_dash(token) == parts


def _tokens_line_by_line(text: str) -> list[str]:
    """The reading `tokenize` must give, spelled out slowly: each line without its comment, parentheses apart, split at
    blanks, each token through `split_dash`."""
    tokens: list[str] = []
    for line in text.splitlines():
        for token in line.split(";", 1)[0].replace("(", " ( ").replace(")", " ) ").split():
            tokens.extend(split_dash(token))
    return tokens


def test_tokenize_reads_every_text_as_the_line_by_line_reading_does():
    """`tokenize` splits the whole text at once and looks for dashes against names only where a token starts with
    one: the same tokens as the slow reading, on the repository's PDDL files and on random texts of awkward pieces."""
    import random

    texts = [path.read_text() for path in sorted(DATA.rglob("*.pddl"))]
    pieces = ["(", ")", " ", "\n", "\t", "\r\n", "-", "-a", "-_b", "-5", "--x", "a-b", "?j", "?j-joint", "?j -joint",
              "; c ( x\n", "İx", "-é", "-²", "x\u00a0y", "\x1c", "\u2028", "A", "define", "Q;"]
    rng = random.Random(5)
    texts += ["".join(rng.choice(pieces) for _ in range(rng.randint(0, 40))) for _ in range(3000)]
    for text in texts:
        assert tokenize(text) == _tokens_line_by_line(text), text


def test_typed_lists_with_dash_tokens_read_as_val_reads_them():
    domain = parse_domain(ORIENTED)
    assert dict(domain.predicates)["connected"] == (("?j", "joint"), ("?l", "link"))
    assert dict(domain.predicates)["next-angle"] == (("?a1", "angle"), ("?a2", "angle"))
    assert domain.requirements == (":strips", ":typing", ":adl", ":equality", ":negative-preconditions")
    problem = parse_problem(ORIENTED_PROBLEM)
    assert problem.objects_of({"joint"}) == ("j1", "j2", "j3")
    assert len(problem.objects_of({"angle"})) == 8


def test_an_action_declared_twice_is_its_first_declaration_and_a_warning():
    domain = parse_domain(ORIENTED)
    assert [a.name for a in domain.actions] == ["increase_angle", "decrease_angle"]
    assert all(len(a.parameters) == 5 for a in domain.actions)  # the first declarations: two links
    assert len(domain.warnings) == 2
    assert "increase_angle" in domain.warnings[0] and "decrease_angle" in domain.warnings[1]
    assert all("first declaration" in w for w in domain.warnings)
    assert parse_domain(RELATIVE).warnings == ()


# -- the normalised copy ----------------------------------------------------------------------------------------
def test_text_that_needs_nothing_is_handed_on_unchanged():
    assert for_external(RELATIVE, RELATIVE_PROBLEM) == (RELATIVE, RELATIVE_PROBLEM)
    assert normalised("(define (domain d", "domain") == "(define (domain d"  # the planner reports bad text


def test_the_normalised_copy_is_what_val_reads():
    copy, problem_copy = for_external(ORIENTED, ORIENTED_PROBLEM)
    assert "-joint" not in copy and copy.count("(:action increase_angle") == 1
    assert "-link" not in problem_copy and parse_problem(problem_copy) == parse_problem(ORIENTED_PROBLEM)
    ours, theirs = parse_domain(ORIENTED), parse_domain(copy)
    assert theirs.actions == ours.actions and theirs.predicates == ours.predicates and theirs.warnings == ()
    assert not any(t.startswith("-") and len(t) > 1 for t in tokenize(copy))


@pytest.mark.parametrize("planner", ["inproc", "fd-lama"])
def test_every_planner_of_the_chain_reads_the_first_declaration(planner):
    result = plan_with_fallback(ORIENTED, ORIENTED_PROBLEM, [planner], 60.0)
    assert result.status is PlanStatus.SOLVED and result.validated, result.message
    assert all(len(step[1:-1].split()) == 6 for step in result.plan)  # name and the first declaration's 5 args
    assert len(result.warnings) == 2
    assert validate_plan(ORIENTED, ORIENTED_PROBLEM, result.plan).valid
    if planner == "inproc":
        assert len(result.plan) == 7 and result.optimal is True  # 2 + 1 + 4 steps of 45 degrees


# -- the chain's VAL step ---------------------------------------------------------------------------------------
class TextAsGiven:
    """Fast Downward run on the text exactly as given, without the normalised copy: it reads both declarations
    of an action and its plan may use the later one, as planners that do not read files as VAL does."""

    name = "fd-as-given"

    def solve(self, domain: str, problem: str, timeout_s: float) -> PlanResult:
        start = time.perf_counter()
        with tempfile.TemporaryDirectory(prefix="planhrc-test-fd-") as tmp:
            Path(tmp, "domain.pddl").write_text(domain)
            Path(tmp, "problem.pddl").write_text(problem)
            run_limited([sys.executable, str(fast_downward_script()), *LAMA_FIRST, "--plan-file",
                         "sas_plan", "domain.pddl", "problem.pddl"], tmp, timeout_s)
            plan = read_best_plan(Path(tmp), "sas_plan")
        status = PlanStatus.SOLVED if plan is not None else PlanStatus.ERROR
        return PlanResult(status, plan or (), time.perf_counter() - start, self.name)


@pytest.fixture
def as_given(monkeypatch):
    monkeypatch.setitem(PLANNERS, "fd-as-given", lambda **options: TextAsGiven())


def test_a_plan_val_refuses_is_not_solved_and_the_chain_goes_on(as_given):
    first = TextAsGiven().solve(TWICE, TWICE_PROBLEM, 60.0)
    assert first.solved and not validate_plan(TWICE, TWICE_PROBLEM, first.plan).valid  # the later declaration
    result = plan_with_fallback(TWICE, TWICE_PROBLEM, ["fd-as-given", "fd-lama"], 60.0)
    refused, answered = result.attempts
    assert refused.status is PlanStatus.INVALID and "VAL rejected" in refused.message
    assert answered.status is PlanStatus.SOLVED and result.planner == "fd-lama" and result.validated
    assert result.plan == ("(finish a)", "(finish b)")


def test_a_refused_plan_and_no_other_planner_is_no_plan(as_given):
    result = plan_with_fallback(TWICE, TWICE_PROBLEM, ["fd-as-given"], 60.0)
    assert result.status is PlanStatus.ERROR and result.plan == () and not result.validated
    assert "invalid" in result.message and "VAL rejected" in result.message


def test_without_validation_the_answer_says_it_is_unvalidated(as_given):
    result = plan_with_fallback(TWICE, TWICE_PROBLEM, ["fd-as-given"], 60.0, validate=False)
    assert result.solved and not result.validated


def test_val_time_comes_out_of_the_chain_time():
    result = plan_with_fallback(RELATIVE, RELATIVE_PROBLEM, ["inproc"], 10.0)
    assert result.validated and result.seconds >= result.attempts[0].seconds


def test_plan_files_validates_by_default():
    result = plan_files(STYLES / "domain-oriented-duplicates.pddl", STYLES / "problem-oriented-4x8.pddl")
    assert result.solved and result.validated and len(result.warnings) == 2
    unchecked = plan_files(STYLES / "domain-oriented-duplicates.pddl", STYLES / "problem-oriented-4x8.pddl",
                           validate=False)
    assert unchecked.solved and not unchecked.validated


def test_cli_labels_validation_and_warnings(capsys):
    args = ["plan", str(STYLES / "domain-oriented-duplicates.pddl"), str(STYLES / "problem-oriented-4x8.pddl")]
    assert cli_main(args + ["--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["validated"] is True and len(out["warnings"]) == 2 and out["optimal"] is True
    assert out["checked_by"] == "val" and out["status"] == "solved"
    assert cli_main(args + ["--json", "--no-validate"]) == 3  # a plan, printed unvalidated: its own exit status
    out = json.loads(capsys.readouterr().out)
    assert out["validated"] is False and out["status"] == "unvalidated" and "--no-validate" in out["message"]
    assert out["checked_by"] is None and out["plan"]
    assert cli_main(args + ["--no-validate"]) == 3
    text = capsys.readouterr().out
    assert ": unvalidated in" in text and text.startswith("; warning: action increase_angle is declared again")
    assert cli_main(args) == 0
    assert "; validated by VAL on the plan as given" in capsys.readouterr().out


def test_val_judges_against_the_domain_the_caller_answers_for():
    """The planners read the oriented domain; VAL judges against the one-action-per-name copy the caller gives,
    where the plans of the first declarations are valid too; against a domain where they are not, they fail."""
    copy = for_external(ORIENTED, ORIENTED_PROBLEM)[0]
    result = plan_with_fallback(ORIENTED, ORIENTED_PROBLEM, ["inproc"], 60.0, validation_domain=copy)
    assert result.solved and result.validated
    later_only = copy.replace("(:action increase_angle", "(:action increase_angle_first", 1)
    refused = plan_with_fallback(ORIENTED, ORIENTED_PROBLEM, ["inproc"], 60.0, validation_domain=later_only)
    assert not refused.solved and refused.attempts[0].status is PlanStatus.INVALID


def test_a_kill_or_vals_own_lack_of_memory_is_no_verdict():
    from planhrc.planner.chain import val_crashed

    assert val_crashed("VAL exit code -9")
    assert val_crashed("Error occurred in validation attempt:\nstd::bad_alloc")
    assert not val_crashed("VAL exit code -11")  # how this VAL build ends a bad plan description
    assert not val_crashed("Goal not satisfied")
    assert not val_crashed("Error occurred in validation attempt:\nstd::bad_alloc\nGoal not satisfied")


def test_val_out_of_memory_is_no_verdict_not_a_refusal(monkeypatch):
    """A real VAL given too little address space for the shortest plan of a 3-link x 24 macros task (VAL accepts such
    plans with its usual space: tests/test_planner_bimanual.py) reports `std::bad_alloc`, and the chain says it has no
    verdict: the plan is kept, unvalidated, never "VAL rejected" and never solved. (Its macros are proved faithful,
    so the chain would check its expansion, which VAL checks in that space: the macro check is emptied here, so that
    VAL gets the plan as given.)"""
    from planhrc.bench.bimanual_tasks import domain_text, make_instances, problem_text
    from planhrc.planner import checking, validate
    from planhrc.planner.chain import judged, val_crashed
    from planhrc.planner.inproc import InprocPlanner
    from planhrc.planner.macros import MacroReport

    domain, problem = domain_text("macros"), problem_text(make_instances([3], [24], 1, "macros")[0])
    result = InprocPlanner().solve(domain, problem, timeout_s=30.0)
    assert result.solved and result.optimal
    monkeypatch.setattr(validate, "VAL_ADDRESS_SPACE_BYTES", 40 * 2 ** 20)
    check = validate.validate_plan(domain, problem, result.plan)
    assert not check.valid and "std::bad_alloc" in check.reason and val_crashed(check.reason)
    assert judged(result, domain, problem, 60.0).validated  # through the expansion
    monkeypatch.setattr(checking, "macro_report", lambda text: MacroReport())
    answer = judged(result, domain, problem, 60.0)
    assert answer.status is PlanStatus.UNVALIDATED and answer.plan == result.plan
    assert "without a verdict" in answer.message and not answer.validated
