"""What a DL reasoner inferred, in the PostgreSQL store: N-Triples lines under a scope in a table of their own
(`planhrc_inferred`), beside the ABox's triples and never among them, so the export, the record reads and the next
reasoner run never take these facts for asserted ones (as `..inferred` keeps them in the SQLite store).

Lines are checked by the core (`..checks.check_inferred`), as for the SQLite store. A scope is replaced in one transaction that holds
the scope's advisory lock: two processes replacing the same scope at once take turns, and the second one's delete
sees the first one's lines (without the lock it would not, and both sets would stay).
"""
from __future__ import annotations

from typing import Sequence

from .session import Session

LOCK_NAMESPACE = "planhrc-inferred:"  # hashed with the scope into the advisory lock's key


class PgInferred:
    """The inferred lines of one PostgreSQL store; every method is called with the store's lock held."""

    def __init__(self, session: Session) -> None:
        self._session = session

    def replace(self, scope: str, lines: Sequence[str]) -> int:
        """Replace the lines of `scope` by checked `lines` (inside the open transaction)."""
        s = self._session
        s.execute("SELECT pg_advisory_xact_lock(hashtextextended(%s, 0))", (LOCK_NAMESPACE + scope,))
        s.execute("DELETE FROM planhrc_inferred WHERE scope = %s", (scope,))
        with s.conn.cursor().copy("COPY planhrc_inferred (scope, line) FROM STDIN") as copy:
            for line in lines:
                copy.write_row((scope, line))
        return len(lines)

    def lines(self) -> list[str]:
        """Every line of every scope, in the order they were stored."""
        return [str(line) for (line,) in self._session.execute("SELECT line FROM planhrc_inferred ORDER BY seq")]
