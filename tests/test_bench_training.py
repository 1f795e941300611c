"""`python -m planhrc.bench.training` on a folder laid out as the training sample, from the published files in
`tests/data/bimanual`: every problem answered by the whole command, validated (through the expansion where the plan
has macro steps), never longer than the authors' plan; an anchor beside it; and the folder checked where it enters."""
from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from planhrc.bench.training import broken, main, sample, with_actions_of
from planhrc.planner.macros import macro_report

DATA = Path(__file__).parent / "data" / "bimanual"


@pytest.fixture
def sample_dir(tmp_path: Path) -> Path:
    for sub in ("problems", "plans", "domains"):
        (tmp_path / sub).mkdir()
    for path in DATA.glob("batch*.pddl"):
        shutil.copy(path, tmp_path / "problems")
        shutil.copy(path.with_suffix(".plan"), tmp_path / "plans")
    for name in ("domain_m_0.pddl", "domain_m_25_B.pddl"):
        shutil.copy(DATA / name, tmp_path / "domains")
    return tmp_path


def test_the_sample_takes_each_stratum_and_the_macro_free_domain_gains_the_macros(sample_dir):
    chosen = sample(sample_dir, 1, 7)
    assert [p.stem for p in chosen] == sorted(p.stem for p in DATA.glob("batch*.pddl"))  # one stratum each
    combined = with_actions_of((DATA / "domain_m_0.pddl").read_text(), (DATA / "domain_m_25_B.pddl").read_text())
    assert set(macro_report(combined).faithful) == {"link-to-central-grasp", "increase_angle_first_child_45",
                                                    "decrease_angle_first_child_45"}
    plan = ("(release-links l2 l1 j1 g1 g2)", "(increase_angle_first_child l2 l1 j1 angle0 angle15 g1 g2)")
    assert broken(plan) == (plan[0], "(increase_angle_first_child l2 l1 j1 angle15 angle15 g1 g2)")
    assert broken(plan[:1]) is None


def test_the_bench_answers_every_published_problem_validated_and_never_longer(sample_dir, tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["--data", str(sample_dir), "--per-stratum", "1", "--anchors", "bfws", "--timeout", "60",
                 "--anchor-timeout", "1",
                 "--as-given-timeout", "0", "--out", str(out), "--no-progress"]) == 0
    report = json.loads((out / "training.json").read_text())
    assert "| domain_m_25_B | planhrc plan | 4/4 |" in (out / "training.md").read_text()
    summary = {(s["domain"], s["planner"]): s for s in report["summary"]}
    for domain in ("domain_m_25_B", "domain_m_0"):
        ours = summary[(domain, "planhrc plan")]
        assert ours["solved_validated"] == ours["not_longer"] == 4 and ours["invalid"] == ours["unvalidated"] == 0
        assert (domain, "bfws") in summary  # the anchor ran beside it, in the same run
    assert summary[("domain_m_25_B", "planhrc plan")]["by_expansion"] >= 1
    assert summary[("domain_m_0", "planhrc plan")]["by_expansion"] == 0  # nothing to expand there
    rows = [r for r in report["rows"] if r["planner"] == "planhrc plan"]
    assert all(r["exit"] == 0 and r["checked_by"] in ("val", "val-expansion") for r in rows)


@pytest.mark.parametrize("make, says", [
    (lambda root: root / "dataset" / "test", "the authors' test set"),
    (lambda root: root / "empty", "no problems in"),
])
def test_a_bad_data_folder_is_refused_in_one_line(tmp_path, make, says):
    folder = make(tmp_path)
    folder.mkdir(parents=True)
    run = subprocess.run([sys.executable, "-m", "planhrc.bench.training", "--data", str(folder)],
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 2 and says in run.stderr and len(run.stderr.strip().splitlines()) == 1
    assert "Traceback" not in run.stderr
