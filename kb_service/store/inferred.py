"""What a DL reasoner inferred, as N-Triples lines under a scope: one side table of the knowledge base's
database, outside owlready2's quad tables, so the export, the record reads and the next reasoner run never see
these facts as asserted ones (the lines are checked by `checks.check_inferred` before)."""
from __future__ import annotations

from typing import Iterator, Sequence

from .owl import QuadStore

SCHEMA = "CREATE TABLE IF NOT EXISTS planhrc_inferred (scope TEXT, line TEXT)"
SCOPE_INDEX = "CREATE INDEX IF NOT EXISTS planhrc_inferred_scope ON planhrc_inferred (scope)"


class InferredFacts:
    def __init__(self, quads: QuadStore) -> None:
        self.quads = quads
        quads.execute(SCHEMA)
        quads.execute(SCOPE_INDEX)

    def replace(self, scope: str, lines: Sequence[str]) -> int:
        """Replace the lines of `scope` (inside the open transaction)."""
        self.quads.execute("DELETE FROM planhrc_inferred WHERE scope = ?", (scope,))
        self.quads.db.executemany("INSERT INTO planhrc_inferred VALUES (?, ?)", [(scope, line) for line in lines])
        return len(lines)

    def lines(self) -> Iterator[str]:
        for (line,) in self.quads.execute("SELECT line FROM planhrc_inferred ORDER BY rowid").fetchall():
            yield str(line)
