"""`planhrc bench --bimanual-only` on a small slice: the chain beside a packaged planner, VAL on every plan, the files."""
import csv
import json

from planhrc.bench.bimanual import CHAIN, bimanual_report, markdown, write_report
from planhrc.bench.bimanual_tasks import make_instances
from planhrc.cli import main


def test_instances_are_fixed_by_seed_and_differ():
    a = make_instances([3, 4], [8, 24], 2, "macros")
    assert a == make_instances([3, 4], [8, 24], 2, "macros") and len(a) == 8
    assert len({(i.init, i.goal) for i in a}) == 8


def test_a_slice_of_the_grid_with_the_whole_command(tmp_path):
    report = bimanual_report([CHAIN, "fd-lama"], [3, 4], [4], 1, timeout_s=30.0, validate=True, val_timeout_s=60.0,
                             command_cell=(4, 4), progress=False)
    rows = report["rows"]
    assert len(rows) == 2 * 2 * 2  # variants x cells x planners
    chain = [r for r in rows if r["planner"] == CHAIN]
    assert all(r["status"] == "solved" and r["valid"] and r["plan_length"] == r["optimal_length"] for r in chain)
    assert all(r["decided_by"] == "inproc" and r["claimed_optimal"] for r in chain)
    lama = [r for r in rows if r["planner"] == "fd-lama" and r["status"] == "solved"]
    assert all(r["valid"] and r["plan_length"] >= r["optimal_length"] for r in lama)
    summary = {(s["variant"], s["planner"]): s for s in report["summary"]}
    assert summary[("macros", CHAIN)]["val_valid"] == 2 and summary[("macros", CHAIN)]["shortest"] == 2
    assert [c["status"] for c in report["command"]] == ["solved", "solved"]  # basic and macros, 4 links x 4
    assert all(c["plan_length"] == c["optimal_length"] for c in report["command"])
    paths = write_report(report, tmp_path)
    assert json.loads(paths[0].read_text())["machine"]["cores"]
    with paths[1].open() as fh:
        assert len(list(csv.DictReader(fh))) == 8
    text = paths[2].read_text()
    assert text == markdown(report) + "\n" and "| macros | chain | 2/2 |" in text and "Whole command" in text


def test_bench_refuses_an_unknown_bimanual_planner(tmp_path, capsys):
    code = main(["bench", "--bimanual-only", "--bimanual-planners", "chain,nosuch", "--out", str(tmp_path)])
    assert code == 2 and "nosuch" in capsys.readouterr().err


def test_field_styles_are_val_valid_in_process(tmp_path, capsys):
    """Files in the paper's benchmark styles (relative, absolute with upstream facts, oriented with actions
    declared twice and `?j -joint`): every one planned in-process and accepted by VAL."""
    from planhrc.bench.field import main as field_main

    assert field_main(["--links", "4,6", "--orientations", "4,6", "--instances", "1", "--out", str(tmp_path)]) == 0
    report = json.loads((tmp_path / "field.json").read_text())
    assert [(s["style"], s["files"], s["val_valid_in_process"]) for s in report["summary"]] == [
        ("relative", 4, 4), ("absolute", 4, 4), ("oriented", 4, 4)]
    assert all(r["warnings"] == 2 for r in report["rows"] if r["style"] == "oriented")
    assert "| oriented | 4 | 4 |" in capsys.readouterr().out


def test_val_is_not_run_where_its_expansion_would_exceed_the_limit():
    from planhrc.bench.bimanual import run_grid, val_expansion

    inst = make_instances([4], [24], 1, "macros")[0]
    assert val_expansion(inst) == 3 * 24 ** 4
    (row,) = run_grid([CHAIN], [inst], 30.0, validate=True, progress=False, val_limit=val_expansion(inst) - 1)
    assert row.status == "solved" and row.valid is None and row.val_reason.startswith("not run")
