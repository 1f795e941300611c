"""Readiness (`GET /health/ready`): may this process take traffic? Its store's database answers a query within
`READY_WAIT_S`, the TBox is loaded, and planning is reachable (`reachable()` of the planning pool or queue)."""
from __future__ import annotations

from typing import Any

import anyio
from fastapi import Request

READY_WAIT_S = 2.0


async def usecases_ready(request: Request) -> dict[str, str]:
    """Each check's result: `ok` or why not."""
    state = request.app.state
    context = getattr(state, "context", None)
    if context is None:  # before start-up finished, or after shutdown began
        return {"store": "not open", "tbox": "not loaded", "planning": "not open"}
    checks = {"store": await _answers(lambda: context.store.revision(), "the store's database"),
              "tbox": "ok" if context.planning.tbox_path.is_file() and getattr(state, "kb", None) is not None
              else "not loaded"}
    pool = context.pool
    reachable = getattr(pool, "reachable", None)
    if pool is None or reachable is None:
        checks["planning"] = "ok"  # planned in the service's process
    else:
        checks["planning"] = await _answers(lambda: reachable() or _raise("closed"), "planning")
    return checks


def _raise(why: str) -> Any:
    raise RuntimeError(why)


async def _answers(probe: Any, what: str) -> str:
    """`ok` when `probe()` returns within READY_WAIT_S (on a thread: a stuck database does not stop the loop)."""
    try:
        with anyio.fail_after(READY_WAIT_S):
            await anyio.to_thread.run_sync(probe, abandon_on_cancel=True)
    except TimeoutError:
        return f"{what}: no answer within {READY_WAIT_S:g} s"
    except Exception as exc:
        return f"{what}: {str(exc).splitlines()[0] if str(exc) else type(exc).__name__}"
    return "ok"
