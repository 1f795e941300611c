"""`planhrc serve` stops on SIGTERM within seconds while a large export is in flight (the export is written as it is
sent, so a client that stops reading, or a shutdown, stops it; before, the service built it whole in memory on a
request thread that the interpreter then waited for at exit, for minutes); request threads that outlive the server
are left behind after a short wait; `GET /objects` on a store of many objects."""
from __future__ import annotations

import os
import random
import signal
import subprocess
import sys
import time

import httpx
import pytest
from fastapi.testclient import TestClient

from planhrc.kb_service.app import create_app
from planhrc.kb_service.store import open_store
from planhrc.paths import default_tbox_path
from planhrc.settings import make_settings
from tests.servers import free_port, serve_command, serve_env, wait_until_serving

pytestmark = pytest.mark.integration

OBJECTS = 30
LINKS = 20


@pytest.fixture(scope="module")
def big_store(tmp_path_factory):
    db = tmp_path_factory.mktemp("shutdown") / "kb.sqlite3"
    rng = random.Random(7)
    settings = make_settings(db_path=str(db), token=None, validate_plans=False)
    with TestClient(create_app(settings)) as client:
        for _ in range(OBJECTS):
            oid = client.post("/objects", json={"name": "rod", "links": LINKS, "orientations": 12,
                                                "formulation": "relative"}).json()["id"]
            client.put(f"/objects/{oid}/goal", json={"link_orientations_deg": [rng.randrange(12) * 30
                                                                               for _ in range(LINKS)]})
            for _ in range(2):
                client.post(f"/objects/{oid}/perceptions", json={"link_orientations_deg": [
                    rng.randrange(12) * 30 for _ in range(LINKS)]})
    return db


def _rss_kb(pid: int) -> int:
    with open(f"/proc/{pid}/status") as status:
        return next(int(line.split()[1]) for line in status if line.startswith("VmRSS:"))


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads the server's memory from /proc")
@pytest.mark.parametrize("accept", ["application/rdf+xml", "text/turtle"])
def test_sigterm_during_an_export_ends_the_service_within_seconds(big_store, accept):
    port = free_port()
    base = f"http://127.0.0.1:{port}"
    log = big_store.parent / f"serve-{port}.log"
    with open(log, "wb") as out:
        proc = subprocess.Popen(serve_command(port, big_store), env=serve_env(), stdout=out, stderr=subprocess.STDOUT,
                                start_new_session=True)
    try:
        wait_until_serving(proc, base, log_path=log)
        before = _rss_kb(proc.pid)
        with httpx.Client(base_url=base, timeout=30) as client:
            with client.stream("GET", "/ontology", params={"history": "all"}, headers={"Accept": accept}) as response:
                assert response.status_code == 200
                first = next(response.iter_bytes())
                assert first.startswith(b"<?xml" if accept.endswith("xml") else b"@prefix")
                time.sleep(1.0)  # the client reads no more: the export waits for it, and holds a piece at a time
                during = _rss_kb(proc.pid)
                began = time.monotonic()
                proc.send_signal(signal.SIGTERM)
                code = proc.wait(timeout=30)
                took = time.monotonic() - began
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    assert code == 128 + signal.SIGTERM
    assert took < 10, f"the service took {took:.1f} s to stop"
    assert during - before < 200_000, f"the server grew by {(during - before) // 1000} MB during the export"


def test_request_threads_that_outlive_the_server_are_left_behind():
    code = ("import threading, time\n"
            "from planhrc.kb_service.cli import _leave_request_threads\n"
            "threading.Thread(target=time.sleep, args=(60,), name='a request').start()\n"
            "_leave_request_threads(143, 'terminated')\n")
    began = time.monotonic()
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=30, env=serve_env())
    assert proc.returncode == 143 and time.monotonic() - began < 15
    assert proc.stderr.strip() == "planhrc serve: terminated; 1 request(s) still running were abandoned"


def test_objects_are_listed_at_a_cost_per_object(big_store):
    settings = make_settings(db_path=str(big_store), token=None, validate_plans=False)
    with TestClient(create_app(settings)) as client:
        listed = client.get("/objects")
        assert listed.status_code == 200 and len(listed.json()) == OBJECTS
        one = client.get(f"/objects/{listed.json()[-1]['id']}").json()
        assert listed.json()[-1] == one
    with open_store(str(big_store), default_tbox_path()) as store:
        objects = store.list_objects()
        assert len(objects) == OBJECTS
        # what cost most of a first listing: each object's plan-check lookups, built only when a check asks
        info = store._records.info(objects[0].ident)
        assert not {"types", "static", "static_fragment", "orientation_atom_name"} & set(vars(info))
        assert info.static_fragment and "static_fragment" in vars(info)
