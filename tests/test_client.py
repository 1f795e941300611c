"""The worker's HTTP client: retries on dropped connections and 5xx, one idempotency key per perception."""
import json
import threading
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

import pytest

from planhrc.client import KBClient, ProtocolError, RetryPolicy

pytestmark = pytest.mark.sim


class FlakyService:
    """A real HTTP server on 127.0.0.1 that fails the first requests of every perception as scripted."""

    def __init__(self, script):
        self.script = list(script)  # per request: "drop", a status code, or "ok"
        self.requests = []
        service = self

        class Handler(BaseHTTPRequestHandler):
            def log_message(self, *args):
                pass

            def _answer(self):
                length = int(self.headers.get("Content-Length") or 0)
                body = json.loads(self.rfile.read(length)) if length else None
                service.requests.append((self.command, self.path, dict(self.headers), body))
                step = service.script.pop(0) if service.script else "ok"
                if step == "drop":
                    self.close_connection = True
                    self.connection.close()
                    return
                status = 200 if step == "ok" else int(step)
                payload = {"decision": "continue", "plan_id": "p1", "next_action": None,
                           "matched_expected_step": 1, "reason": "scripted"} if status == 200 else {"detail": "scripted"}
                data = json.dumps(payload).encode()
                self.send_response(status)
                self.send_header("Content-Type", "application/json")
                self.send_header("Content-Length", str(len(data)))
                self.end_headers()
                self.wfile.write(data)

            do_GET = do_POST = do_PUT = _answer

        self.server = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.url = f"http://127.0.0.1:{self.server.server_address[1]}"
        self.thread = threading.Thread(target=self.server.serve_forever, daemon=True)

    def __enter__(self):
        self.thread.start()
        return self

    def __exit__(self, *exc):
        self.server.shutdown()
        self.server.server_close()


def _client(url, **kw):
    return KBClient(url, retry=RetryPolicy(attempts=4, initial_delay_s=0.01), timeout_s=5, **kw)


def test_a_perception_is_retried_with_the_same_idempotency_key():
    with FlakyService(["drop", 503, "ok", "ok"]) as service, _client(service.url, token="T") as kb:
        decision = kb.post_perception("obj1", [0.0, 90.2, 180.0])
        assert decision.decision == "continue" and decision.matched_expected_step == 1
        kb.post_perception("obj1", [0.0, 90.2, 180.0])
    keys = [headers.get("Idempotency-Key") for _, _, headers, _ in service.requests]
    assert len(keys) == 4
    assert keys[0] == keys[1] == keys[2] and keys[0]
    assert keys[3] != keys[0]
    assert all(h.get("Authorization") == "Bearer T" for _, _, h, _ in service.requests)
    assert service.requests[0][1] == "/objects/obj1/perceptions"
    assert service.requests[0][3] == {"link_orientations_deg": [0.0, 90.2, 180.0]}


def test_a_4xx_is_not_retried():
    with FlakyService([422]) as service, _client(service.url) as kb:
        with pytest.raises(ProtocolError) as err:
            kb.post_perception("obj1", [0.0])
    assert err.value.status == 422
    assert len(service.requests) == 1


def test_giving_up_after_every_attempt():
    with FlakyService([500, 500, 500, 500]) as service, _client(service.url) as kb:
        with pytest.raises(ProtocolError, match="gave up after 4 attempts"):
            kb.post_feedback("obj1", "p1_a1", "partial")
    assert len({h.get("Idempotency-Key") for _, _, h, _ in service.requests}) == 1


def test_an_unreachable_service_raises_protocol_error():
    with FlakyService([]) as service:
        url = service.url
    with _client(url) as kb:
        with pytest.raises(ProtocolError, match="gave up"):
            kb.next_action("obj1")
