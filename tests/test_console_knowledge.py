"""The console asks the knowledge base too, in a real browser (Debian's Chromium through Playwright) against a real
`planhrc serve`: its query panel runs a ready example and shows the rows the API answers, shows the endpoint's
own message for a refused query, and "why not?" beside a decision names the joints the perceived state lacks."""
from __future__ import annotations

import httpx
import pytest

from tests.test_console import browser, open_page, serve  # noqa: F401 (the module's browser fixture)

TOKEN = "console-token"

pytestmark = [pytest.mark.integration, pytest.mark.browser]


@pytest.fixture(scope="module")
def page(browser, tmp_path_factory):  # noqa: F811
    db = tmp_path_factory.mktemp("console-knowledge") / "kb.sqlite3"
    with serve(db, None, TOKEN) as base:
        with httpx.Client(base_url=base, timeout=30, headers={"Authorization": f"Bearer {TOKEN}"}) as client:
            oid = client.post("/objects", json={"name": "rod", "links": 4, "orientations": 4,
                                                "formulation": "relative"}).json()["id"]
            goal = client.put(f"/objects/{oid}/goal", json={"link_orientations_deg": [0, 90, 90, 180]})
            assert goal.status_code == 200
            assert client.post(f"/objects/{oid}/perceptions", json={"link_orientations_deg": [0, 0, 0, 0]}).json()[
                "decision"] == "replan"
            outside: list[str] = []
            page = open_page(browser, f"{base}/?object={oid}", outside, bypass_csp=True)
            page.fill("#token", TOKEN)
            page.dispatch_event("#token", "change")
            page.wait_for_selector("#log li.replan")
            yield page, client, oid, outside
            page.close()


def test_the_query_panel_runs_an_example(page):
    page, client, oid, outside = page
    page.select_option("#query-example", label="current state of every object")
    page.click("#query-run")
    page.wait_for_selector("#query-result table tr:nth-child(2)")
    cells = page.locator("#query-result td").all_inner_texts()
    assert cells[:3] == [oid, f"{oid}_j1", "0"]  # relative: j1 carries l2 - l1 = 0
    answer = client.get("/sparql", params={"query": page.input_value("#query-text")}).json()
    assert page.locator("#query-result tr").count() == len(answer["results"]["bindings"]) + 1
    assert "rows in" in page.inner_text("#query-status")
    assert outside == []


def test_a_refused_query_shows_the_endpoints_message(page):
    page = page[0]
    page.fill("#query-text", "DELETE WHERE { ?s ?p ?o }")
    page.click("#query-run")
    page.wait_for_function("document.getElementById('query-error').textContent.length > 0")
    assert "read-only" in page.inner_text("#query-error")
    assert page.locator("#query-result table").count() == 0


def test_why_not_names_the_missing_joints(page):
    page, _, oid, _ = page
    item = page.locator("#log li.replan").first
    item.locator(".why-button").click()
    page.wait_for_selector("#log li.replan .why-not li")
    text = item.locator(".why-not").inner_text()
    assert "not within the goal" in text
    assert "j1 is 0°, wants 90°" in text and "j3 is 0°, wants 90°" in text
