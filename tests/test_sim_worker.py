"""The worker loop against a small scripted KB service (a real HTTP server on 127.0.0.1)."""
import json
import threading
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

import pytest

from planhrc.robot_sim.human import HumanEvent, Scenario, get_scenario
from planhrc.robot_sim.perception import Perception
from planhrc.robot_sim.scene import SceneSpec
from planhrc.robot_sim.worker import _perceive, run_worker

pytestmark = pytest.mark.sim

STEP = 45


class GreedyKB:
    """Plans one step at a time: the first joint whose relative angle is off the goal turns by one step."""

    def __init__(self, goal):
        self.goal = [g % 360 for g in goal]
        self.pending = None
        self.counter = 0
        self.log = []
        kb = self

        class Handler(BaseHTTPRequestHandler):
            def log_message(self, *args):
                pass

            def _reply(self, status, payload):
                data = json.dumps(payload).encode()
                self.send_response(status)
                self.send_header("Content-Type", "application/json")
                self.send_header("Content-Length", str(len(data)))
                self.end_headers()
                self.wfile.write(data)

            def _body(self):
                n = int(self.headers.get("Content-Length") or 0)
                return json.loads(self.rfile.read(n)) if n else None

            def do_GET(self):
                kb.log.append(("GET", self.path, dict(self.headers), None))
                if self.path == "/objects/o1":
                    self._reply(200, {"id": "o1", "formulation": "relative", "orientations": 8, "step_deg": STEP,
                                      "links": [{"name": f"o1_l{i}", "length_m": 0.155} for i in range(1, 6)],
                                      "goal_state_id": None})
                else:
                    self._reply(404, {"detail": "unknown"})

            def do_PUT(self):
                kb.log.append(("PUT", self.path, dict(self.headers), self._body()))
                self._reply(200, {"goal_state_id": "g1", "problem_id": None})

            def do_POST(self):
                body = self._body()
                kb.log.append(("POST", self.path, dict(self.headers), body))
                if self.path.endswith("/perceptions"):
                    self._reply(200, kb.decide(body["link_orientations_deg"]))
                elif self.path == "/objects/o1/actions/next":
                    self._reply(200, kb.pending)
                else:
                    self._reply(200, {"action_id": self.path.split("/")[-2], "accepted": "current"})

        self.server = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.url = f"http://127.0.0.1:{self.server.server_address[1]}"
        threading.Thread(target=self.server.serve_forever, daemon=True).start()

    def decide(self, perceived):
        snapped = [round(v / STEP) * STEP % 360 for v in perceived]
        for k in range(1, len(snapped)):
            have = (snapped[k] - snapped[k - 1]) % 360
            want = (self.goal[k] - self.goal[k - 1]) % 360
            if have != want:
                off = (want - have + 180) % 360 - 180
                self.counter += 1
                self.pending = {"id": f"a{self.counter}", "name": "rotate", "params": [], "step": self.counter,
                                "plan_id": "p1", "joint_index": k, "turned_link_index": k + 1,
                                "held_link_index": k, "delta_deg": STEP if off > 0 else -STEP, "macro_steps": 1}
                return {"decision": "continue", "plan_id": "p1", "next_action": self.pending,
                        "matched_expected_step": None, "reason": "greedy"}
        self.pending = None
        return {"decision": "goal_reached", "plan_id": "p1", "next_action": None,
                "matched_expected_step": None, "reason": "greedy"}

    def close(self):
        self.server.shutdown()
        self.server.server_close()


@pytest.fixture
def kb():
    service = GreedyKB([90, 45, 90, 135, 90])
    yield service
    service.close()


def test_worker_reaches_the_goal_and_records_everything(kb, tmp_path):
    summary = run_worker(kb.url, "o1", SceneSpec(), "none", tmp_path, max_steps=10, token="T",
                         goal_link_orientations_deg=[90, 45, 90, 135, 90])
    assert summary.reached_goal and summary.stop_reason == "goal_reached"
    assert summary.outcomes == ("succeeded",) * 4
    assert summary.decisions[-1] == "goal_reached"
    assert [round(v) % 360 for v in summary.configurations[-1]] == [90, 45, 90, 135, 90]
    for name in ("summary.json", "run.gif", "configurations.png", "frame_000.png"):
        assert (tmp_path / name).stat().st_size > 0
    perceptions = [h for m, path, h, _ in kb.log if path.endswith("/perceptions")]
    assert len({h["Idempotency-Key"] for h in perceptions}) == len(perceptions) == 5
    assert all(h.get("Authorization") == "Bearer T" for m, _, h, _ in kb.log if m != "GET")
    feedback = [b["outcome"] for m, path, _, b in kb.log if path.endswith("/feedback")]
    assert feedback == ["succeeded"] * 4


def test_partial_rotation_is_reported_and_the_human_completes_it(kb, tmp_path):
    summary = run_worker(kb.url, "o1", SceneSpec(), "fig14", tmp_path, max_steps=10, perception="fallback",
                         record_frames=False)
    assert summary.reached_goal
    assert "partial" in summary.outcomes
    completed = [s for s in summary.steps if any("completed" in h for h in s.human_before)]
    assert completed and completed[0].step == 3
    feedback = [b["outcome"] for m, path, _, b in kb.log if path.endswith("/feedback")]
    assert feedback[1] == "partial"


def test_a_disturbance_after_the_goal_is_repaired(kb, tmp_path):
    scenario = Scenario("late", events=(HumanEvent(at_step=8, when="before", link=2, delta_deg=45),))
    summary = run_worker(kb.url, "o1", SceneSpec(), scenario, tmp_path, max_steps=12, perception="fallback",
                         record_frames=False)
    assert summary.reached_goal
    assert summary.decisions.count("goal_reached") == 2
    assert any(s.human_before for s in summary.steps)
    assert (tmp_path / "configurations.png").exists() and not (tmp_path / "run.gif").exists()


def test_scenario_names():
    assert get_scenario("none").events == ()
    assert get_scenario("fig14").faults[0].stop_fraction == 0.5
    assert get_scenario("random:3:4") == get_scenario("random:3:4")
    assert len(get_scenario("random:3:4").events) == 4


def test_a_link_still_unseen_is_filled_from_the_simulator():
    class Blind:
        calls = 0

        def perceive(self):
            Blind.calls += 1
            return Perception((10.0, None, 30.0), None)

    class Truth:
        def perceive(self):
            return Perception((11.0, 21.0, 31.0), None)

    seen, values = _perceive(Blind(), Truth())
    assert Blind.calls == 2  # one retry before falling back
    assert seen.missing_links == (2,)
    assert values == (10.0, 21.0, 30.0)
