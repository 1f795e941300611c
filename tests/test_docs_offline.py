"""The API documentation works with no network beyond loopback: Swagger UI (`/docs`) and ReDoc (`/redoc`) load
their scripts from files installed with the project, and the OpenAPI document declares the bearer-token scheme
(the Authorize button). Checked in Debian's Chromium against a real `planhrc serve` process."""
from __future__ import annotations

import sys
from pathlib import Path

import httpx
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_console import browser_missing, chromium, open_page, serve  # noqa: E402

pytestmark = [pytest.mark.integration, pytest.mark.browser]


@pytest.fixture(scope="module")
def service(tmp_path_factory):
    with serve(tmp_path_factory.mktemp("docs") / "kb.sqlite3", token="docs-token") as base:
        yield base


def test_openapi_declares_the_bearer_scheme_on_every_write(service):
    schema = httpx.get(f"{service}/openapi.json").json()
    assert schema["components"]["securitySchemes"]["bearerToken"] == {
        "type": "http", "scheme": "bearer", "description": schema["components"]["securitySchemes"]["bearerToken"]["description"]}
    secured = {(path, method) for path, ops in schema["paths"].items() for method, op in ops.items() if op.get("security")}
    assert ("/objects", "post") in secured
    assert ("/objects/{object_id}/perceptions", "post") in secured
    assert ("/objects/{object_id}/goal", "put") in secured
    assert ("/objects", "get") not in secured and ("/health", "get") not in secured  # reads stay open
    for ops in schema["paths"].values():  # the token is asked for once, by the scheme, not as a header field
        for op in ops.values():
            assert all(p["name"].lower() != "authorization" for p in op.get("parameters", []))


def test_docs_pages_reference_no_other_host(service):
    for path in ("/docs", "/redoc"):
        html = httpx.get(f"{service}{path}").text
        assert "cdn." not in html and "https://" not in html.replace("https://fastapi.tiangolo.com", "")
    for asset in ("swagger-ui-bundle.js", "swagger-ui.css", "redoc.standalone.js"):
        r = httpx.get(f"{service}/docs-assets/{asset}")
        assert r.status_code == 200 and len(r.content) > 10_000


def test_swagger_ui_lists_the_operations_offline(service):
    reason = browser_missing()
    if reason:
        pytest.skip(reason)
    operations = sum(len(ops) for ops in httpx.get(f"{service}/openapi.json").json()["paths"].values())
    outside: list[str] = []
    with chromium() as browser:
        page = open_page(browser, f"{service}/docs", outside)
        page.wait_for_selector(".opblock", timeout=20000)
        assert page.locator(".opblock").count() == operations
        assert page.locator(".opblock-summary-path", has_text="/objects/{object_id}/perceptions").count() >= 1
        assert page.locator("button.authorize").count() == 1
        redoc = open_page(browser, f"{service}/redoc", outside)
        redoc.wait_for_selector("[data-section-id^='tag/']", timeout=20000)
        assert redoc.locator("[data-section-id^='operation/']").count() == operations
        page.close()
        redoc.close()
    assert outside == []
