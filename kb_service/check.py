"""`planhrc ontology check` (a DL reasoner on the TBox, or on the TBox with a store's ABox: consistency, classes,
inferred facts) and `planhrc ontology bench-subsumption` (the in-process subsumption check's latency)."""
from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass
from pathlib import Path

from planhrc.cli_args import int_in, positive_float, positive_int, tbox_file
from planhrc.paths import default_tbox_path

from .store.errors import KBError
from .store.location import shown_location
from .reasoner import REASONERS, ReasonerReport, run_reasoner


@dataclass(frozen=True)
class CheckReport:
    reasoner: str
    tbox_path: str
    db_path: str | None
    report: ReasonerReport

    @property
    def consistent(self) -> bool:
        return self.report.consistent


def check_ontology(tbox_path: Path | str, db_path: str | None, reasoner: str, timeout_s: float = 300.0) -> CheckReport:
    """Run a reasoner on the TBox alone, or on the TBox plus the ABox stored in `db_path`.

    Raises ReasonerError when the reasoner cannot run, KBError when the files cannot be opened.
    """
    from owlready2 import World

    from .store import TBOX_IRI, open_store
    from .store.backends import backend_of

    tbox_path = Path(tbox_path)
    if not tbox_path.is_file():
        raise KBError(f"tbox: no such file {tbox_path}")
    if db_path is not None:
        if backend_of(db_path) == "sqlite" and not Path(db_path).is_file():
            raise KBError(f"db: no such file {db_path}")
        with open_store(db_path, tbox_path) as kb:  # a server's password: PGPASSFILE or PGPASSWORD
            report = run_reasoner(kb, reasoner, timeout_s)
    else:
        world = World()
        try:
            with open(tbox_path, "rb") as f:
                world.get_ontology(TBOX_IRI).load(fileobj=f)
            report = run_reasoner(world, reasoner, timeout_s)
        finally:
            world.close()
    return CheckReport(reasoner, str(tbox_path), db_path, report)


def add_ontology_parser(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> argparse.ArgumentParser:
    parser = subparsers.add_parser("ontology", help="check the ontology with a DL reasoner; benchmark subsumption")
    sub = parser.add_subparsers(dest="ontology_command", required=True, metavar="SUBCOMMAND")
    check = sub.add_parser("check", help="consistency, classes and inferred facts of the TBox (and a stored ABox)")
    check.add_argument("--reasoner", choices=list(REASONERS), default="pellet")
    check.add_argument("--db", default=None,
                       help="store whose ABox to include: a SQLite file or a PostgreSQL URL (password: PGPASSFILE)")
    check.add_argument("--tbox", type=tbox_file, default=None, help="TBox file (default: the repository's)")
    check.add_argument("--timeout", type=positive_float, default=300.0, help="reasoner time limit in seconds")
    bench = sub.add_parser("bench-subsumption", help="p50/p95 of one in-process subsumption check (20 links)")
    bench.add_argument("--runs", type=positive_int, default=10_000)
    bench.add_argument("--links", type=int_in(2), default=20)
    parser.set_defaults(func=run_ontology)
    return parser


def run_ontology(args: argparse.Namespace) -> int:
    if args.ontology_command == "bench-subsumption":
        from .subsumption import bench_subsumption

        b = bench_subsumption(runs=args.runs, links=args.links)
        print(f"subsumption check, {args.links} links "
              f"({b.atoms_s1} atoms vs {b.atoms_s2}), {b.runs} runs: "
              f"p50 {b.p50_us:.2f} us, p95 {b.p95_us:.2f} us, mean {b.mean_us:.2f} us")
        return 0
    try:
        result = check_ontology(args.tbox or default_tbox_path(), args.db, args.reasoner, args.timeout)
    except KBError as exc:
        print(f"planhrc ontology check: {exc}", file=sys.stderr)
        return 1
    r = result.report
    print(f"reasoner: {result.reasoner}")
    print(f"ontology: {result.tbox_path}" + (f" + ABox {shown_location(result.db_path)}" if result.db_path else ""))
    print(f"consistent: {'yes' if r.consistent else 'no'}")
    print(f"classes: {r.classes}")
    print(f"inferred facts: {r.inferred_facts}")
    print(f"seconds: {r.seconds:.2f}")
    for note in r.notes:
        print(f"note: {note}")
    return 0 if r.consistent else 1
