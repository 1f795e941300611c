"""The FastAPI application, built by `create_app(settings)`; nothing is created at import time."""
from __future__ import annotations

import gc
import logging
import threading
from contextlib import asynccontextmanager
from typing import TYPE_CHECKING, AsyncIterator, Callable

from fastapi import FastAPI
from starlette.routing import Mount, Route

import planhrc
from planhrc.settings import Settings, get_settings

from .api import install_error_handlers, router
from .clients import ClientRegistry, open_table
from .console import install_console
from .events import EventBell
from .guard import GuardPolicy, RequestGuard, Scope, check_routes, route_table
from .metrics import ServiceMetrics
from .observe import Observation, Observe
from .tracing import Tracing
from .knowledge.service import KnowledgeService
from .knowledge_api import install_knowledge_errors
from .knowledge_api import router as knowledge_router
from .locks import ObjectLocks
from .planning_pool import PlanningPool
from .store import EventFeeding, KBError, KnowledgeStore
from .store.backends import backend_of
from .store.location import shown_location
from .usecases import close_context, open_context

if TYPE_CHECKING:
    from .planning_queue import QueuedPlanning  # psycopg: only with a PostgreSQL store

log = logging.getLogger(__name__)


def open_knowledge_base(settings: Settings) -> KnowledgeStore:
    """Open the store named by the settings (a SQLite file, ':memory:' or None for a throwaway in-memory store, or
    a PostgreSQL URL)."""
    from planhrc.kb_service.store import open_store

    password = settings.db_password.get_secret_value() if settings.db_password else None
    return open_store(settings.db_path, settings.tbox_path, password)


def open_planning(settings: Settings, tracing: Tracing | None = None) -> PlanningPool | QueuedPlanning:
    """Where the service plans large tasks: the database's planning job queue (`planning_queue`, PostgreSQL), served
    by `planhrc planning-worker` processes on any host, else its own planning worker processes."""
    if settings.planning_queue:
        if settings.db_path is None or backend_of(settings.db_path) != "postgresql":
            raise KBError("planning_queue: the planning job queue is a PostgreSQL store's (--db postgresql://...)")
        from .planning_queue import QueuedPlanning

        password = settings.db_password.get_secret_value() if settings.db_password else None
        return QueuedPlanning(settings.db_path, password, settings.planning_pool_min_atoms, tracing=tracing)
    environment = {"PLANHRC_OTLP_ENDPOINT": settings.otlp_endpoint} if settings.otlp_endpoint else {}
    return PlanningPool(settings.planning_workers, settings.planning_pool_min_atoms, tracing=tracing,
                        environment=environment)


def open_clients(settings: Settings) -> ClientRegistry:
    """The clients' keys in the store's database (an in-memory store's: in memory), with the tokens' shortcuts."""
    password = settings.db_password.get_secret_value() if settings.db_password else None
    return ClientRegistry(open_table(settings.db_path, password), settings.token, settings.read_token)


def _registry(scope: Scope) -> ClientRegistry | None:
    registry: ClientRegistry | None = getattr(scope["app"].state, "clients", None)
    return registry


def compact_on_schedule(kb: KnowledgeStore, settings: Settings, stop: threading.Event) -> None:
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
               open_store: Callable[[Settings], KnowledgeStore] = open_knowledge_base) -> FastAPI:
    """The planHRC knowledge-base service: a SqliteStore is opened at start-up (`open_store`, by default the
    one the settings name) and closed at shutdown."""
    settings = settings or get_settings()

    observation = Observation(ServiceMetrics() if settings.metrics else None, Tracing.off())

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        tracing = observation.tracing = Tracing.start("planhrc-service", settings.otlp_endpoint, settings.trace_ratio)
        pool = open_planning(settings, tracing)
        try:
            kb = open_store(settings)
            clients = open_clients(settings)
        except BaseException:
            pool.close()
            tracing.close()
            raise
        app.state.kb = kb
        app.state.clients = clients
        context = app.state.context = open_context(kb, settings, ObjectLocks(), pool, observation)
        if observation.metrics is not None:
            observation.metrics.watch_queue(getattr(pool, "depth", None))
        knowledge = app.state.knowledge = KnowledgeService(kb, settings)
        # a store other processes write too: event streams wait on its feed of committed events
        bell = app.state.bell = EventBell(kb.event_feed) if isinstance(kb, EventFeeding) else None
        log.info("knowledge base open: %s", shown_location(settings.db_path) if settings.db_path else "in memory")
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
            if bell is not None:
                bell.close()
            knowledge.close()
            close_context(context)
            pool.close()
            clients.close()
            kb.close()
            tracing.close()
            observation.tracing = Tracing.off()
            if observation.metrics is not None:
                observation.metrics.watch_queue(None)
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
    app.state.observation = observation
    app.add_middleware(RequestGuard, policy=GuardPolicy(protect_reads=settings.protect_reads,
                                                        max_body_bytes=settings.max_body_bytes), registry=_registry)
    app.add_middleware(Observe, observation=observation)  # the outermost: refusals are counted and traced too
    install_error_handlers(app)
    install_knowledge_errors(app)
    app.include_router(router)
    app.include_router(knowledge_router)
    install_console(app, protect_reads=settings.protect_reads)
    # what the guard and the metrics match a request against: the routers' routes and the app's own
    routes = [*router.routes, *knowledge_router.routes, *(r for r in app.routes if isinstance(r, (Route, Mount)))]
    check_routes(routes)
    app.state.routes = route_table(routes)
    return app
