"""Every available planner backend, both formulations: status contract, VAL-checked plans, clean-up, registry."""
import json
import sys
import random
import tempfile
from pathlib import Path

import pytest

from planhrc.model import make_object
from planhrc.planner import Planner, PlannerError, PlanStatus, available_planners, get_planner, plan_files, validate_plan
from planhrc.planner.cli import main as cli_main
from planhrc.planner.fast_downward import has_conditional_effects
from planhrc.planner.registry import PLANNERS
from planhrc.translator.problem import get_problem

DATA = Path(__file__).parent / "data"
DOMAINS = {f: (DATA / f"domain-{f}.pddl").read_text() for f in ("relative", "absolute", "absolute-paper")}
PAPER = {"relative": DOMAINS["relative"], "absolute": DOMAINS["absolute-paper"]}
FORMULATIONS = ["relative", "absolute"]
BACKENDS = available_planners()
EXTERNAL = [name for name in BACKENDS if name in ("probe", "madagascar")]


def small_case(formulation: str, n_links: int, k: int, seed: int, domain_name: str | None = None) -> str:
    rng = random.Random(seed)
    obj = make_object("obj1", formulation, n_links, k)
    init = [rng.choice(obj.orientation_degrees) for _ in obj.joint_indices]
    goal = {("hasorientation", f"deg_{rng.choice(obj.orientation_degrees)}", obj.joint(j))
            for j in obj.joint_indices if rng.random() < 0.7} or {("hasorientation", "deg_0", obj.joint(1))}
    return get_problem(obj, obj.configuration_atoms(init), goal, f"small-{seed}", domain_name)


def unsolvable_relative() -> str:
    """The golden relative problem with joint j2 cut off from link l3 and a goal that needs j2 to move."""
    text = (DATA / "problem-relative-3x4.pddl").read_text().replace("(connected obj1_j2 obj1_l3)", "")
    head, sep, goal = text.partition("(:goal")
    return head + sep + goal.replace("(hasorientation deg_90 obj1_j2)", "(hasorientation deg_0 obj1_j2)")


@pytest.fixture
def private_tmp(tmp_path, monkeypatch):
    """A private temporary root, so concurrent runs elsewhere cannot disturb the clean-up checks."""
    root = tmp_path / "tmp"
    root.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(root))
    return root


def test_registry_names():
    assert set(PLANNERS) == {"inproc", "fd-lama", "fd-opt", "symk", "bfws", "probe", "madagascar"}
    assert {"inproc", "fd-lama", "fd-opt"} <= set(BACKENDS)


@pytest.mark.parametrize("name", BACKENDS)
def test_every_backend_implements_the_protocol(name):
    planner = get_planner(name)
    assert isinstance(planner, Planner) and planner.name == name


def test_unknown_planner_names_the_known_ones():
    with pytest.raises(PlannerError, match="fd-lama"):
        get_planner("lama")


def test_external_planner_needs_a_binary(monkeypatch):
    monkeypatch.delenv("PLANHRC_PROBE", raising=False)
    with pytest.raises(PlannerError, match="PLANHRC_PROBE"):
        get_planner("probe")
    assert "probe" not in available_planners()
    with pytest.raises(PlannerError, match="not an executable"):
        get_planner("probe", binary="/nonexistent/probe")


def test_bad_option_is_refused():
    with pytest.raises(PlannerError, match="unknown option"):
        get_planner("fd-lama", colour="blue")


@pytest.mark.parametrize("name", BACKENDS)
@pytest.mark.parametrize("formulation", FORMULATIONS)
def test_golden_fixture_solved_and_valid(name, formulation):
    problem = (DATA / f"problem-{formulation}-3x4.pddl").read_text()
    result = get_planner(name).solve(DOMAINS[formulation], problem, 60.0)
    assert result.status is PlanStatus.SOLVED, result.message
    assert result.planner == name
    assert all(step == step.lower() and step.startswith("(") and step.endswith(")") for step in result.plan)
    check = validate_plan(PAPER[formulation], problem, result.plan)
    assert check.valid, check.reason


@pytest.mark.parametrize("formulation", FORMULATIONS)
@pytest.mark.parametrize("seed", range(3))
def test_inproc_matches_fd_opt_length(formulation, seed):
    problem = small_case(formulation, 4, 4, seed)
    exact = get_planner("fd-opt").solve(DOMAINS[formulation], problem, 120.0)
    fast = get_planner("inproc").solve(DOMAINS[formulation], problem, 5.0)
    assert exact.status is PlanStatus.SOLVED and fast.status is PlanStatus.SOLVED
    assert exact.optimal is True and fast.optimal is True
    assert len(fast.plan) == len(exact.plan)


@pytest.mark.parametrize("seed", range(4))
def test_inproc_matches_fd_opt_on_the_paper_domain(seed):
    """The paper's schema (no guard) goes through the chain DP: its length must equal A* with hmax."""
    problem = small_case("absolute", 4, 4, seed, domain_name="planhrc-absolute-paper")
    exact = get_planner("fd-opt").solve(DOMAINS["absolute-paper"], problem, 120.0)
    fast = get_planner("inproc").solve(DOMAINS["absolute-paper"], problem, 5.0)
    assert exact.status is PlanStatus.SOLVED and fast.status is PlanStatus.SOLVED
    assert fast.optimal is True
    assert len(fast.plan) == len(exact.plan)


@pytest.mark.parametrize("name", [n for n in BACKENDS if n != "inproc"])
def test_unsolvable_is_a_status(name):
    problem = unsolvable_relative()
    result = get_planner(name).solve(DOMAINS["relative"], problem, 60.0)
    assert result.status is PlanStatus.UNSOLVABLE, result.message
    assert result.plan == ()


def test_inproc_unsolvable_is_a_status():
    problem = unsolvable_relative()
    result = get_planner("inproc").solve(DOMAINS["relative"], problem, 5.0)
    assert result.status is PlanStatus.UNSOLVABLE


@pytest.mark.parametrize("name", [n for n in BACKENDS if n != "inproc"])
def test_timeout_is_a_status_and_leaves_no_temp_files(name, private_tmp):
    problem = small_case("absolute", 20, 12, seed=1)
    result = get_planner(name).solve(DOMAINS["absolute"], problem, 0.05)
    assert result.status is PlanStatus.TIMEOUT
    assert result.seconds < 5.0
    assert list(private_tmp.iterdir()) == []


@pytest.mark.parametrize("name", [n for n in BACKENDS if n.startswith("fd-")])
def test_fast_downward_leaves_no_temp_files(name, private_tmp):
    result = get_planner(name).solve(DOMAINS["relative"], (DATA / "problem-relative-3x4.pddl").read_text(), 60.0)
    assert result.status is PlanStatus.SOLVED
    assert list(private_tmp.iterdir()) == []


@pytest.mark.parametrize("name", BACKENDS)
def test_garbage_pddl_is_an_error_status(name):
    result = get_planner(name).solve("(define (domain broken", "(define (problem p))", 30.0)
    assert result.status is PlanStatus.ERROR
    assert result.plan == ()


def test_fd_opt_picks_a_config_that_supports_conditional_effects():
    fd = get_planner("fd-opt")
    assert has_conditional_effects(DOMAINS["absolute"]) and not has_conditional_effects(DOMAINS["relative"])
    assert fd.search_args(DOMAINS["relative"]) == ("--alias", "seq-opt-lmcut")
    assert "lmcut" not in " ".join(fd.search_args(DOMAINS["absolute"]))


# -- VAL ---------------------------------------------------------------------------------------------------
GOLDEN_ABSOLUTE_PLAN = (
    "(rotateclockwise obj1_l1 obj1_l0 obj1_j1 deg_0 deg_90)",
    "(rotateanticlockwise obj1_l2 obj1_l1 obj1_j2 deg_180 deg_90)",
    "(rotateclockwise obj1_l3 obj1_l2 obj1_j3 deg_180 deg_270)",
    "(rotateclockwise obj1_l3 obj1_l2 obj1_j3 deg_270 deg_0)",
)


def test_validate_accepts_a_valid_plan():
    problem = (DATA / "problem-absolute-3x4.pddl").read_text()
    result = validate_plan(DOMAINS["absolute-paper"], problem, GOLDEN_ABSOLUTE_PLAN)
    assert result.valid and result.reason == "Plan valid"
    assert result.seconds > 0


def test_validate_reports_the_wrong_step():
    problem = (DATA / "problem-absolute-3x4.pddl").read_text()
    wrong = ("(rotateclockwise obj1_l1 obj1_l0 obj1_j1 deg_90 deg_180)",) + GOLDEN_ABSOLUTE_PLAN[1:]
    result = validate_plan(DOMAINS["absolute-paper"], problem, wrong)
    assert not result.valid
    assert "unsatisfied precondition" in result.reason
    assert "(rotateclockwise obj1_l1 obj1_l0 obj1_j1 deg_90 deg_180)" in result.reason


def test_validate_reports_the_unmet_goal():
    problem = (DATA / "problem-absolute-3x4.pddl").read_text()
    result = validate_plan(DOMAINS["absolute-paper"], problem, GOLDEN_ABSOLUTE_PLAN[:-1])
    assert not result.valid
    assert "Goal not satisfied" in result.reason
    assert "(hasorientation deg_0 obj1_j3)" in result.reason


def test_validate_leaves_no_temp_files(private_tmp):
    validate_plan(DOMAINS["absolute-paper"], (DATA / "problem-absolute-3x4.pddl").read_text(), GOLDEN_ABSOLUTE_PLAN)
    assert list(private_tmp.iterdir()) == []


# -- files and CLI -----------------------------------------------------------------------------------------
def test_plan_files_and_cli_json(capsys):
    domain, problem = DATA / "domain-absolute.pddl", DATA / "problem-absolute-3x4.pddl"
    result = plan_files(domain, problem, "inproc", 5.0)
    assert result.status is PlanStatus.SOLVED
    code = cli_main(["plan", str(domain), str(problem), "--planner", "inproc", "--timeout", "5", "--json"])
    out = json.loads(capsys.readouterr().out)
    assert code == 0
    assert out["status"] == "solved" and out["planner"] == "inproc"
    assert tuple(out["plan"]) == result.plan and isinstance(out["seconds"], float)


def test_cli_exit_code_is_one_when_not_solved(capsys, tmp_path):
    problem = (DATA / "problem-relative-3x4.pddl").read_text().replace("(orientationord deg_270 deg_0)", "")
    path = tmp_path / "p.pddl"
    path.write_text(problem)
    code = cli_main(["plan", str(DATA / "domain-relative.pddl"), str(path), "--no-fallback", "--json"])
    assert code == 1
    assert json.loads(capsys.readouterr().out)["status"] == "error"


def test_plan_files_refuses_missing_file(tmp_path):
    with pytest.raises(PlannerError, match="cannot read"):
        plan_files(tmp_path / "nope.pddl", DATA / "problem-relative-3x4.pddl", "inproc", 5.0)


# -- external planners (only with a configured binary) ------------------------------------------------------
@pytest.mark.slow
@pytest.mark.parametrize("name", ["probe", "madagascar"])
def test_external_planner_small_instance(name):
    if name not in EXTERNAL:
        pytest.skip(f"no {name} binary configured (set PLANHRC_{name.upper()} to its path to run this test)")
    problem = small_case("relative", 4, 4, seed=2)
    result = get_planner(name).solve(DOMAINS["relative"], problem, 60.0)
    assert result.status is PlanStatus.SOLVED, result.message
    assert validate_plan(DOMAINS["relative"], problem, result.plan).valid


# -- the external backend's contract, with a stand-in planner script -------------------------------------
FAKE_PLANNER = """#!{python}
import sys, time
args = sys.argv[1:]
mode = {mode!r}
plan = args[args.index("-o") + 1] if "-o" in args else None
if mode == "sleep":
    time.sleep(30)
elif mode == "unsolvable":
    print("Problem is UNSOLVABLE")
    sys.exit(1)
elif mode == "crash":
    print("segmentation fault", file=sys.stderr)
    sys.exit(139)
else:
    with open(plan + ".1", "w") as f:
        f.write("; first plan\\n(A B)\\n(c d)\\n")
    with open(plan + ".2", "w") as f:
        f.write("0: (ROTATECLOCKWISE obj1_l2 obj1_l1 obj1_j1 deg_0 deg_90)\\n; cost 1\\n")
"""


def fake_planner(tmp_path, mode: str) -> Path:
    path = tmp_path / f"fake-{mode}"
    path.write_text(FAKE_PLANNER.format(python=sys.executable, mode=mode))
    path.chmod(0o755)
    return path


@pytest.mark.parametrize("name", ["probe", "madagascar"])
def test_external_backend_reads_the_last_plan(name, tmp_path, private_tmp):
    planner = get_planner(name, binary=str(fake_planner(tmp_path, "plan")))
    result = planner.solve(DOMAINS["relative"], (DATA / "problem-relative-3x4.pddl").read_text(), 10.0)
    assert result.status is PlanStatus.SOLVED and result.planner == name
    assert result.plan == ("(rotateclockwise obj1_l2 obj1_l1 obj1_j1 deg_0 deg_90)",)
    assert list(private_tmp.iterdir()) == []


@pytest.mark.parametrize("mode,status", [("sleep", PlanStatus.TIMEOUT), ("unsolvable", PlanStatus.UNSOLVABLE),
                                         ("crash", PlanStatus.ERROR)])
def test_external_backend_statuses(mode, status, tmp_path, private_tmp):
    planner = get_planner("probe", binary=str(fake_planner(tmp_path, mode)))
    result = planner.solve(DOMAINS["relative"], (DATA / "problem-relative-3x4.pddl").read_text(), 0.5)
    assert result.status is status, result.message
    assert result.seconds < 5.0
    assert list(private_tmp.iterdir()) == []


def test_available_planners_includes_configured_external(tmp_path, monkeypatch):
    monkeypatch.setenv("PLANHRC_MADAGASCAR", str(fake_planner(tmp_path, "plan")))
    assert "madagascar" in available_planners()
    assert "probe" in available_planners({"probe": str(fake_planner(tmp_path, "plan"))})
