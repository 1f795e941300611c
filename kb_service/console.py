"""The cell console at `/` and the API documentation at `/docs` and `/redoc`, all served from installed files.

The console is plain HTML, JavaScript and CSS shipped as package data (`console/`): no build step, nothing
fetched from elsewhere. It only reads and posts goals and perceptions through the JSON API; it never takes an
action for execution (that is the worker's). Swagger UI and ReDoc load their scripts from the `fastapi-offline`
package's files, so the documentation works on a network that reaches no CDN. The OpenAPI document declares the
bearer scheme on every operation that needs a key, so the docs page has an Authorize button.
"""
from __future__ import annotations

from importlib.resources import files
from pathlib import Path
from typing import Any, Callable

from fastapi import FastAPI, Request
from fastapi.openapi.docs import get_redoc_html, get_swagger_ui_html, get_swagger_ui_oauth2_redirect_html
from fastapi.responses import FileResponse, HTMLResponse
from fastapi.staticfiles import StaticFiles

from .guard import ACCESS, OPEN, READ

CONSOLE_URL = "/"
CONSOLE_ASSETS_URL = "/console"
DOCS_URL = "/docs"
REDOC_URL = "/redoc"
DOCS_ASSETS_URL = "/docs-assets"
SECURITY_SCHEME = "bearerToken"
# What the pages may load: only this service. Swagger UI and ReDoc need their inline start-up script and styles
# (and ReDoc a worker from a blob); the one outside image ReDoc's bundle names (its logo) is thereby never fetched.
DOCS_POLICY = ("default-src 'self'; script-src 'self' 'unsafe-inline' blob:; worker-src 'self' blob:; "
               "style-src 'self' 'unsafe-inline'; img-src 'self' data:; font-src 'self' data:")
CONSOLE_POLICY = "default-src 'self'; img-src 'self' data:"


def console_dir() -> Path:
    """The console's static files, as installed with `planhrc.kb_service`."""
    return Path(str(files("planhrc.kb_service") / "console"))


def docs_assets_dir() -> Path:
    """Swagger UI and ReDoc scripts and styles shipped by the `fastapi-offline` package."""
    return Path(str(files("fastapi_offline") / "static"))


def install_console(app: FastAPI, protect_reads: bool = False) -> None:
    """Mount the console, the offline docs and their assets on an app built with docs_url=redoc_url=None.

    `protect_reads`: the service asks for the token on reads of the knowledge base too (see `guard`), so the
    OpenAPI document declares the scheme on those operations as well."""
    app.mount(CONSOLE_ASSETS_URL, StaticFiles(directory=console_dir()), name="console-assets")
    app.mount(DOCS_ASSETS_URL, StaticFiles(directory=docs_assets_dir()), name="docs-assets")
    index = console_dir() / "index.html"
    oauth2_redirect_url = app.swagger_ui_oauth2_redirect_url or "/docs/oauth2-redirect"

    @app.get(CONSOLE_URL, include_in_schema=False)
    def read_console() -> FileResponse:
        return FileResponse(index, media_type="text/html",
                            headers={"Cache-Control": "no-cache", "Content-Security-Policy": CONSOLE_POLICY})

    def docs_page(request: Request, make: Callable[[str, str], HTMLResponse]) -> HTMLResponse:
        """A documentation page made by `make(root, assets)` (the served root, the shipped assets' URL), under the
        documentation pages' content policy."""
        root = request.scope.get("root_path", "")
        page = make(root, f"{root}{DOCS_ASSETS_URL}")
        page.headers["Content-Security-Policy"] = DOCS_POLICY
        return page

    @app.get(DOCS_URL, include_in_schema=False)
    def read_swagger_ui(request: Request) -> HTMLResponse:
        return docs_page(request, lambda root, assets: get_swagger_ui_html(
            openapi_url=f"{root}{app.openapi_url}", title=f"{app.title} - Swagger UI",
            oauth2_redirect_url=f"{root}{oauth2_redirect_url}", swagger_js_url=f"{assets}/swagger-ui-bundle.js",
            swagger_css_url=f"{assets}/swagger-ui.css", swagger_favicon_url=f"{assets}/favicon.png",
            swagger_ui_parameters={"persistAuthorization": True}))

    @app.get(oauth2_redirect_url, include_in_schema=False)
    def read_swagger_ui_redirect() -> HTMLResponse:
        return get_swagger_ui_oauth2_redirect_html()

    @app.get(REDOC_URL, include_in_schema=False)
    def read_redoc(request: Request) -> HTMLResponse:
        return docs_page(request, lambda root, assets: get_redoc_html(
            openapi_url=f"{root}{app.openapi_url}", title=f"{app.title} - ReDoc",
            redoc_js_url=f"{assets}/redoc.standalone.js", redoc_favicon_url=f"{assets}/favicon.png",
            with_google_fonts=False))

    app.openapi = openapi_with_bearer(app.openapi, protect_reads)  # type: ignore[method-assign]


def openapi_with_bearer(build: Callable[[], dict[str, Any]], protect_reads: bool = False) -> Callable[[], dict[str, Any]]:
    """Wrap FastAPI's OpenAPI builder: declare the bearer scheme on every operation for a role, and on every read
    when reads are protected (each operation's `x-planhrc-access`, `guard`)."""
    def openapi() -> dict[str, Any]:
        schema = build()  # FastAPI caches the document: this adds the scheme once
        schemes = schema.setdefault("components", {}).setdefault("securitySchemes", {})
        if SECURITY_SCHEME in schemes:
            return schema
        schemes[SECURITY_SCHEME] = {
            "type": "http", "scheme": "bearer",
            "description": "A client's key (`planhrc keys add NAME --role ROLE`), or the token given to `planhrc "
            "serve --token`. Each write needs the role its operation names (`x-planhrc-access`) once the service has "
            "a key or a token; reads need a key of any role when reads are protected.",
        }
        for path, operations in schema.get("paths", {}).items():
            for operation in operations.values():
                allowed = operation.get(ACCESS, OPEN)
                if allowed == OPEN or (allowed == READ and not protect_reads):
                    continue
                operation.setdefault("security", [{SECURITY_SCHEME: []}])
        return schema

    return openapi
