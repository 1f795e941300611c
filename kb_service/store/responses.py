"""Idempotent responses: the first answer given under an `Idempotency-Key`, so a retried request gets it again.
One side table of the SQLite store's database (a response is checked by `checks.check_response` before)."""
from __future__ import annotations

import json
from typing import Any

from .owl import QuadStore

SCHEMA = "CREATE TABLE IF NOT EXISTS planhrc_response (object_id TEXT, key TEXT, response TEXT, PRIMARY KEY (object_id, key))"


class ResponseMemory:
    def __init__(self, quads: QuadStore) -> None:
        self.quads = quads
        quads.execute(SCHEMA)

    def recall(self, object_id: str, key: str) -> dict[str, Any] | None:
        row = self.quads.execute("SELECT response FROM planhrc_response WHERE object_id=? AND key=?",
                                 (str(object_id), str(key))).fetchone()
        return json.loads(row[0]) if row else None

    def remember(self, object_id: str, key: str, text: str) -> None:
        """Remember a checked response (inside the open transaction); the first one stored under a key wins."""
        self.quads.execute("INSERT OR IGNORE INTO planhrc_response VALUES (?,?,?)", (str(object_id), key, text))
