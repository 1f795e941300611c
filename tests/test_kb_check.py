"""`planhrc ontology check` and `planhrc ontology bench-subsumption`."""
from __future__ import annotations

import argparse

import pytest

from planhrc.kb_service.check import add_ontology_parser, check_ontology
from planhrc.kb_service.store import SqliteStore
from planhrc.model import make_object
from planhrc.paths import default_tbox_path


def _run(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(prog="planhrc")
    add_ontology_parser(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(argv)
    return args.func(args)


def test_bench_subsumption_prints_percentiles(capsys):
    assert _run(["ontology", "bench-subsumption", "--runs", "200"]) == 0
    out = capsys.readouterr().out
    assert "p50" in out and "p95" in out and "282 atoms" in out


def test_check_with_missing_db_fails(tmp_path, capsys):
    assert _run(["ontology", "check", "--db", str(tmp_path / "nope.sqlite3")]) == 1
    assert "no such file" in capsys.readouterr().err


@pytest.mark.reasoner
@pytest.mark.parametrize("reasoner", ["pellet", "hermit"])
def test_check_stored_kb(tmp_path, capsys, reasoner):
    db = tmp_path / "kb.sqlite3"
    with SqliteStore(str(db), default_tbox_path()) as kb:
        obj = make_object("obj1", "absolute", 3, 4)
        kb.create_object(obj)
        kb.add_state("obj1", "perceived", obj.state([0, 90, 180]), [0.0, 90.0, 180.0])
    assert _run(["ontology", "check", "--reasoner", reasoner, "--db", str(db)]) == 0
    out = capsys.readouterr().out
    assert "consistent: yes" in out and "classes: " in out and "inferred facts: " in out
    report = check_ontology(default_tbox_path(), None, reasoner)
    assert report.consistent
