"""Crash safety, measured: `planhrc serve` is killed with SIGKILL at random points of whole episodes (while a
perception, a re-plan, a dispatch, a feedback or a goal is in flight), restarted on the same file, and then

- every write that got a 2xx is there (and its idempotent retry returns the same answer);
- nothing half-written is visible: every plan named by the execution or an event has all its expected states,
  every state, problem and plan an event names exists;
- the episode continues: the interrupted request is sent again, and the worker finally reaches the goal.

`PLANHRC_CRASH_TRIALS` sets the number of kills (20 by default); `PLANHRC_CRASH_SEED` the random seed.
"""
from __future__ import annotations

import os
import random
import signal
import subprocess
import sys
import threading
import time
import uuid
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import httpx
import pytest

REPO = Path(__file__).resolve().parent.parent
if str(REPO / "tests") not in sys.path:
    sys.path.insert(0, str(REPO / "tests"))

from test_service_api import move, noisy  # noqa: E402
from tests.servers import free_port, serve_command, wait_until_serving  # noqa: E402

pytestmark = pytest.mark.integration

TRIALS = int(os.environ.get("PLANHRC_CRASH_TRIALS", "20"))
SEED = int(os.environ.get("PLANHRC_CRASH_SEED", "12"))
LINKS, K = 3, 4
GOALS = ([0, 90, 180], [0, 180, 180], [90, 90, 0], [0, 270, 90])


@dataclass
class Server:
    """One `planhrc serve` process on the database file; `kill()` is SIGKILL, nothing gets to clean up."""

    db: Path
    proc: subprocess.Popen | None = None
    base: str = ""

    def start(self) -> None:
        port = free_port()
        env = {k: v for k, v in os.environ.items() if not k.startswith("PLANHRC_")}
        env["PYTHONPATH"] = str(REPO) + os.pathsep + env.get("PYTHONPATH", "")
        env["PLANHRC_MERGE_MACRO_STEPS"] = "false"
        self.proc = subprocess.Popen(serve_command(port, self.db), cwd=self.db.parent, env=env,
                                     stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        self.base = f"http://127.0.0.1:{port}"
        wait_until_serving(self.proc, self.base)

    def kill(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.send_signal(signal.SIGKILL)
        if self.proc is not None:
            self.proc.wait()


@dataclass(frozen=True)
class Request:
    kind: str  # perception, next, feedback, goal
    method: str
    path: str
    body: Any = None
    key: str | None = None


@dataclass
class Ledger:
    """What the service acknowledged (2xx), as the client saw it."""

    acked: list[tuple[Request, Any]] = field(default_factory=list)
    latency: dict[str, float] = field(default_factory=dict)


def send(base: str, request: Request) -> httpx.Response:
    headers = {"Idempotency-Key": request.key} if request.key else {}
    return httpx.request(request.method, base + request.path, json=request.body, headers=headers, timeout=60)


def check_consistent(c: httpx.Client, oid: str) -> None:
    """Nothing half-written: whatever the object, its execution and its log name exists, plans in full."""
    obj = c.get(f"/objects/{oid}")
    assert obj.status_code == 200, obj.text
    plans = {obj.json()["execution"]["plan_id"]} - {None}
    states = {obj.json()["goal_state_id"]} - {None}
    problems: set[str] = set()
    events = c.get(f"/objects/{oid}/events").json()
    seqs = [e["seq"] for e in events]
    assert seqs == sorted(set(seqs)), "event seqs not strictly increasing"
    for event in events:
        for key, value in event["data"].items():
            if isinstance(value, str) and key.endswith("state_id"):
                states.add(value)
            elif isinstance(value, str) and key == "plan_id":
                plans.add(value)
            elif isinstance(value, str) and key == "problem_id":
                problems.add(value)
    for plan_id in plans:
        plan = c.get(f"/plans/{plan_id}")
        assert plan.status_code == 200, (plan_id, plan.text)
        plan = plan.json()
        assert len(plan["expected_state_ids"]) == len(plan["steps"]) + 1 == len(plan["expected_states"]), plan_id
        states.update(plan["expected_state_ids"])
        problems.add(plan["problem_id"])
    for problem_id in problems:
        problem = c.get(f"/problems/{problem_id}")
        assert problem.status_code == 200, (problem_id, problem.text)
        states.update((problem.json()["init_state_id"], problem.json()["goal_state_id"]))
    for state_id in states:
        assert c.get(f"/states/{state_id}").status_code == 200, state_id


def check_acknowledged(c: httpx.Client, oid: str, ledger: Ledger) -> None:
    """Every 2xx write is there; an idempotent retry of it returns the first answer."""
    events = c.get(f"/objects/{oid}/events").json()
    perceived = {e["data"].get("perceived_state_id") for e in events}
    fed_back = {e["data"].get("action_id") for e in events if e["kind"] == "feedback"}
    dispatched = {e["data"].get("action_id") for e in events if e["kind"] == "dispatched"}
    for request, answer in ledger.acked:
        if request.kind == "perception":
            assert answer["perceived_state_id"] in perceived, answer
            if answer["plan_id"]:
                assert c.get(f"/plans/{answer['plan_id']}").status_code == 200
        elif request.kind == "feedback":
            assert answer["action_id"] in fed_back, answer
        elif request.kind == "next" and answer is not None:
            assert answer["id"] in dispatched, answer
        elif request.kind == "goal":
            assert c.get(f"/states/{answer['goal_state_id']}").status_code == 200
    for request, answer in ledger.acked[-6:]:  # retries of the latest acknowledged writes
        if request.key:
            again = send(str(c.base_url), request)
            assert again.status_code == 200 and again.json() == answer, (request, again.text)


class Episode:
    """A worker and a world: the world's link orientations change only when the worker executes an action
    (or when the test knocks the object, which forces a re-plan)."""

    def __init__(self, oid: str, rng: random.Random) -> None:
        self.oid, self.rng = oid, rng
        self.links: list[float] = [0.0] * LINKS
        self.pending: list[Request] = []  # the worker's next requests, in order
        self.calm = False  # no knocks, no new goals, no failures: the worker just finishes

    def perception(self) -> Request:
        return Request("perception", "POST", f"/objects/{self.oid}/perceptions",
                       {"link_orientations_deg": noisy(self.links, 5.0)}, uuid.uuid4().hex)

    def next_request(self) -> Request:
        if self.pending:
            return self.pending.pop(0)
        roll = 1.0 if self.calm else self.rng.random()
        if roll < 0.15:  # someone knocks the object: the next perception re-plans
            self.links = [float(self.rng.randrange(K) * 360 // K) for _ in range(LINKS)]
        elif roll < 0.22:
            return Request("goal", "PUT", f"/objects/{self.oid}/goal",
                           {"link_orientations_deg": list(self.rng.choice(GOALS))})
        return self.perception()

    def answered(self, request: Request, answer: Any) -> None:
        """The worker reacts to an answer: take the next action, execute it, report it."""
        if request.kind == "perception" and answer["next_action"] is not None:
            self.pending = [Request("next", "POST", f"/objects/{self.oid}/actions/next")]
        elif request.kind == "next" and answer is not None:
            self.links = move(self.links, answer)
            outcome = "succeeded" if self.calm or self.rng.random() < 0.85 else "failed"
            if outcome == "failed":
                self.links = move(self.links, {**answer, "delta_deg": -answer["delta_deg"]})
            self.pending = [Request("feedback", "POST", f"/objects/{self.oid}/actions/{answer['id']}/feedback",
                                    {"outcome": outcome}, uuid.uuid4().hex)]
        elif request.kind == "feedback":
            self.pending = [self.perception()]


def run_step(server: Server, episode: Episode, ledger: Ledger) -> None:
    request = episode.next_request()
    started = time.perf_counter()
    r = send(server.base, request)
    assert r.status_code in (200, 201), (request, r.text)
    ledger.latency[request.kind] = time.perf_counter() - started
    ledger.acked.append((request, r.json()))
    episode.answered(request, r.json())


def kill_during(server: Server, episode: Episode, ledger: Ledger, rng: random.Random) -> tuple[Request, Any]:
    """Send the episode's next request and SIGKILL the server at a random moment of its handling."""
    request = episode.next_request()
    result: dict[str, Any] = {}

    def go() -> None:
        try:
            r = send(server.base, request)
            result["answer"] = r.json() if r.status_code in (200, 201) else None
        except httpx.TransportError:
            pass

    thread = threading.Thread(target=go)
    thread.start()
    time.sleep(rng.uniform(0, 1.2 * ledger.latency.get(request.kind, 0.05)))
    server.kill()
    thread.join()
    return request, result.get("answer")


def test_sigkill_at_random_points_loses_nothing_and_the_episode_continues(tmp_path):
    rng = random.Random(SEED)
    server = Server(tmp_path / "kb.sqlite3")
    ledger = Ledger()
    interrupted: dict[str, int] = {}
    try:
        server.start()
        with httpx.Client(base_url=server.base, timeout=60) as c:
            r = c.post("/objects", json={"name": "rod", "links": LINKS, "orientations": K, "formulation": "relative"})
            assert r.status_code == 201, r.text
            oid = r.json()["id"]
            r = c.put(f"/objects/{oid}/goal", json={"link_orientations_deg": list(GOALS[0])})
            assert r.status_code == 200, r.text
        episode = Episode(oid, rng)
        for _ in range(TRIALS):
            for _ in range(rng.randrange(1, 4)):
                run_step(server, episode, ledger)
            request, answer = kill_during(server, episode, ledger, rng)
            if answer is not None:  # the answer arrived before the kill: acknowledged
                ledger.acked.append((request, answer))
                episode.answered(request, answer)
            else:
                interrupted[request.kind] = interrupted.get(request.kind, 0) + 1
            server.start()
            with httpx.Client(base_url=server.base, timeout=60) as c:
                check_consistent(c, oid)
                check_acknowledged(c, oid, ledger)
            if answer is None:  # the worker retries what got no answer (same idempotency key)
                episode.pending.insert(0, request)
                run_step(server, episode, ledger)

        # the episode continues to the goal on the last restarted server
        episode.calm = True
        for _ in range(60):
            run_step(server, episode, ledger)
            request, answer = ledger.acked[-1]
            if request.kind == "perception" and answer["decision"] == "goal_reached":
                break
        else:
            raise AssertionError("goal not reached after the crashes")
        with httpx.Client(base_url=server.base, timeout=60) as c:
            check_consistent(c, oid)
            check_acknowledged(c, oid, ledger)
    finally:
        server.kill()
    kinds = [request.kind for request, _ in ledger.acked]
    print(f"\n{TRIALS} SIGKILLs; interrupted before an answer: {interrupted}; acknowledged writes checked: "
          f"{len(kinds)} ({ {k: kinds.count(k) for k in set(kinds)} })")
    assert sum(interrupted.values()) >= 1, "no kill landed inside a request"
