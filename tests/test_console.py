"""The cell console at `/` in a real browser (Debian's Chromium driven by Playwright) against a real
`planhrc serve` process: it lists and draws an object, shows a perception posted over HTTP in its live log
within a second and redraws, sets a goal that reaches the knowledge base, and shows the API's own message for a
bad goal while nothing changes. Screenshots at desktop width are written to `docs/` when
PLANHRC_CONSOLE_SCREENSHOTS=1 (they are the README's pictures).

The browser is the system Chromium (`/usr/bin/chromium`, installed by `python3 run.py test` where apt is usable);
no browser is ever downloaded. Without it, or without the `playwright` package, these tests skip and say why.
"""
from __future__ import annotations

import os
import time
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

import httpx
import pytest

from tests.servers import free_port, serving

REPO = Path(__file__).resolve().parent.parent
CHROMIUM = Path("/usr/bin/chromium")
DESKTOP = {"width": 1440, "height": 1000}
TOKEN = "console-token"

pytestmark = [pytest.mark.integration, pytest.mark.browser]


def browser_missing() -> str | None:
    """Why the browser tests cannot run here, or None."""
    try:
        import playwright.sync_api  # noqa: F401
    except ImportError:
        return "the playwright package is not installed (pip install -e '.[test]')"
    if not CHROMIUM.exists():
        return f"{CHROMIUM} is missing: `python3 run.py test` installs Debian's chromium where apt-get runs as root"
    return None


@contextmanager
def serve(db: Path, port: int | None = None, token: str | None = None, *extra: str) -> Iterator[str]:
    """`planhrc serve` as a process on a loopback port; yields its base URL and stops it afterwards."""
    with serving(db, port, (["--token", token] if token else []) + list(extra)) as base:
        yield base


@contextmanager
def chromium() -> Iterator[object]:
    """Debian's Chromium through Playwright (headless), closed afterwards."""
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=str(CHROMIUM), headless=True)
        try:
            yield browser
        finally:
            browser.close()


def open_page(browser, url: str, outside: list[str], bypass_csp: bool = False):
    """A desktop-width page that refuses every request beyond loopback (recorded in `outside`).

    `bypass_csp` lets the test's own `wait_for_function` expressions run on a page whose policy forbids eval."""
    page = browser.new_page(viewport=DESKTOP, bypass_csp=bypass_csp)

    def guard(route) -> None:
        host = route.request.url.split("/")[2].split(":")[0] if "://" in route.request.url else ""
        if route.request.url.startswith(("data:", "blob:")) or host in ("127.0.0.1", "localhost"):
            route.continue_()
        else:
            outside.append(route.request.url)
            route.abort()

    page.route("**/*", guard)
    page.goto(url)
    return page


@pytest.fixture(scope="module")
def browser():
    """One headless Chromium for the module (Playwright allows one sync driver at a time)."""
    reason = browser_missing()
    if reason:
        pytest.skip(reason)
    with chromium() as b:
        yield b


@pytest.fixture(scope="module")
def cell(browser, tmp_path_factory):
    """One service (with a bearer token), one page, one object with a goal and a first perception."""
    db = tmp_path_factory.mktemp("console") / "kb.sqlite3"
    with serve(db, token=TOKEN) as base:
        client = httpx.Client(base_url=base, timeout=30, headers={"Authorization": f"Bearer {TOKEN}"})
        r = client.post("/objects", json={"name": "rod", "links": 4, "orientations": 4, "formulation": "relative"})
        assert r.status_code == 201, r.text
        oid = r.json()["id"]
        assert client.put(f"/objects/{oid}/goal", json={"link_orientations_deg": [0, 90, 90, 180]}).status_code == 200
        first = client.post(f"/objects/{oid}/perceptions", json={"link_orientations_deg": [0, 0, 0, 0]})
        assert first.status_code == 200 and first.json()["decision"] == "replan", first.text
        outside: list[str] = []
        page = open_page(browser, f"{base}/?object={oid}", outside, bypass_csp=True)
        page.fill("#token", TOKEN)
        page.dispatch_event("#token", "change")
        page.wait_for_selector("#log li.replan")
        page.wait_for_selector("#drawing .perceived-layer .link")
        page.wait_for_selector("#drawing .expected-layer .link")
        yield {"base": base, "client": client, "oid": oid, "page": page, "outside": outside, "browser": browser}
        page.close()
        client.close()


def drawn_angles(page) -> list[str]:
    return page.locator("#drawing .perceived-layer text").evaluate_all("els => els.map(e => e.textContent)")


def test_console_shows_the_object_its_plan_and_its_drawing(cell):
    page, oid = cell["page"], cell["oid"]
    assert oid in page.locator("#objects").inner_text()
    assert page.locator("#drawing .perceived-layer .link").count() == 4
    assert page.locator("#drawing .goal-layer .link").count() == 4
    assert page.locator("#drawing .expected-layer .link").count() == 4  # the state after the next action
    assert drawn_angles(page) == ["l1 0°", "l2 0°", "l3 0°", "l4 0°"]
    plan = cell["client"].get(f"/objects/{oid}/plan").json()
    steps = page.locator("#plan li")
    assert steps.count() == len(plan["steps"]) > 0
    assert "current" in steps.nth(0).get_attribute("class")
    first = plan["steps"][0]
    assert f"joint j{first['joint_index']}" in steps.nth(0).inner_text()
    assert f"turn l{first['turned_link_index']}" in steps.nth(0).inner_text()
    # The expected state after each step is viewable, step by step.
    steps.nth(0).click()
    assert page.locator("#angles").inner_text().count("expected after a_1") == 1
    assert "viewing" in steps.nth(0).get_attribute("class")
    page.click("#step-next")
    last = min(2, len(plan["steps"]))
    assert f"expected after a_{last}" in page.locator("#angles").inner_text()
    expected = plan["expected_states"][last]["joint_values_deg"]
    row = page.locator("#angles tr").nth(3).locator("td").all_inner_texts()[1:]
    angles = [float(t.rstrip("°")) for t in row]
    assert [(angles[k + 1] - angles[k]) % 360 for k in range(3)] == [expected[f"{oid}_j{k + 1}"] for k in range(3)]
    page.click("#step-live")
    assert page.locator("#plan li.viewing").count() == 0
    assert cell["outside"] == []


def test_a_bimanual_plan_names_each_step_by_what_it_does(cell):
    client = cell["client"]
    oid = client.post("/objects", json={"name": "arms", "links": 4, "orientations": 4,
                                        "formulation": "bimanual"}).json()["id"]
    assert client.put(f"/objects/{oid}/goal", json={"link_orientations_deg": [0, 90, 90, 180]}).status_code == 200
    assert client.post(f"/objects/{oid}/perceptions", json={"link_orientations_deg": [0, 0, 0, 0]}).status_code == 200
    names = [s["name"] for s in client.get(f"/objects/{oid}/plan").json()["steps"]]
    page = open_page(cell["browser"], f"{cell['base']}/?object={oid}", cell["outside"], bypass_csp=True)
    try:
        page.fill("#token", TOKEN)
        page.dispatch_event("#token", "change")
        page.wait_for_selector("#plan li")
        texts = page.locator("#plan li").all_inner_texts()
    finally:
        page.close()
    assert len(texts) == len(names) and not any(" 0°" in t for t in texts), texts
    for name, text in zip(names, texts):
        words = {"grasplinks": ": grasp l", "releaselinks": ": release l", "movetocentre": ": centre the hands on joint j"}
        assert words.get(name, ": joint j") in text and ("turn l" in text) == (name not in words), text


def test_the_console_runs_under_its_own_content_security_policy(cell):
    """The page as a person's browser sees it: the policy allows this service only, and the page still works."""
    assert "default-src 'self'" in httpx.get(cell["base"] + "/").headers["content-security-policy"]
    outside: list[str] = []
    page = open_page(cell["browser"], f"{cell['base']}/?object={cell['oid']}", outside)
    try:
        page.wait_for_selector("#drawing .perceived-layer .link")
        page.wait_for_selector("#log li.replan")
        # The log comes from the event stream, the plan from its own read: either may be drawn first.
        page.wait_for_selector("#plan li")
        assert page.locator("#plan li").count() > 0
    finally:
        page.close()
    assert outside == []


def test_a_perception_over_http_appears_in_the_log_within_a_second_and_redraws(cell):
    page, client, oid = cell["page"], cell["client"], cell["oid"]
    before = page.locator("#log li").count()
    # A person turns l4 by hand: no robot action explains it.
    started = time.monotonic()
    answer = client.post(f"/objects/{oid}/perceptions", json={"link_orientations_deg": [0, 0, 0, 90]})
    assert answer.status_code == 200, answer.text
    decision = answer.json()["decision"]
    page.wait_for_function(f"document.querySelectorAll('#log li').length > {before}", timeout=1000)
    page.wait_for_function("[...document.querySelectorAll('#drawing .perceived-layer text')]"
                           ".some(t => t.textContent === 'l4 90°')", timeout=1000)
    assert time.monotonic() - started < 2.0  # the post itself plus at most a second to show it
    newest = page.locator("#log li").first
    assert decision.replace("_", " ") in newest.locator(".kind").inner_text().lower()
    assert "human" in newest.locator(".actor").inner_text()
    assert newest.locator(".client").inner_text() == "by token"  # the client whose request caused it (--token)
    assert drawn_angles(page)[-1] == "l4 90°"


def test_a_goal_set_from_the_page_reaches_the_knowledge_base(cell):
    page, client, oid = cell["page"], cell["client"], cell["oid"]
    page.select_option("#goal-kind", "link_orientations_deg")
    for k, value in enumerate([0, 90, 180, 180]):
        page.fill(f"#goal-inputs input[name=goal-{k}]", str(value))
    page.click("#goal-submit")
    page.wait_for_function("document.getElementById('notice').textContent.startsWith('goal ')")
    goal_id = client.get(f"/objects/{oid}").json()["goal_state_id"]
    assert goal_id in page.locator("#notice").inner_text()
    joints = client.get(f"/states/{goal_id}").json()["joint_values_deg"]
    assert joints == {f"{oid}_j1": 90, f"{oid}_j2": 90, f"{oid}_j3": 0}
    assert page.locator("#error").inner_text() == ""


def test_turning_a_goal_link_in_the_drawing_sets_that_goal(cell):
    page, client, oid = cell["page"], cell["client"], cell["oid"]
    page.click("#goal-reset")
    before = [page.input_value(f"#goal-inputs input[name=goal-{k}]") for k in range(4)]
    page.locator("#drawing .goal-layer .link").nth(3).click()  # l4 one step clockwise
    after = [page.input_value(f"#goal-inputs input[name=goal-{k}]") for k in range(4)]
    assert after[:3] == before[:3] and int(after[3]) == (int(before[3]) + 90) % 360
    page.click("#goal-submit")
    page.wait_for_function("document.getElementById('notice').textContent.startsWith('goal ')")
    goal_id = client.get(f"/objects/{oid}").json()["goal_state_id"]
    joints = client.get(f"/states/{goal_id}").json()["joint_values_deg"]
    assert joints[f"{oid}_j3"] == (int(after[3]) - int(after[2])) % 360


def test_a_bad_goal_typed_in_the_page_shows_the_api_message_and_changes_nothing(cell):
    page, client, oid = cell["page"], cell["client"], cell["oid"]
    obj_before = client.get(f"/objects/{oid}").json()
    events_before = client.get(f"/objects/{oid}/events").json()
    page.select_option("#goal-kind", "link_orientations_deg")
    page.fill("#goal-inputs input[name=goal-2]", "45")  # not one of the 4 allowed orientations
    page.click("#goal-submit")
    page.wait_for_function("document.getElementById('error').textContent !== ''")
    # The page shows exactly what the API answers to the same body.
    body = {"link_orientations_deg": [float(page.input_value(f"#goal-inputs input[name=goal-{k}]")) for k in range(4)]}
    direct = client.put(f"/objects/{oid}/goal", json=body)
    assert direct.status_code == 422
    assert page.locator("#error").inner_text() == direct.json()["detail"]
    assert "link_orientations_deg" in direct.json()["detail"]
    assert client.get(f"/objects/{oid}").json() == obj_before
    assert client.get(f"/objects/{oid}/events").json() == events_before


def test_without_the_token_the_page_shows_the_refusal(cell):
    page, client, oid = cell["page"], cell["client"], cell["oid"]
    events_before = client.get(f"/objects/{oid}/events").json()
    page.fill("#token", "")
    page.click("#perception-submit")
    page.wait_for_function("document.getElementById('error').textContent !== ''")
    typed = [float(page.input_value(f"#perception-inputs input[name=perceived-{k}]")) for k in range(4)]
    direct = httpx.post(f"{cell['base']}/objects/{oid}/perceptions", json={"link_orientations_deg": typed})
    assert direct.status_code == 401
    assert page.locator("#error").inner_text() == direct.json()["detail"]
    assert client.get(f"/objects/{oid}/events").json() == events_before
    page.fill("#token", TOKEN)


def test_the_log_reconnects_after_a_service_restart(browser, tmp_path):
    """The stream resumes with Last-Event-ID: events stored while the page was cut off are shown once."""
    db, port = tmp_path / "kb.sqlite3", free_port()
    body = {"name": "rod", "links": 3, "orientations": 4, "formulation": "absolute"}
    if True:
        with serve(db, port=port) as base:
            oid = httpx.post(f"{base}/objects", json=body).json()["id"]
            httpx.put(f"{base}/objects/{oid}/goal", json={"link_orientations_deg": [0, 90, 90]})
            page = open_page(browser, f"{base}/?object={oid}", [], bypass_csp=True)
            page.wait_for_selector("#log li.goal_set")
        page.wait_for_function("document.getElementById('stream').textContent === 'reconnecting…'", timeout=10000)
        with serve(db, port=port) as base:
            httpx.post(f"{base}/objects/{oid}/perceptions", json={"link_orientations_deg": [0, 0, 0]})
            page.wait_for_selector("#log li.replan", timeout=15000)
            page.wait_for_function("document.getElementById('stream').textContent === 'live'")
            seqs = page.locator("#log li").evaluate_all("items => items.map(li => Number(li.dataset.seq))")
            stored = [e["seq"] for e in httpx.get(f"{base}/objects/{oid}/events").json()]
            assert sorted(seqs) == stored  # every event once, none twice
        page.close()


def test_a_partial_goal_by_joint_angles_leaves_the_empty_joint_free(cell):
    page, client, oid = cell["page"], cell["client"], cell["oid"]
    page.select_option("#goal-kind", "joint_angles_deg")
    for k, value in enumerate(["90", "", "270"]):
        page.fill(f"#goal-inputs input[name=goal-{k}]", value)
    page.click("#goal-submit")
    page.wait_for_function("document.getElementById('notice').textContent.startsWith('goal ')")
    goal_id = client.get(f"/objects/{oid}").json()["goal_state_id"]
    assert client.get(f"/states/{goal_id}").json()["joint_values_deg"] == {f"{oid}_j1": 90, f"{oid}_j3": 270}
    page.select_option("#goal-kind", "link_orientations_deg")


def test_a_failed_robot_action_is_shown_with_its_reason(cell):
    page, client, oid = cell["page"], cell["client"], cell["oid"]
    decision = client.post(f"/objects/{oid}/perceptions", json={"link_orientations_deg": [0, 0, 0, 90]}).json()
    assert decision["decision"] == "replan", decision
    action = take_next_action(client, oid)
    r = client.post(f"/objects/{oid}/actions/{action['id']}/feedback",
                    json={"outcome": "failed", "message": "gripper lost the link"})
    assert r.status_code == 200, r.text
    failure = page.locator("#log li.feedback.failure").first
    failure.wait_for(timeout=2000)
    assert "gripper lost the link" in failure.inner_text()
    assert f"robot: a_{action['step']} failed" in failure.locator(".actor").inner_text()
    # the plan is still drawn: the failed step stays the current one, nothing is ticked
    page.wait_for_selector("#plan li.current")
    assert page.locator("#plan li.done").count() == action["step"] - 1


def test_with_protected_reads_the_token_field_opens_the_page(browser, tmp_path):
    """Reads need the (read-only) token too: the page says so, and works once the token is typed."""
    with serve(tmp_path / "kb.sqlite3", None, TOKEN, "--protect-reads", "--read-token", "look") as base:
        headers = {"Authorization": f"Bearer {TOKEN}"}
        body = {"name": "rod", "links": 3, "orientations": 4, "formulation": "relative"}
        oid = httpx.post(f"{base}/objects", json=body, headers=headers).json()["id"]
        httpx.put(f"{base}/objects/{oid}/goal", json={"link_orientations_deg": [0, 90, 90]}, headers=headers)
        schema = httpx.get(f"{base}/openapi.json").json()
        assert schema["paths"]["/objects"]["get"]["security"] == [{"bearerToken": []}]
        assert "security" not in schema["paths"]["/health"]["get"]
        page = open_page(browser, f"{base}/?object={oid}", [], bypass_csp=True)
        try:
            page.wait_for_function("document.getElementById('error').textContent.includes('reads of the knowledge base')")
            page.fill("#token", "look")
            page.dispatch_event("#token", "change")
            page.wait_for_selector("#log li.goal_set")
            page.wait_for_selector(f"#objects button[data-object-id={oid}]")
            page.wait_for_function("document.getElementById('plan-meta').textContent === 'none yet'")
            assert page.locator("#drawing .goal-layer .link").count() == 3
        finally:
            page.close()


def take_next_action(client: httpx.Client, oid: str) -> dict:
    """What a worker does (never the console): take the next action for execution."""
    r = client.post(f"/objects/{oid}/actions/next")
    assert r.status_code == 200, r.text
    return r.json()


def links_from_joints(values: dict[str, int], oid: str, n: int, first: float = 0.0) -> list[float]:
    """Link orientations of a relative state: l1 where it was, then each joint's angle added."""
    out = [first]
    for k in range(1, n):
        out.append((out[-1] + values[f"{oid}_j{k}"]) % 360)
    return out


@pytest.mark.skipif(os.environ.get("PLANHRC_CONSOLE_SCREENSHOTS") != "1",
                    reason="set PLANHRC_CONSOLE_SCREENSHOTS=1 to refresh docs/")
def test_screenshots_for_the_readme(cell):
    """An episode played over HTTP as a worker and a person would: a plan, one robot action done, a human
    move, the next action under way; the page is photographed at desktop width."""
    client = cell["client"]
    body = {"name": "cable", "links": 6, "orientations": 4, "formulation": "relative"}
    oid = client.post("/objects", json=body).json()["id"]
    assert client.put(f"/objects/{oid}/goal", json={"link_orientations_deg": [0, 90, 180, 180, 90, 90]}).status_code == 200
    assert client.post(f"/objects/{oid}/perceptions", json={"link_orientations_deg": [0.8, 1.1, 359.2, 0.4, 1.9, 0.0]}).status_code == 200
    action = take_next_action(client, oid)
    client.post(f"/objects/{oid}/actions/{action['id']}/feedback", json={"outcome": "succeeded"})
    plan = client.get(f"/objects/{oid}/plan").json()
    after = plan["expected_states"][action["last_step"]]["joint_values_deg"]
    seen = links_from_joints(after, oid, 6)
    client.post(f"/objects/{oid}/perceptions", json={"link_orientations_deg": [v + 0.7 for v in seen]})
    seen[5] = (seen[5] + 90) % 360  # a person turns the last link
    client.post(f"/objects/{oid}/perceptions", json={"link_orientations_deg": [v - 0.6 for v in seen]})
    take_next_action(client, oid)
    page = open_page(cell["browser"], f"{cell['base']}/?object={oid}", [], bypass_csp=True)
    try:
        page.fill("#token", TOKEN)
        page.wait_for_selector("#log li.dispatched")
        page.wait_for_selector("#drawing .expected-layer .link")
        page.wait_for_timeout(500)
        page.screenshot(path=str(REPO / "docs" / "console.png"), full_page=True)
        page.locator("#plan li").last.click()
        page.wait_for_timeout(200)
        page.screenshot(path=str(REPO / "docs" / "console-expected-step.png"), full_page=True)
    finally:
        page.close()
