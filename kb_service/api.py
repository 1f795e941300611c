"""HTTP routes of the knowledge-base service. The only module that chooses HTTP status codes:

NotFoundError -> 404, ValidationError / ModelError / TranslationError / bad request body -> 422 (the message
names the field), ConflictError -> 409, DeadlineError (planning past its deadline) -> 503,
UnavailableError (the store lost its database connection, a PostgreSQL store only; nothing written) -> 503.
Handlers are plain `def`s: FastAPI runs them in its thread pool, and the use cases' per-object locks serialize
what touches one object. A handler turns its body into a use case's request (`usecases`) and the use case's frozen
result into the route's response model (`schemas`).
"""
from __future__ import annotations

import logging
from typing import Annotated, Any, Awaitable, Callable, Iterable, Iterator, Literal, Sequence

from fastapi import APIRouter, Depends, FastAPI, Header, Query, Request
from fastapi.exception_handlers import http_exception_handler
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse, PlainTextResponse, Response, StreamingResponse
from starlette.concurrency import run_in_threadpool
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.routing import Match, Route

import planhrc
from planhrc.translator.errors import TranslationError

from . import usecases
from .clients import Role
from .guard import OPEN, READ, access
from .events import counted_stream, stream_events
from .store import MAX_EVENTS_PAGE, ConflictError, DeadlineError, NotFoundError, UnavailableError, ValidationError
from .health import usecases_ready
from .record_schemas import (ErrorPublic, EventFields, EventPublic, HealthPublic, LivePublic, PlanPublic, ProblemPublic,
                             ReadyPublic, StatePublic, event_public, event_stream_schema)
from .schemas import (
    DecisionPublic,
    FeedbackCreate,
    FeedbackPublic,
    GiveUpCreate,
    GiveUpPublic,
    GoalPublic,
    GoalUpdate,
    NextActionPublic,
    ObjectCreate,
    ObjectPublic,
    PerceptionCreate,
    SQLITE_MAX_INT,
    QUERY_INTEGRAL,
)

log = logging.getLogger(__name__)

ERRORS: dict[int | str, dict[str, Any]] = {
    400: {"model": ErrorPublic, "description": "The body is not UTF-8 JSON, or Content-Length is not a number."},
    401: {"model": ErrorPublic, "description": "No key, or an unknown or revoked one, where the service needs a key "
          "(writes when the service has keys or a token; reads too when reads are protected)."},
    403: {"model": ErrorPublic, "description": "The client's key is valid but its role may not do this; the message "
          "names the role needed. Nothing was stored."},
    404: {"model": ErrorPublic, "description": "Unknown object, state, problem, plan or action."},
    409: {"model": ErrorPublic, "description": "Conflicts with what is stored."},
    413: {"model": ErrorPublic, "description": "The request body is over the service's size limit."},
    422: {"model": ErrorPublic, "description": "Bad input; the message names the field."},
    503: {"model": ErrorPublic, "description": "Planning (with VAL) did not finish within the service's planning "
          "deadline, or the store's database cannot be reached now (a PostgreSQL store); nothing was stored (the "
          "message says which; retry later, or use a smaller object)."},
}
ERROR_JSON = {"application/json": {"schema": {"$ref": "#/components/schemas/ErrorPublic"}}}
TEXT_ERRORS: dict[int | str, dict[str, Any]] = {  # routes answering text/plain still send their errors as JSON
    status: {"description": ERRORS[status]["description"], "content": ERROR_JSON} for status in (404, 422)
}
RDF_TYPES = {"application/rdf+xml": "xml", "text/turtle": "turtle", "application/n-triples": "nt"}
NEXT_ACTION_MOVED = ("GET /objects/{object_id}/next-action was removed (a GET must not change state): take the next "
                     "action with POST /objects/{object_id}/actions/next")

router = APIRouter(responses={401: ERRORS[401], 403: ERRORS[403], 404: ERRORS[404], 422: ERRORS[422], 503: ERRORS[503]})


def links(status: int, targets: dict[str, tuple[str, str, dict[str, str]]]) -> dict[int | str, dict[str, Any]]:
    """OpenAPI links of a success response: name -> (path, method, {parameter: runtime expression}), so a client
    (and the contract test's stateful phase) knows which answer feeds which request. A link is declared only
    where it holds: its target answers for whatever the response says (a new object has no plan and no problem
    yet, so no link leads from it to `/plan` or `/pddl/problem`); a link through a nullable id
    (`plan_id`, `problem_id`, an action's `id`) holds whenever the id is not null."""
    def ref(path: str, method: str) -> str:
        return "#/paths/" + path.replace("~", "~0").replace("/", "~1") + "/" + method
    return {status: {"links": {name: {"operationRef": ref(path, method), "parameters": parameters}
                               for name, (path, method, parameters) in targets.items()}}}


OBJECT = "/objects/{object_id}"
NEW_OBJECT = {"object_id": "$response.body#/id"}
SAME_OBJECT = {"object_id": "$request.path.object_id"}


# -- dependencies -----------------------------------------------------------------------------------------
# Both are `async def`: they do no I/O and return at once, and FastAPI runs a plain `def` dependency on its thread
# pool, a trip there and back before the handler's own, on the path of every request.
async def get_context(request: Request) -> usecases.Context:
    context: usecases.Context = request.app.state.context
    return context


Ctx = Annotated[usecases.Context, Depends(get_context)]
# The robot's loop (perceive, take the next action, report its outcome) and /health are `async def` and hand their
# use case to the thread pool themselves: FastAPI runs a plain `def` handler there and then validates its answer on
# the pool too, a second trip on every call; these answers are small, validated on the event loop in microseconds.
# Who may call each route (`guard`): the role of a write, READ for a read, OPEN for the probes.
ROBOT, OPERATOR, READS, OPEN_TO_ALL = access(Role.ROBOT), access(Role.OPERATOR), access(READ), access(OPEN)
WRITE_ERRORS: dict[int | str, dict[str, Any]] = {status: ERRORS[status] for status in (400, 401, 403, 409, 413)}


# -- objects ------------------------------------------------------------------------------------------------
@router.post("/objects", status_code=201, response_model=ObjectPublic, openapi_extra=OPERATOR,
             responses={**WRITE_ERRORS, **links(201, {
                 "read": (OBJECT, "get", NEW_OBJECT), "set_goal": (f"{OBJECT}/goal", "put", NEW_OBJECT),
                 "perceive": (f"{OBJECT}/perceptions", "post", NEW_OBJECT),
                 "take_next_action": (f"{OBJECT}/actions/next", "post", NEW_OBJECT),
                 "events": (f"{OBJECT}/events", "get", NEW_OBJECT),
                 "pddl_domain": (f"{OBJECT}/pddl/domain", "get", NEW_OBJECT),
                 "give_up": (f"{OBJECT}/give-up", "post", NEW_OBJECT)})},
             tags=["objects"])
def create_object(body: ObjectCreate, context: Ctx) -> ObjectPublic:
    """Create an articulated object in the ABox."""
    links = body.links if isinstance(body.links, int) else tuple(link.length_m for link in body.links)
    base = tuple(body.base_point_xy) if body.base_point_xy is not None else None
    request = usecases.NewObject(body.name, links, body.orientations, body.formulation, base)
    created = usecases.create_object(context, request)
    return ObjectPublic.model_validate(created, from_attributes=True)


@router.get("/objects", response_model=list[ObjectPublic], tags=["objects"], openapi_extra=READS)
def list_objects(context: Ctx) -> list[ObjectPublic]:
    """Every stored object."""
    return [ObjectPublic.model_validate(o, from_attributes=True) for o in usecases.list_objects(context)]


@router.get("/objects/{object_id}", response_model=ObjectPublic, tags=["objects"], openapi_extra=READS)
def read_object(object_id: str, context: Ctx) -> ObjectPublic:
    """One object with its goal and execution state."""
    return ObjectPublic.model_validate(usecases.read_object(context, object_id), from_attributes=True)


@router.put("/objects/{object_id}/goal", response_model=GoalPublic, openapi_extra=OPERATOR,
            responses={**WRITE_ERRORS, **links(200, {
                "perceive": (f"{OBJECT}/perceptions", "post", SAME_OBJECT),
                "read_problem": ("/problems/{problem_id}", "get", {"problem_id": "$response.body#/problem_id"})})},
            tags=["cooperation"])
def update_goal(object_id: str, body: GoalUpdate, context: Ctx) -> GoalPublic:
    """Set the goal configuration.

    The goal State is stored at once, with a Problem from the latest perceived state when there is one
    (`problem_id`, else null). Any current plan is dropped; planning happens at the next perception (the paper:
    setting a goal triggers a perception), so a goal set before the first perception waits for it.

    For an object placed in the cell (created with `base_point_xy`), a complete goal configuration that does not
    lie on the table (off the table, inside the robot's body, folded onto itself) is refused with 422 naming the
    links, unless `allow_infeasible` is true; links beyond the robot's reach are accepted with `warnings`."""
    links = tuple(body.link_orientations_deg) if body.link_orientations_deg is not None else None
    joints = tuple(body.joint_angles_deg) if body.joint_angles_deg is not None else None
    goal = usecases.set_goal(context, usecases.GoalRequest(object_id, links, joints, body.allow_infeasible))
    return GoalPublic.model_validate(goal, from_attributes=True)


@router.post("/objects/{object_id}/perceptions", response_model=DecisionPublic, openapi_extra=ROBOT,
             responses={**WRITE_ERRORS, 503: ERRORS[503], **links(200, {
                 "take_next_action": (f"{OBJECT}/actions/next", "post", SAME_OBJECT),
                 "read_plan": ("/plans/{plan_id}", "get", {"plan_id": "$response.body#/plan_id"}),
                 "read_state": ("/states/{state_id}", "get", {"state_id": "$response.body#/perceived_state_id"})})},
             tags=["cooperation"])
async def create_perception(
    object_id: str,
    body: PerceptionCreate,
    context: Ctx,
    idempotency_key: Annotated[str | None, Header(max_length=200)] = None,
) -> DecisionPublic:
    """Store a perceived state and apply the cooperation model: goal reached, continue, resume or re-plan; for an
    object placed in the cell a new plan is put in an order that stays on the table, and when the robot cannot
    carry it out the answer is `human_help_requested` with `help`. A perception with unseen links (null) is
    answered `incomplete_perception` with `unseen_links`: it stores no state and changes nothing. With
    `base_point_xy` (the base point as measured) a placed object is checked where it lies now, not where it was
    created."""
    base = tuple(body.base_point_xy) if body.base_point_xy is not None else None
    request = usecases.PerceptionRequest(object_id, tuple(body.link_orientations_deg), idempotency_key, base)
    turn = await run_in_threadpool(usecases.perceive, context, request)
    return DecisionPublic.model_validate(turn, from_attributes=True)


@router.post("/objects/{object_id}/actions/next", response_model=NextActionPublic | None, openapi_extra=ROBOT,
             responses={**WRITE_ERRORS, **links(200, {"feedback": (
                 f"{OBJECT}/actions/{{action_id}}/feedback", "post",
                 {**SAME_OBJECT, "action_id": "$response.body#/id"})})},
             tags=["cooperation"])
async def take_next_action(object_id: str, context: Ctx) -> NextActionPublic | None:
    """For workers: take the action to execute now, which is marked dispatched (taking it again returns the same
    action); null when there is none (no plan, goal reached, or the last action is done and a perception is due).
    It changes the execution, so it is a POST and needs the bearer token when one is configured.

    It replaces `GET /objects/{object_id}/next-action` (a GET must not change state), which is no longer an
    operation: it answers 410 Gone with an ErrorPublic body naming this route."""
    action = await run_in_threadpool(usecases.take_next_action, context, object_id)
    return NextActionPublic.model_validate(action, from_attributes=True) if action is not None else None


@router.get("/objects/{object_id}/next-action", include_in_schema=False)  # documented with its replacement
def read_next_action_gone(object_id: str) -> JSONResponse:
    """Removed: a GET must not change state. Take the next action with `POST /objects/{id}/actions/next`."""
    return JSONResponse({"detail": NEXT_ACTION_MOVED.format(object_id=object_id)}, status_code=410)


@router.post("/objects/{object_id}/actions/{action_id}/feedback", response_model=FeedbackPublic,
             openapi_extra=ROBOT, responses=WRITE_ERRORS, tags=["cooperation"])
async def create_feedback(
    object_id: str,
    action_id: str,
    body: FeedbackCreate,
    context: Ctx,
    idempotency_key: Annotated[str | None, Header(max_length=200)] = None,
) -> FeedbackPublic:
    """Report the outcome of the dispatched action, with the failure's `reason` and the turned link's
    `measured_deg` when it did not succeed (both stored in the feedback event)."""
    request = usecases.FeedbackRequest(object_id, action_id, body.outcome, body.message, idempotency_key,
                                       body.reason, body.measured_deg,
                                       usecases.RefusalFact.of_data(body.refusal.model_dump(mode="json"))
                                       if body.refusal is not None else None, body.hands_open)
    result = await run_in_threadpool(usecases.give_feedback, context, request)
    return FeedbackPublic.model_validate(result, from_attributes=True)


@router.post("/objects/{object_id}/give-up", response_model=GiveUpPublic, openapi_extra=ROBOT,
             responses=WRITE_ERRORS, tags=["cooperation"])
def create_give_up(object_id: str, body: GiveUpCreate, context: Ctx) -> GiveUpPublic:
    """For workers: say that the worker stopped working on the object, and why. The service records a
    `worker_gave_up` event and leaves the execution idle with nothing dispatched; the next perception decides
    anew. A give-up is never silent: it becomes a help request (a `human_help_requested` decision in the log, and
    in the answer) naming what the human should do to reach the goal and why the robot stopped."""
    gave_up = usecases.give_up(context, usecases.GiveUpRequest(object_id, body.reason, body.message))
    return GiveUpPublic.model_validate(gave_up, from_attributes=True)


# -- stored records -------------------------------------------------------------------------------------
@router.get("/objects/{object_id}/plan", response_model=PlanPublic, tags=["records"], openapi_extra=READS, responses=links(200, {
    "read_problem": ("/problems/{problem_id}", "get", {"problem_id": "$response.body#/problem_id"})}))
def read_object_plan(object_id: str, context: Ctx) -> PlanPublic:
    """The plan being followed (or, when none is, the latest one), with its expected states."""
    return PlanPublic.model_validate(usecases.read_current_plan(context, object_id), from_attributes=True)


@router.get("/plans/{plan_id}", response_model=PlanPublic, tags=["records"], openapi_extra=READS)
def read_plan(plan_id: str, context: Ctx) -> PlanPublic:
    return PlanPublic.model_validate(usecases.read_plan(context, plan_id), from_attributes=True)


@router.get("/states/{state_id}", response_model=StatePublic, tags=["records"], openapi_extra=READS)
def read_state(state_id: str, context: Ctx) -> StatePublic:
    return StatePublic.model_validate(usecases.read_state(context, state_id), from_attributes=True)


@router.get("/problems/{problem_id}", response_model=ProblemPublic, tags=["records"], openapi_extra=READS)
def read_problem(problem_id: str, context: Ctx) -> ProblemPublic:
    return ProblemPublic.model_validate(usecases.read_problem(context, problem_id), from_attributes=True)


@router.get("/objects/{object_id}/pddl/domain", response_class=PlainTextResponse, responses=TEXT_ERRORS,
            tags=["pddl"], openapi_extra=READS)
def read_pddl_domain(object_id: str, context: Ctx) -> PlainTextResponse:
    """The PDDL domain of the object's formulation, written from the TBox."""
    return PlainTextResponse(usecases.read_pddl(context, object_id).domain)


@router.get("/objects/{object_id}/pddl/problem", response_class=PlainTextResponse, responses=TEXT_ERRORS,
            tags=["pddl"], openapi_extra=READS)
def read_pddl_problem(object_id: str, context: Ctx) -> PlainTextResponse:
    """The PDDL problem of the object's latest Problem (initial state and goal from the ABox)."""
    return PlainTextResponse(usecases.read_pddl(context, object_id, with_problem=True).problem)


@router.get("/ontology", tags=["records"], openapi_extra=READS,
            responses={200: {"content": {"application/rdf+xml": {}, "text/turtle": {}, "application/n-triples": {}},
                             "description": "TBox and ABox."}})
def read_ontology(
    context: Ctx,
    accept: Annotated[str | None, Header()] = None,
    history: Annotated[Literal["current", "all"], Query(
        description="current: each object's current ABox (object, goal, latest perceived state, latest problem, "
                    "current plan with its actions and expected states); all: every stored triple.")] = "current",
    object_id: Annotated[str | None, Query(alias="object", max_length=200,
                                           description="Only this object's current ABox (with the TBox).")] = None,
) -> Response:
    """TBox and ABox as RDF/XML (default), Turtle (`Accept: text/turtle`) or N-Triples
    (`Accept: application/n-triples`), each written and streamed as it is read, the whole history too. By default the
    ABox is each object's current state of affairs, so the export costs what it returns however long the history;
    `?history=all` adds every past perception, problem and plan; `?object=objN` restricts it to one object."""
    media = _rdf_media_type(accept)
    # streamed in every format: the response holds a piece at a time, and a client (or a shutdown) that stops
    # reading stops the export
    return StreamingResponse(_in_pieces(usecases.export_ontology(context, RDF_TYPES[media], history, object_id)),
                             media_type=media)


# -- events ---------------------------------------------------------------------------------------------
@router.get("/objects/{object_id}/events", response_model=list[EventPublic], tags=["events"], openapi_extra=READS)
def list_events(
    object_id: str,
    context: Ctx,
    after_seq: Annotated[int, Query(ge=0, le=SQLITE_MAX_INT, description="Return events after this seq."), QUERY_INTEGRAL] = 0,
    limit: Annotated[int, Query(ge=1, le=MAX_EVENTS_PAGE, description="At most this many events."), QUERY_INTEGRAL] = MAX_EVENTS_PAGE,
) -> list[EventFields]:
    """A page of the object's log, oldest first: every decision with its reason, goals, dispatches and feedback,
    each kind with its own record as `data` (its schema: the variant of the event's `kind`). The next page starts
    after the last `seq` returned (`after_seq`); a page never holds more than `MAX_EVENTS_PAGE` events, so its cost
    does not grow with the history."""
    return [event_public(e) for e in usecases.list_events(context, object_id, after_seq, limit)]


@router.get("/objects/{object_id}/events/stream", tags=["events"], openapi_extra=READS,
            responses={200: {"content": {"text/event-stream": {"schema": event_stream_schema()}},
                             "description": "Server-Sent Events: `id: <seq>`, `event: <kind>` and `data:` one event "
                             "as `GET /objects/{object_id}/events` lists it (the schema of that line)."}})
def stream_object_events(
    object_id: str,
    request: Request,
    context: Ctx,
    after_seq: Annotated[int, Query(ge=0, le=SQLITE_MAX_INT, description="Send events after this seq."), QUERY_INTEGRAL] = 0,
    max_events: Annotated[int | None, Query(ge=1, le=SQLITE_MAX_INT, description="Stop after this many events."), QUERY_INTEGRAL] = None,
    timeout_s: Annotated[float | None, Query(gt=0, le=86400, description="Stop after this many seconds.")] = None,
    last_event_id: Annotated[str | None, Header()] = None,
) -> StreamingResponse:
    """Every new event of the object, live, as Server-Sent Events."""
    usecases.events_after(context, object_id, after_seq, limit=1)  # an unknown object is a 404 before the stream starts
    if last_event_id and last_event_id.isascii() and last_event_id.isdigit() and int(last_event_id) <= SQLITE_MAX_INT:
        after_seq = max(after_seq, int(last_event_id))
    bell = getattr(request.app.state, "bell", None)  # a store other processes write too: their events, as committed
    frames = stream_events(lambda seq: usecases.events_after(context, object_id, seq), request.is_disconnected,
                           after_seq=after_seq, max_events=max_events, timeout_s=timeout_s,
                           news=None if bell is None else lambda: bell.subscribe(object_id))
    metrics = request.app.state.observation.metrics
    if metrics is not None:
        frames = counted_stream(frames, metrics.event_streams)
    return StreamingResponse(frames, media_type="text/event-stream",
                             headers={"Cache-Control": "no-cache", "X-Accel-Buffering": "no"})


@router.get("/health", response_model=HealthPublic, tags=["service"], openapi_extra=OPEN_TO_ALL)
async def read_health(context: Ctx) -> HealthPublic:
    health = await run_in_threadpool(usecases.read_health, context)  # one trip to the pool: see `Ctx`
    return HealthPublic(status="ok", version=planhrc.__version__, objects=health.objects, triples=health.triples,
                        plans_to_write=health.plans_to_write, auth=bool(context.settings.token))


@router.get("/health/live", response_model=LivePublic, tags=["service"], openapi_extra=OPEN_TO_ALL)
async def read_liveness() -> LivePublic:
    """Liveness, for an orchestrator: the process answers HTTP (its event loop runs). Touches nothing else, so a
    slow database never gets a live service restarted."""
    return LivePublic(status="alive", version=planhrc.__version__)


@router.get("/health/ready", response_model=ReadyPublic, tags=["service"], openapi_extra=OPEN_TO_ALL,
            responses={503: {"model": ReadyPublic, "description": "Not ready: `checks` says what failed."}})
async def read_readiness(request: Request) -> JSONResponse:
    """Readiness, for an orchestrator or a load balancer: 200 when the store answers (a query on its database,
    within `READY_WAIT_S`), the TBox is loaded and planning is reachable (the service's planning pool is open, or
    the planning queue's database answers); else 503 with what failed, so traffic goes to another replica."""
    checks = await usecases_ready(request)
    ready = all(check == "ok" for check in checks.values())
    body = ReadyPublic(status="ready" if ready else "not ready", version=planhrc.__version__, checks=checks)
    return JSONResponse(body.model_dump(), status_code=200 if ready else 503)


@router.get("/metrics", tags=["service"], openapi_extra=READS, response_class=PlainTextResponse,
            responses={200: {"content": {"text/plain": {}}, "description": "Prometheus' text format."},
                       404: ERRORS[404]})
async def read_metrics(request: Request) -> Response:
    """The service's measurements in Prometheus' text format (`metrics`), every name under `planhrc_`: a read
    (it needs a key when reads are protected); 404 when the service runs without metrics."""
    metrics = request.app.state.observation.metrics
    if metrics is None:
        raise NotFoundError("metrics: this service runs without metrics (PLANHRC_METRICS=false)")
    from .metrics import CONTENT_TYPE

    body = await run_in_threadpool(metrics.text)
    return Response(body, media_type=CONTENT_TYPE)


# -- errors ---------------------------------------------------------------------------------------------
def install_error_handlers(app: FastAPI) -> None:
    """Map the typed errors of the libraries to HTTP status codes."""
    from planhrc.model import ModelError

    def handler(status: int) -> Callable[[Request, Exception], Awaitable[JSONResponse]]:
        async def handle(request: Request, exc: Exception) -> JSONResponse:
            return JSONResponse({"detail": str(exc)}, status_code=status)
        return handle

    app.add_exception_handler(NotFoundError, handler(404))
    app.add_exception_handler(ValidationError, handler(422))
    app.add_exception_handler(ModelError, handler(422))
    app.add_exception_handler(TranslationError, handler(422))
    app.add_exception_handler(ConflictError, handler(409))
    app.add_exception_handler(DeadlineError, handler(503))
    app.add_exception_handler(UnavailableError, handler(503))
    app.add_exception_handler(RequestValidationError, _request_validation_error)
    app.add_exception_handler(StarletteHTTPException, _http_error)


async def _http_error(request: Request, exc: Exception) -> Response:
    """FastAPI's own answer, except that a 405's `Allow` lists every method of the path: the router names only
    the methods of the first route whose path matched (`OPTIONS /objects` said `Allow: POST`, not `GET, POST`).
    The service's routes are this module's router's (included without a prefix) and the app's own pages."""
    assert isinstance(exc, StarletteHTTPException)  # registered for that type only
    if exc.status_code == 405:
        allowed = {method for route in (*router.routes, *request.app.router.routes)
                   if isinstance(route, Route) and route.methods and route.matches(request.scope)[0] is not Match.NONE
                   for method in route.methods}
        exc = StarletteHTTPException(405, exc.detail, headers={**(exc.headers or {}),
                                                             "Allow": ", ".join(sorted(allowed))})
    return await http_exception_handler(request, exc)


async def _request_validation_error(request: Request, exc: Exception) -> JSONResponse:
    assert isinstance(exc, RequestValidationError)  # registered for that type only
    messages = [_message(e) for e in exc.errors()]
    return JSONResponse({"detail": "; ".join(messages) or "invalid request"}, status_code=422)


def _message(error: dict[str, Any]) -> str:
    """`field: what is wrong`. A schema's own check says it in its own words (pydantic would prefix "Value
    error, "), and one over the whole body names its fields itself (`reason: must be null when ...`)."""
    path = _field_path(error.get("loc", ()))
    cause = error.get("ctx", {}).get("error") if error.get("type") == "value_error" else None
    if cause is None:
        return f"{path}: {error.get('msg', 'invalid')}"
    return str(cause) if path == "body" else f"{path}: {cause}"


def _field_path(loc: Sequence[int | str]) -> str:
    parts = list(loc)
    if parts and parts[0] in ("body", "query", "path", "header"):
        parts = parts[1:]
    out = ""
    for p in parts:
        if isinstance(p, int):
            out += f"[{p}]"
        else:
            out += ("." if out else "") + str(p)
    return out or "body"


# -- conversions ----------------------------------------------------------------------------------------
def _in_pieces(lines: Iterable[str], size: int = 64 * 1024) -> Iterator[bytes]:
    """Lines joined into pieces of about `size` bytes: the stream still starts at once and holds one piece, but
    it no longer hops to the thread pool once per triple, which made a whole ABox's export crawl."""
    piece: list[str] = []
    length = 0
    for line in lines:
        piece.append(line)
        length += len(line)
        if length >= size:
            yield "".join(piece).encode("utf-8")
            piece, length = [], 0
    if piece:
        yield "".join(piece).encode("utf-8")
def _rdf_media_type(accept: str | None) -> str:
    """The first of RDF/XML, Turtle and N-Triples named by the Accept header; RDF/XML when none is."""
    if accept:
        for part in accept.split(","):
            media = part.split(";")[0].strip().lower()
            if media in RDF_TYPES:
                return media
    return "application/rdf+xml"
