"""Untrusted input costs nothing before it is trusted, against a real `planhrc serve` process.

The token is checked from the headers before the body is read; a `Content-Length` over the limit gets 413
without reading; a chunked body is cut at the limit; reads can be put behind the token (or a read-only token).
The sockets here announce a 150 MB body and send only its first bytes: an answer that comes back at once proves
the server did not wait for, or read, the rest.
"""
from __future__ import annotations

import json
import socket
import time
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

import httpx
import pytest

from tests.servers import free_port, serving

from planhrc.kb_service.guard import GuardPolicy, RequestGuard, bearer

pytestmark = pytest.mark.integration

TOKEN, READ_TOKEN = "s3cret-writer", "s3cret-reader"
LIMIT = 64 * 1024


@contextmanager
def guarded_server(tmp_path: Path, protect_reads: bool) -> Iterator[int]:
    env = {"PLANHRC_TOKEN": TOKEN, "PLANHRC_READ_TOKEN": READ_TOKEN, "PLANHRC_MAX_BODY_BYTES": str(LIMIT),
           "PLANHRC_PROTECT_READS": "true" if protect_reads else "false"}
    port = free_port()
    with serving(tmp_path / "kb.sqlite3", port, env=env):
        yield port


def _raw_request(port: int, head: str, first_bytes: bytes = b"") -> tuple[int, dict, float]:
    """Send a request head (and the first bytes of a body), read the answer: status, JSON body, seconds."""
    with socket.create_connection(("127.0.0.1", port), timeout=10) as sock:
        start = time.perf_counter()
        sock.sendall(head.encode("latin-1") + first_bytes)
        data = b""
        while b"\r\n\r\n" not in data:
            chunk = sock.recv(65536)
            if not chunk:
                break
            data += chunk
        header_block, _, body = data.partition(b"\r\n\r\n")
        length = next((int(line.split(b":")[1]) for line in header_block.split(b"\r\n")
                       if line.lower().startswith(b"content-length:")), 0)
        while len(body) < length:
            chunk = sock.recv(65536)
            if not chunk:
                break
            body += chunk
        seconds = time.perf_counter() - start
    status = int(header_block.split(b" ")[1])
    return status, json.loads(body) if body else {}, seconds


def _count_objects(port: int) -> int:
    return len(httpx.get(f"http://127.0.0.1:{port}/objects", headers={"Authorization": f"Bearer {TOKEN}"}).json())


def test_huge_bodies_are_refused_before_they_are_read(tmp_path: Path):
    with guarded_server(tmp_path, protect_reads=False) as port:
        huge = 150 * 1024 * 1024
        # no token: 401 from the headers alone, although 150 MB are announced and 1 KB is sent
        status, body, seconds = _raw_request(
            port, f"POST /objects HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\n"
                  f"Content-Length: {huge}\r\n\r\n", b"{" + b" " * 1023)
        assert status == 401 and "Bearer" in body["detail"]
        assert seconds < 1.0
        # with the token: 413 from the announced length, body never read
        status, body, seconds = _raw_request(
            port, f"POST /objects HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer {TOKEN}\r\n"
                  f"Content-Type: application/json\r\nContent-Length: {huge}\r\n\r\n", b"{" + b" " * 1023)
        assert status == 413 and str(LIMIT) in body["detail"]
        assert seconds < 1.0
        # chunked, no length: cut as soon as the limit is passed (sent: limit + 1 KB of a far larger body)
        chunk = b" " * 4096
        chunks = b"".join(b"%x\r\n%s\r\n" % (len(chunk), chunk) for _ in range(LIMIT // 4096 + 1))
        status, body, seconds = _raw_request(
            port, f"POST /objects HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer {TOKEN}\r\n"
                  f"Content-Type: application/json\r\nTransfer-Encoding: chunked\r\n\r\n", chunks)
        assert status == 413
        assert seconds < 1.0
        assert _count_objects(port) == 0  # nothing was created by any of them
        # a body within the limit still works
        ok = httpx.post(f"http://127.0.0.1:{port}/objects", headers={"Authorization": f"Bearer {TOKEN}"},
                        json={"name": "bar", "links": 3, "orientations": 4, "formulation": "relative"})
        assert ok.status_code == 201, ok.text
        assert _count_objects(port) == 1


def test_reads_behind_the_token_when_asked(tmp_path: Path):
    with guarded_server(tmp_path, protect_reads=True) as port:
        base = f"http://127.0.0.1:{port}"
        assert httpx.get(f"{base}/health").status_code == 200  # the probes stay open
        assert httpx.get(f"{base}/health/live").status_code == 200
        assert httpx.get(f"{base}/metrics").status_code == 401  # /metrics is a read
        assert httpx.get(f"{base}/openapi.json").status_code == 200
        refused = httpx.get(f"{base}/objects")
        assert refused.status_code == 401 and refused.headers["www-authenticate"] == "Bearer"
        assert httpx.get(f"{base}/ontology").status_code == 401
        reader = {"Authorization": f"Bearer {READ_TOKEN}"}
        assert httpx.get(f"{base}/objects", headers=reader).status_code == 200
        assert httpx.get(f"{base}/metrics", headers=reader).text.count("planhrc_http_requests_total") > 0
        # the read-only token never writes: its client is a reader
        write = httpx.post(f"{base}/objects", headers=reader,
                           json={"name": "bar", "links": 3, "orientations": 4, "formulation": "relative"})
        assert write.status_code == 403 and "operator" in write.json()["detail"]
        assert _count_objects(port) == 0


def test_policy_helpers():
    assert bearer("Bearer abc") == "abc" and bearer("bearer  abc ") == "abc"
    assert bearer("Basic abc") is None and bearer("Bearer ") is None and bearer(None) is None
    guard = RequestGuard(app=None, policy=GuardPolicy(False, LIMIT), registry=lambda scope: None)  # type: ignore[arg-type]
    assert guard._refuse_length({"content-length": "12x"})[0] == 400
    assert guard._refuse_length({"content-length": str(LIMIT + 1)})[0] == 413
    assert guard._refuse_length({}) is None
