"""HTTP routes of the knowledge service (`knowledge.KnowledgeService`): the SPARQL 1.1 Protocol endpoint, the
subsumption check between two states and reasoning jobs. Mounted by `app.create_app`; like `api`, this layer alone
chooses the status codes of its errors:

QueryError (malformed query, update, SERVICE, unknown graph, answer over the size limit) -> 400 (the SPARQL
Protocol's "malformed query"), BusyError (the reasoning queue is full) -> 429 with Retry-After; DeadlineError
(a query past its time limit) and EngineError (the query process failed) -> 503, and as everywhere (`api`'s mapping)
NotFoundError -> 404, ValidationError -> 422 and UnavailableError (the store lost its database connection; nothing
written) -> 503.

Reads follow the service's policy for reads (`POST /sparql` is a read: a query changes nothing); `POST /reasoning`
stores what the reasoner inferred, so it is the operator's.
"""
from __future__ import annotations

from typing import Annotated, Any, Literal
from urllib.parse import parse_qs

from fastapi import APIRouter, Depends, FastAPI, Query, Request
from fastapi.responses import JSONResponse, Response
from pydantic import BaseModel, ConfigDict, Field
from starlette.concurrency import run_in_threadpool

from planhrc.vocabulary import ReasoningScope

from .api import ERRORS, OPERATOR, READS
from .knowledge.reasoning_jobs import BusyError
from .knowledge.service import KnowledgeService
from .knowledge.query_engine import EngineError, QueryError
from .knowledge.sparql import GRAPH_TYPES, RESULT_TYPES, SparqlRequest

SPARQL_QUERY = "application/sparql-query"
SPARQL_UPDATE = "application/sparql-update"
FORM = "application/x-www-form-urlencoded"
UPDATE_REFUSED = ("update: this endpoint is read-only; SPARQL Update (INSERT, DELETE, LOAD, CLEAR, CREATE, DROP, "
                  "...) is refused")
RETRY_AFTER_S = 5
# A query by GET travels in the request line, which the HTTP server reads only up to a size (percent-encoded, a
# character may take 12 bytes): longer queries go by POST, whose body has the service's own limit.
GET_QUERY_CHARS = 1000

QUERY_ERRORS: dict[int | str, dict[str, Any]] = {
    400: {"model": ERRORS[422]["model"], "description": "Not a query this endpoint answers: malformed, an update, "
          "SERVICE, a graph it does not have, or an answer over the result-size limit (the message says which)."},
    503: {"model": ERRORS[422]["model"], "description": "The query did not finish within the service's time limit, "
          "or the store's database cannot be reached now (a PostgreSQL store)."},
}
UNAVAILABLE = {"model": ERRORS[422]["model"], "description": "The store's database cannot be reached now (a "
               "PostgreSQL store); nothing was written: send the request again later."}
SPARQL_CONTENT: dict[str, dict[str, Any]] = {media: {} for media in (*RESULT_TYPES, *GRAPH_TYPES)}

router = APIRouter(responses={401: ERRORS[401], 403: ERRORS[403], 422: ERRORS[422], 503: UNAVAILABLE})


class ReasoningCreate(BaseModel):
    model_config = ConfigDict(extra="forbid")
    reasoner: Literal["pellet", "hermit"] = Field(description="The DL reasoner to run.")
    object_id: str | None = Field(default=None, min_length=1, max_length=200,
                                  description="Only this object's current ABox (with the TBox); else every object's.")
    scope: ReasoningScope = Field(default=ReasoningScope.STATES, description="`states`: each object with its goal "
                                  "and latest perceived state (what consistency, the states' types and the rules "
                                  "are about); `current`: the whole current ABox, the plan's actions and expected "
                                  "states included (slower).")


async def get_knowledge(request: Request) -> KnowledgeService:
    knowledge: KnowledgeService = request.app.state.knowledge
    return knowledge


Knowledge = Annotated[KnowledgeService, Depends(get_knowledge)]


# -- SPARQL ---------------------------------------------------------------------------------------------------
@router.get("/sparql", tags=["knowledge"], openapi_extra=READS, responses={200: {"content": SPARQL_CONTENT, "description":
            "SPARQL results (SELECT, ASK) or RDF (CONSTRUCT, DESCRIBE) in the format Accept names."}, **QUERY_ERRORS})
def read_sparql(
    knowledge: Knowledge,
    request: Request,
    query: Annotated[str, Query(max_length=GET_QUERY_CHARS, description="A SPARQL 1.1 query (longer: by POST).")],
    default_graph_uri: Annotated[list[Annotated[str, Field(max_length=200)]] | None,
                                 Query(alias="default-graph-uri", max_length=4)] = None,
    named_graph_uri: Annotated[list[Annotated[str, Field(max_length=200)]] | None,
                               Query(alias="named-graph-uri", max_length=4)] = None,
) -> Response:
    """A SPARQL 1.1 query (the SPARQL Protocol's query by GET) over the TBox, the current ABox of every object and
    the facts the TBox entails from it (the default graph), with the graphs `http://planhrc.org/graph/tbox`,
    `…/abox`, `…/entailed` and `…/inferred` (what `POST /reasoning` inferred) as named graphs. Answers
    SPARQL JSON by default, XML, CSV or TSV by `Accept`; CONSTRUCT and DESCRIBE answer Turtle, N-Triples,
    RDF/XML or JSON-LD."""
    return _answer(knowledge, SparqlRequest(query, request.headers.get("accept"), tuple(default_graph_uri or ()),
                                            tuple(named_graph_uri or ())))


@router.post("/sparql", tags=["knowledge"], openapi_extra={**READS, "requestBody": {"required": True, "content": {
             SPARQL_QUERY: {"schema": {"type": "string"}},
             FORM: {"schema": {"type": "object", "properties": {"query": {"type": "string"}}}}}}},
             responses={200: {"content": SPARQL_CONTENT, "description": "As GET."}, **QUERY_ERRORS, 413: ERRORS[413]})
async def create_sparql_query(knowledge: Knowledge, request: Request) -> Response:
    """The same query by POST: a form (`query=...`) or the query itself (`Content-Type: application/sparql-query`).
    An update (`update=...`, `application/sparql-update`) is refused: the endpoint is read-only."""
    media = request.headers.get("content-type", "").split(";")[0].strip().lower()
    body = await request.body()
    params = {k: v for k, v in parse_qs(request.url.query).items()}
    if media == SPARQL_UPDATE:
        raise QueryError(UPDATE_REFUSED)
    if media == SPARQL_QUERY:
        params["query"] = [body.decode("utf-8", errors="replace")]
    elif media == FORM:
        form = parse_qs(body.decode("utf-8", errors="replace"))
        if "update" in form:
            raise QueryError(UPDATE_REFUSED)
        for key, values in form.items():
            params.setdefault(key, []).extend(values)
    else:
        raise QueryError(f"Content-Type: send the query as {SPARQL_QUERY} or as a form ({FORM}), not {media!r}")
    queries = params.get("query") or [""]
    if len(queries) > 1:
        raise QueryError("query: send one query per request")
    sparql = SparqlRequest(queries[0], request.headers.get("accept"), tuple(params.get("default-graph-uri", ())),
                           tuple(params.get("named-graph-uri", ())))
    return await run_in_threadpool(_answer, knowledge, sparql)  # the query is CPU work: off the event loop


def _answer(knowledge: KnowledgeService, request: SparqlRequest) -> Response:
    answer = knowledge.sparql(request)
    return Response(answer.body, media_type=answer.media_type,
                    headers={"X-Result-Count": str(answer.rows), "Cache-Control": "no-store"})


# -- subsumption ------------------------------------------------------------------------------------------------
class SubsumptionPublic(BaseModel):
    state_id: str
    by_state_id: str
    subsumed: bool = Field(description="D(state) ⊑ D(by): every atom of `by` is an atom of `state`.")
    missing: list[str] = Field(description="The atoms of `by` that `state` does not assert (empty when subsumed).")
    differs: list[dict[str, str | None]] = Field(description="For each joint among `missing`: its orientation in "
                                                 "`state` (`has`, null when `state` gives none) and in `by` (`wants`).")
    atoms_checked: int = Field(description="How many atoms `by` asserts.")


@router.get("/states/{state_id}/subsumed-by/{by_state_id}", response_model=SubsumptionPublic,
            tags=["knowledge"], openapi_extra=READS, responses={404: ERRORS[404]})
def read_subsumption(state_id: str, by_state_id: str, knowledge: Knowledge) -> dict[str, Any]:
    """Is D(state) ⊑ D(by)? The check the cooperation model runs (is the perceived state within the goal, or
    the expected state?); when not, the atoms of `by` that `state` does not entail, i.e. why not."""
    return knowledge.subsumption(state_id, by_state_id)


# -- reasoning ------------------------------------------------------------------------------------------------
@router.post("/reasoning", openapi_extra=OPERATOR, tags=["knowledge"], status_code=200,
             responses={202: {"description": "The job runs on; its answer will be at Location."}, 400: ERRORS[400],
                        404: ERRORS[404], 413: ERRORS[413],
                        429: {"model": ERRORS[422]["model"], "description": "Too many reasoning jobs at once; "
                              "Retry-After says when to try again."}})
def create_reasoning(body: ReasoningCreate, knowledge: Knowledge) -> JSONResponse:
    """Run a DL reasoner (consistency, classification, the SWRL rules) on the live ABox, off the request path.
    The answer is the result when the job finishes within the service's `reasoning_answer_wait_s`, else 202 with
    the job's location. The result: `{"consistent", "reasoner", "inferred", "seconds", ...}`, and for an
    inconsistent ABox the individuals and axioms of an explanation. What a consistent run inferred is stored
    apart from the asserted facts: the SPARQL graph `http://planhrc.org/graph/inferred`."""
    job = knowledge.submit_reasoning(body.model_dump())
    answer = knowledge.wait(job, knowledge.settings.reasoning_answer_wait_s)
    if not job.finished.is_set():
        return JSONResponse(answer, status_code=202, headers={"Location": f"/reasoning/{job.id}"})
    return JSONResponse(answer, status_code=200)


@router.get("/reasoning/{job_id}", tags=["knowledge"], openapi_extra=READS, responses={404: ERRORS[404]})
def read_reasoning(job_id: str, knowledge: Knowledge) -> dict[str, Any]:
    """A reasoning job: `queued`, `running`, `done` (with its result) or `failed` (with its error)."""
    return knowledge.reasoning_job(job_id)


# -- errors -------------------------------------------------------------------------------------------------
def install_knowledge_errors(app: FastAPI) -> None:
    async def bad_query(request: Request, exc: Exception) -> JSONResponse:
        return JSONResponse({"detail": str(exc)}, status_code=400)

    async def busy(request: Request, exc: Exception) -> JSONResponse:
        return JSONResponse({"detail": str(exc)}, status_code=429, headers={"Retry-After": str(RETRY_AFTER_S)})

    async def unavailable(request: Request, exc: Exception) -> JSONResponse:
        return JSONResponse({"detail": str(exc)}, status_code=503, headers={"Retry-After": "1"})

    app.add_exception_handler(QueryError, bad_query)
    app.add_exception_handler(EngineError, unavailable)
    app.add_exception_handler(BusyError, busy)
