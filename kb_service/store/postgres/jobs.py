"""The planning job queue in PostgreSQL: one row a job, served by `planhrc planning-worker` processes on any host
(`planning_queue`).

A job is a value the service pickles (`planning_pool.PlanningJob`) and its outcome the frames the service's own
planning pool sends (`planning_pool.pack_outcome`); both are opaque here. Every time is the database's clock
(`now()`), so hosts need not agree on theirs: a job's deadline is stored as `now()` plus the seconds it has left, a
worker learns from the row how many seconds are left, and a lease is `now()` plus its length.

* **Submit**: a row `queued`, announced on `JOB_CHANNEL` when it commits.
* **Claim**: a worker takes the oldest row that is queued, or running on a lease that expired (its worker stopped
  renewing it: killed, or cut off), and whose deadline is more than `MIN_LEFT_S` away, with `FOR UPDATE SKIP
  LOCKED` (two workers never take the same row, and neither waits for the other); a job past its deadline is never
  started.
* **Renew**: a worker extends its lease while it plans; a row taken over by another worker, or withdrawn, is not
  its own any more (the renewal finds nothing).
* **Finish**: the outcome stored on the row, if the row is still the worker's, announced on `DONE_CHANNEL`; a
  worker whose lease was taken over finds nothing to finish, so a job has one outcome.
* **Collect** (the service): the outcome taken with the row in one `DELETE`; **withdraw**: the row deleted when the
  service stops waiting (its deadline passed), whatever its state.
* **Hand back**: a worker that stops (SIGTERM) returns its running job to the queue.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

JOB_CHANNEL = "planhrc_planning_job"  # a job was queued: workers wake
DONE_CHANNEL = "planhrc_planning_done"  # payload: the job's id, once its outcome is stored
MIN_LEFT_S = 0.05  # a job with less time left than this is not started
FORGOTTEN_S = 600  # rows of jobs this far past their deadline are deleted (their service is gone)

JOB_TABLES = (
    "CREATE TABLE IF NOT EXISTS planhrc_planning_job (id bigserial PRIMARY KEY, object_id text NOT NULL,"
    " job bytea NOT NULL, deadline timestamptz NOT NULL, state text NOT NULL DEFAULT 'queued',"
    " worker text, lease_until timestamptz, attempts integer NOT NULL DEFAULT 0, outcome bytea,"
    " created_at timestamptz NOT NULL DEFAULT now(), CHECK (state IN ('queued', 'running', 'done')))",
    "CREATE INDEX IF NOT EXISTS planhrc_planning_job_open ON planhrc_planning_job (id) WHERE state <> 'done'",
    # the trace context of the request that queued the job (W3C traceparent; null when it was not traced)
    # (a look first: each worker's connection runs these, and an ALTER TABLE locks the table even when it finds the
    # column)
    "DO $$ BEGIN IF NOT EXISTS (SELECT 1 FROM information_schema.columns WHERE table_schema = current_schema() "
    "AND table_name = 'planhrc_planning_job' AND column_name = 'trace') THEN ALTER TABLE planhrc_planning_job ADD COLUMN trace text; "
    "END IF; END $$",
)

SUBMIT = ("WITH j AS (INSERT INTO planhrc_planning_job (object_id, job, deadline, trace) "
          "VALUES (%s, %s, now() + make_interval(secs => %s), %s) RETURNING id) "
          f"SELECT id, pg_notify('{JOB_CHANNEL}', id::text) FROM j")
# A claim returns, besides the job, whether it was taken over (running, on a lease that expired) and its trace.
CLAIM = ("WITH old AS (SELECT id, state FROM planhrc_planning_job WHERE (state = 'queued' OR (state = 'running' AND "
         f"lease_until < now())) AND deadline > now() + make_interval(secs => {MIN_LEFT_S}) "
         "ORDER BY id LIMIT 1 FOR UPDATE SKIP LOCKED) "
         "UPDATE planhrc_planning_job j SET state = 'running', worker = %(worker)s, attempts = j.attempts + 1, "
         "lease_until = now() + make_interval(secs => %(lease)s) FROM old WHERE j.id = old.id "
         "RETURNING j.id, j.object_id, j.job, extract(epoch FROM j.deadline - now())::float8, j.attempts, "
         "old.state = 'running', j.trace")
DEPTH = ("SELECT state, count(*) FROM planhrc_planning_job WHERE state <> 'done' AND deadline > now() "
         "GROUP BY state")
RENEW = ("UPDATE planhrc_planning_job SET lease_until = now() + make_interval(secs => %s) "
         "WHERE id = %s AND worker = %s AND state = 'running' RETURNING id")
FINISH = ("WITH d AS (UPDATE planhrc_planning_job SET state = 'done', outcome = %s, lease_until = NULL "
          "WHERE id = %s AND worker = %s AND state = 'running' RETURNING id) "
          f"SELECT pg_notify('{DONE_CHANNEL}', id::text) FROM d")
HAND_BACK = ("WITH b AS (UPDATE planhrc_planning_job SET state = 'queued', worker = NULL, lease_until = NULL "
             "WHERE id = %s AND worker = %s AND state = 'running' RETURNING id) "
             f"SELECT pg_notify('{JOB_CHANNEL}', id::text) FROM b")
COLLECT = "DELETE FROM planhrc_planning_job WHERE id = %s AND state = 'done' RETURNING outcome"
WITHDRAW = "DELETE FROM planhrc_planning_job WHERE id = %s"
FORGET = f"DELETE FROM planhrc_planning_job WHERE deadline < now() - make_interval(secs => {FORGOTTEN_S})"


@dataclass(frozen=True)
class Claimed:
    """A claimed row: the job's id, its object, the pickled job, the seconds left, the attempts so far (this one
    included), whether it was taken over from a worker whose lease expired, and the trace context it carries."""

    id: int
    object_id: str
    blob: bytes
    left: float
    attempts: int
    taken_over: bool
    trace: str | None


def claimed(row: Any) -> Claimed | None:
    if row is None:
        return None
    return Claimed(int(row[0]), str(row[1]), bytes(row[2]), float(row[3]), int(row[4]), bool(row[5]),
                   None if row[6] is None else str(row[6]))
