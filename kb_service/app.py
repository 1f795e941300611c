"""The FastAPI application, built by `create_app(settings)`; nothing is created at import time."""
from __future__ import annotations

import gc
import logging
import threading
from contextlib import asynccontextmanager
from typing import AsyncIterator, Callable

from fastapi import FastAPI

import planhrc
from planhrc.settings import Settings, get_settings

from .api import install_error_handlers, router
from .console import install_console
from .guard import GuardPolicy, RequestGuard
from .locks import ObjectLocks
from .planning_pool import PlanningPool
from .store import KBError, KnowledgeBase
from .usecases import close_context, open_context

log = logging.getLogger(__name__)


def open_knowledge_base(settings: Settings) -> KnowledgeBase:
    """Open the store named by the settings (':memory:' or None: a throwaway in-memory store)."""
    path = None if settings.db_path in (None, "", ":memory:") else settings.db_path
    return KnowledgeBase(path, settings.tbox_path)


def compact_on_schedule(kb: KnowledgeBase, settings: Settings, stop: threading.Event) -> None:
    """Compact the store every `compact_every_s` seconds until `stop` is set (the retention policy)."""
    while not stop.wait(settings.compact_every_s):
        try:
            done = kb.compact(settings.keep_perceived)
            log.info("compacted the store: %d individuals, %d triples dropped", done.individuals, done.triples)
        except KBError as exc:
            log.error("compaction failed: %s", exc)


def freeze_heap() -> None:
    """Leave what start-up built (modules, the TBox, the store) out of the garbage collector's full passes until
    shutdown (`gc.freeze`): each full pass walks every object not frozen while it holds the interpreter, and
    start-up's objects (most of the heap) made every pass long enough for every request (/health too) to wait on
    it. Shutdown unfreezes them, so an app built and closed in a longer process (a test) is collected."""
    gc.freeze()


def create_app(settings: Settings | None = None,
               open_store: Callable[[Settings], KnowledgeBase] = open_knowledge_base) -> FastAPI:
    """The planHRC knowledge-base service: a KnowledgeBase is opened at start-up (`open_store`, by default the
    one the settings name) and closed at shutdown."""
    settings = settings or get_settings()

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        kb = open_store(settings)
        app.state.kb = kb
        pool = PlanningPool(settings.planning_workers, settings.planning_pool_min_atoms)
        context = app.state.context = open_context(kb, settings, ObjectLocks(), pool)
        log.info("knowledge base open: %s", settings.db_path or "in memory")
        freeze_heap()
        stop = threading.Event()
        compactor = None
        if settings.compact_every_s > 0:
            compactor = threading.Thread(target=compact_on_schedule, args=(kb, settings, stop),
                                         name="planhrc-compact", daemon=True)
            compactor.start()
        try:
            yield
        finally:
            stop.set()
            if compactor is not None:
                compactor.join(timeout=60)
            close_context(context)
            pool.close()
            kb.close()
            gc.unfreeze()
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
