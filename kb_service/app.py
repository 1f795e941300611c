"""The FastAPI application, built by `create_app(settings)`; nothing is created at import time."""
from __future__ import annotations

import logging
from contextlib import asynccontextmanager
from typing import AsyncIterator

from fastapi import FastAPI

import planhrc
from planhrc.settings import Settings, get_settings

from .api import install_error_handlers, router
from .console import install_console
from .guard import GuardPolicy, RequestGuard
from .locks import ObjectLocks
from .orchestrator import Orchestrator

log = logging.getLogger(__name__)


def open_knowledge_base(settings: Settings):
    """Open the store named by the settings (':memory:' or None: a throwaway in-memory store)."""
    from planhrc.kb_service.store import KnowledgeBase

    path = None if settings.db_path in (None, "", ":memory:") else settings.db_path
    return KnowledgeBase(path, settings.tbox_path)


def create_app(settings: Settings | None = None) -> FastAPI:
    """The planHRC knowledge-base service: a KnowledgeBase is opened at start-up and closed at shutdown."""
    settings = settings or get_settings()

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        kb = open_knowledge_base(settings)
        app.state.kb = kb
        app.state.orchestrator = Orchestrator(kb, settings, ObjectLocks())
        log.info("knowledge base open: %s", settings.db_path or "in memory")
        try:
            yield
        finally:
            kb.close()
            log.info("knowledge base closed")

    app = FastAPI(
        title="planHRC knowledge-base service",
        version=planhrc.__version__,
        description="Ontology (TBox + ABox), cooperation model and plans of articulated objects manipulated by "
        "a robot and a human together.",
        lifespan=lifespan,
        docs_url=None,  # served offline by install_console
        redoc_url=None,
    )
    app.state.settings = settings
    app.add_middleware(RequestGuard, policy=GuardPolicy(
        token=settings.token, read_token=settings.read_token, protect_reads=settings.protect_reads,
        max_body_bytes=settings.max_body_bytes))
    install_error_handlers(app)
    app.include_router(router)
    install_console(app, protect_reads=settings.protect_reads)
    return app
