"""`planhrc bench --bimanual` on a small slice: the chain beside a packaged planner, VAL on every plan, the files."""
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
    code = main(["bench", "--bimanual", "--bimanual-planners", "chain,nosuch", "--out", str(tmp_path)])
    assert code == 2 and "nosuch" in capsys.readouterr().err
