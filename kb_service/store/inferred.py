"""What a DL reasoner inferred, as N-Triples lines under a scope: one side table of the knowledge base's
database, outside owlready2's quad tables, so the export, the record reads and the next reasoner run never see
these facts as asserted ones."""
from __future__ import annotations

from typing import Iterator, Sequence

from .errors import ValidationError
from .owl import QuadStore

SCHEMA = "CREATE TABLE IF NOT EXISTS planhrc_inferred (scope TEXT, line TEXT)"
SCOPE_INDEX = "CREATE INDEX IF NOT EXISTS planhrc_inferred_scope ON planhrc_inferred (scope)"


class InferredFacts:
    def __init__(self, quads: QuadStore) -> None:
        self.quads = quads
        quads.execute(SCHEMA)
        quads.execute(SCOPE_INDEX)

    @staticmethod
    def check(scope: object, lines: Sequence[object]) -> list[str]:
        """Validate what to keep: a non-empty scope, N-Triples lines (each ending with ' .')."""
        if not isinstance(scope, str) or not scope:
            raise ValidationError("scope: must be a non-empty string")
        out = []
        for i, line in enumerate(lines):
            if not isinstance(line, str) or not line.rstrip().endswith("."):
                raise ValidationError(f"lines[{i}]: not an N-Triples line")
            out.append(line if line.endswith("\n") else line + "\n")
        return out

    def replace(self, scope: str, lines: Sequence[str]) -> int:
        """Replace the lines of `scope` (inside the open transaction)."""
        self.quads.execute("DELETE FROM planhrc_inferred WHERE scope = ?", (scope,))
        self.quads.db.executemany("INSERT INTO planhrc_inferred VALUES (?, ?)", [(scope, line) for line in lines])
        return len(lines)

    def lines(self) -> Iterator[str]:
        for (line,) in self.quads.execute("SELECT line FROM planhrc_inferred ORDER BY rowid").fetchall():
            yield str(line)
