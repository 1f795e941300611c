"""`planhrc bench` runs the grid, re-planning and the bimanual grid in one run, and `bench.tables` writes the
README's tables from that run's files only."""
import json

import pytest

from planhrc.bench.errors import BenchError
from planhrc.bench.tables import BEGIN, END, load_run, main as tables_main, replace_block
from planhrc.cli import main


@pytest.fixture(scope="module")
def one_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("one-run")
    code = main(["bench", "--planners", "inproc", "--formulations", "relative,absolute", "--links", "4",
                 "--orientations", "4", "--instances", "1", "--replan", "--replan-runs", "2", "--fd-runs", "1",
                 "--no-http", "--bimanual", "--bimanual-links", "3", "--bimanual-orientations", "4",
                 "--bimanual-planners", "chain", "--bimanual-instances", "1", "--no-progress", "--out", str(out)])
    assert code == 0
    return out


def test_every_file_of_the_run_carries_one_run_record(one_run):
    runs = [json.loads((one_run / name).read_text())["run"] for name in ("bench.json", "replan.json", "bimanual.json")]
    assert runs[0] == runs[1] == runs[2] and runs[0]["parts"] == ["replan", "grid", "bimanual"]
    reports = load_run(one_run)
    assert [s["solved_valid"] for s in reports["bench.json"]["summary"]] == [1, 1]


def test_the_readme_block_is_written_from_the_run_and_checked(one_run, tmp_path, capsys):
    readme = tmp_path / "README.md"
    readme.write_text(f"# x\n\nbefore\n{BEGIN}\nold\n{END}\nafter\n")
    args = ["--results", str(one_run), "--readme", str(readme)]
    assert tables_main([*args, "--check"]) == 1
    assert tables_main(args) == 0
    text = readme.read_text()
    assert text.startswith("# x\n\nbefore\n") and text.endswith(f"{END}\nafter\n") and "old" not in text
    assert "| relative | inproc | 1/1 | 1 | 1 |" in text and "| macros | chain | 1/1 | 1, 0 | 1 |" in text
    assert tables_main([*args, "--check"]) == 0


def test_files_of_two_runs_are_refused(one_run, tmp_path, capsys):
    for name in ("bench.json", "replan.json", "bimanual.json"):
        (tmp_path / name).write_text((one_run / name).read_text())
    other = json.loads((tmp_path / "bimanual.json").read_text())
    other["run"] = {**other["run"], "id": "another"}
    (tmp_path / "bimanual.json").write_text(json.dumps(other))
    with pytest.raises(BenchError, match="different runs"):
        load_run(tmp_path)
    readme = tmp_path / "README.md"
    readme.write_text(f"{BEGIN}\n{END}\n")
    assert tables_main(["--results", str(tmp_path), "--readme", str(readme)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "bimanual.json: another" in err
    assert readme.read_text() == f"{BEGIN}\n{END}\n"  # nothing changed


def test_a_readme_without_its_markers_is_refused():
    with pytest.raises(BenchError, match="bench:begin"):
        replace_block("no markers here", "table")


def test_the_readme_holds_the_tables_of_the_committed_run():
    """The README's planning, re-planning and bimanual tables are those `bench.tables` writes from the one run's files
    in docs/results/one-run, and those files come from one run."""
    from pathlib import Path

    repo = Path(__file__).resolve().parents[1]
    assert tables_main(["--results", str(repo / "docs/results/one-run"), "--readme", str(repo / "README.md"),
                        "--check"]) == 0
