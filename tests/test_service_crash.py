"""One perception, one transaction: the service killed (SIGKILL) inside a perception's store write keeps all of
every earlier perception and nothing of the killed one, and `planhrc serve` goes on after a restart on the same
file. The kill comes from the test's own launcher (`crash_launcher`: the service's app around a store that dies
before committing its N-th perception), not from the service."""
from __future__ import annotations

import subprocess
import sys
import time
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

import httpx
import pytest

from planhrc.service_process import RunningService, die_with_parent, stop_process_group
from tests.servers import (TOKEN, free_port, serve_env, served, settled_health, store_location, token_client,
                           wait_until_serving)


@contextmanager
def crashing_service(db: str, folder: Path, crash_at: int) -> Iterator[RunningService]:
    """The service on `db` (`tests.crash_launcher`), dying inside the write of its `crash_at`-th perception."""
    port = free_port()
    log_path = folder / f"crash-{port}.log"
    with open(log_path, "wb") as log_file:
        proc = subprocess.Popen([sys.executable, "-m", "tests.crash_launcher", "--port", str(port), "--db", str(db),
                                 "--crash-at", str(crash_at)], cwd=folder, env=serve_env({"PLANHRC_TOKEN": TOKEN}),
                                stdout=log_file, stderr=subprocess.STDOUT, start_new_session=True,
                                preexec_fn=die_with_parent)
    url = f"http://127.0.0.1:{port}"
    try:
        wait_until_serving(proc, url, log_path=log_path)
        yield RunningService(url, proc.pid, log_path)
    finally:
        stop_process_group(proc)


def _perceive(client: httpx.Client, oid: str, links: list[float], key: str) -> httpx.Response:
    return client.post(f"/objects/{oid}/perceptions", json={"link_orientations_deg": links},
                       headers={"Idempotency-Key": key})


def _dead(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().split(")")[-1].split()[0] in ("Z", "X")
    except FileNotFoundError:
        return True


@pytest.mark.parametrize("backend", ["sqlite", "postgresql"])
def test_serve_killed_inside_a_perception_write_keeps_all_or_nothing(tmp_path, backend, request):
    db = store_location(backend, tmp_path, request)
    with crashing_service(db, tmp_path, crash_at=3) as server, token_client(server) as client:
        oid = client.post("/objects", json={"name": "rod", "links": 3, "orientations": 4,
                                            "formulation": "relative"}).json()["id"]
        assert client.put(f"/objects/{oid}/goal", json={"link_orientations_deg": [0, 90, 90]}).status_code == 200
        kept = [_perceive(client, oid, links, f"p{i}") for i, links in enumerate(([0, 0, 0], [0, 90, 0]))]
        assert [r.status_code for r in kept] == [200, 200]
        health = settled_health(client)
        events = client.get(f"/objects/{oid}/events").json()
        with pytest.raises(httpx.TransportError):  # the third perception kills the service mid-write
            _perceive(client, oid, [0, 0, 90], "p2")
        deadline = time.monotonic() + 10
        while not _dead(server.pid) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert _dead(server.pid)

    with served(db, env={"PLANHRC_TOKEN": TOKEN}, folder=tmp_path) as server, token_client(server) as client:
        after = client.get("/health").json()  # counted by a scan of the tables at start-up
        assert (after["objects"], after["triples"]) == (health["objects"], health["triples"])
        assert client.get(f"/objects/{oid}/events").json() == events
        for i, r in enumerate(kept):  # all of each earlier perception: its remembered answer comes back
            again = _perceive(client, oid, ([0, 0, 0], [0, 90, 0])[i], f"p{i}")
            assert again.status_code == 200 and again.json() == r.json()
        retried = _perceive(client, oid, [0, 0, 90], "p2")  # nothing of the killed one: decided anew
        assert retried.status_code == 200
        assert retried.json()["perceived_state_id"] not in {r.json()["perceived_state_id"] for r in kept}
        assert len(client.get(f"/objects/{oid}/events").json()) == len(events) + 1
