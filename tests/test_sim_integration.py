"""The worker against the real KB service (uvicorn on 127.0.0.1, in-memory store), both formulations."""
import threading
import time

import pytest

pytestmark = [pytest.mark.sim, pytest.mark.integration]


@pytest.fixture(scope="module")
def service_url():
    uvicorn = pytest.importorskip("uvicorn")
    from kb_service.app import create_app
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
    from robot_sim.protocol import KBClient
    from robot_sim.worker import run_worker

    with KBClient(service_url, token="tok") as kb:
        obj = kb.create_object("rod", 5, 8, formulation)
        summary = run_worker(service_url, obj["id"], None, "fig14", tmp_path, max_steps=10, token="tok",
                             perception="fallback", goal_link_orientations_deg=[90, 45, 90, 135, 90],
                             record_frames=False, kb=kb)
    assert summary.reached_goal, summary.decisions
    assert "partial" in summary.outcomes
    assert summary.decisions[0] == "replan" and summary.decisions[-1] == "goal_reached"
    assert [round(v) % 360 for v in summary.configurations[-1]] == [90, 45, 90, 135, 90]
