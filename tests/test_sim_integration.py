"""The worker against the real KB service (uvicorn on 127.0.0.1, in-memory store), both formulations."""
import threading
import time

import pytest

pytestmark = [pytest.mark.sim, pytest.mark.integration]


@pytest.fixture(scope="module")
def service_url():
    uvicorn = pytest.importorskip("uvicorn")
    from planhrc.kb_service.app import create_app
    from planhrc.settings import make_settings

    app = create_app(make_settings(db_path=None, token="tok"))
    server = uvicorn.Server(uvicorn.Config(app, host="127.0.0.1", port=0, log_level="warning"))
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    deadline = time.monotonic() + 60
    while not (server.started and server.servers):
        assert time.monotonic() < deadline, "the KB service did not start"
        time.sleep(0.05)
    port = server.servers[0].sockets[0].getsockname()[1]
    yield f"http://127.0.0.1:{port}"
    server.should_exit = True
    thread.join(timeout=10)


@pytest.mark.parametrize("formulation", ["relative", "absolute"])
def test_fig14_run_reaches_the_goal_through_the_service(service_url, tmp_path, formulation):
    from planhrc.client import KBClient
    from planhrc.robot_sim.demo import DEMO_SCENARIOS
    from planhrc.robot_sim.scene import SceneSpec
    from planhrc.robot_sim.worker import run_worker

    # where the demo places it: the plan's first action swings l2-l5 towards the far edge, and there they fit
    spec = SceneSpec(base_point_xy=DEMO_SCENARIOS["fig14"].base_point_xy)
    with KBClient(service_url, token="tok") as kb:
        obj = kb.create_object("rod", 5, 8, formulation)
        summary = run_worker(service_url, obj["id"], spec, "fig14", tmp_path, max_steps=10, token="tok",
                             perception="fallback", goal_link_orientations_deg=[90, 45, 90, 135, 90],
                             record_frames=False, kb=kb)
    assert summary.reached_goal, summary.decisions
    assert "partial" in summary.outcomes
    assert summary.decisions[0] == "replan" and summary.decisions[-1] == "goal_reached"
    # the measured pose of the physical object, within a few degrees of the goal
    assert all(abs((v - g + 180) % 360 - 180) < 6 for v, g in zip(summary.configurations[-1], [90, 45, 90, 135, 90]))


def test_worker_survives_a_restart_of_the_service_and_no_perception_counts_twice(tmp_path):
    """`planhrc serve` as a real process is stopped after the first decision and started again on the same port
    and store; the worker retries with backoff, reaches the goal, and every perception is stored once."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    from planhrc.robot_sim.demo import DEMO_SCENARIOS
    from planhrc.service_process import free_port
    from planhrc.robot_sim.scene import SceneSpec
    from planhrc.client import KBClient, ProtocolError, RetryPolicy
    from planhrc.robot_sim.worker import run_worker

    repo = Path(__file__).resolve().parent.parent
    port, db = free_port(), tmp_path / "kb.sqlite3"
    url = f"http://127.0.0.1:{port}"
    env = {k: v for k, v in os.environ.items() if not k.startswith("PLANHRC_")}
    env.update(PLANHRC_TOKEN="tok", PYTHONPATH=str(repo))
    cmd = [sys.executable, "-m", "planhrc.cli", "serve", "--port", str(port), "--db", str(db)]

    def start() -> subprocess.Popen:
        proc = subprocess.Popen(cmd, env=env, cwd=tmp_path, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        with KBClient(url, retry=RetryPolicy(attempts=1)) as probe:
            deadline = time.monotonic() + 60
            while True:
                try:
                    probe.health()
                    return proc
                except ProtocolError:
                    assert proc.poll() is None and time.monotonic() < deadline, "the KB service did not start"
                    time.sleep(0.1)

    server = start()
    try:
        kb = KBClient(url, token="tok", retry=RetryPolicy(attempts=20, initial_delay_s=0.1, max_delay_s=1.0))
        obj = kb.create_object("rod", 5, 8, "absolute")
        result = {}

        def work():
            # placed where this goal's plan stays on the table (see the fig14 test above)
            spec = SceneSpec(base_point_xy=DEMO_SCENARIOS["fig14"].base_point_xy)
            result["summary"] = run_worker(url, obj["id"], spec, "none", tmp_path / "w", max_steps=15, token="tok",
                                           perception="fallback",
                                           goal_link_orientations_deg=[90, 45, 90, 135, 90], record_frames=False,
                                           kb=kb)

        worker = threading.Thread(target=work)
        worker.start()
        with KBClient(url, retry=RetryPolicy(attempts=1)) as reader:
            deadline = time.monotonic() + 60
            while not any(e["kind"] == "replan" for e in reader.read_events(obj["id"])):
                assert time.monotonic() < deadline
                time.sleep(0.02)
        assert worker.is_alive(), "the episode ended before the restart: nothing was tested"
        server.terminate()  # the service goes away mid-episode
        server.wait(timeout=30)
        time.sleep(0.5)
        server = start()  # same port, same store
        worker.join(timeout=180)
        assert not worker.is_alive()
        summary = result["summary"]
        assert summary.reached_goal, summary.decisions
        with KBClient(url, retry=RetryPolicy(attempts=1)) as reader:
            events = reader.read_events(obj["id"])
        decisions = [e for e in events if e["kind"] in ("goal_reached", "continue", "resume", "replan", "no_plan")]
        assert len(decisions) == len(summary.steps)  # one stored perception per perception the worker made
        kb.close()
    finally:
        server.terminate()
        server.wait(timeout=30)
