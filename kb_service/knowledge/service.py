"""The knowledge service: what a client may ask the knowledge base, as three functions of plain values (JSON in,
JSON out), so that the HTTP routes (`knowledge_api`) and, later, ROS 2 services call the same thing:

* `sparql(request)` -> the answer's bytes and media type (a SPARQL 1.1 query, read-only, bounded);
* `subsumption(state_id, by_state_id)` -> `{"subsumed", "missing", ...}` (the cooperation model's check);
* `submit_reasoning(body)` / `reasoning_job(job_id)` -> a reasoning job on the live ABox and its answer.

Built from the store (through its interface) and the settings; `close()` stops the reasoning worker.
"""
from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

from planhrc.paths import cache_folder
from planhrc.settings import Settings
from planhrc.vocabulary import ReasoningScope

from .explain import explain_subsumption
from .graph import KnowledgeGraph, KnowledgeSource
from .reasoning import ReasoningRequest, ReasoningResult, check_request, reason, scope_of
from .reasoning_jobs import Job, ReasoningJobs
from .sparql import ENGINES, SparqlAnswer, SparqlEndpoint, SparqlRequest

log = logging.getLogger(__name__)


class KnowledgeService:
    def __init__(self, store: KnowledgeSource, settings: Settings) -> None:
        self.store = store
        self.settings = settings
        self.graph = KnowledgeGraph(store, Path(settings.tbox_path))
        self.endpoint = SparqlEndpoint(self.graph, ENGINES[settings.sparql_engine](settings.sparql_timeout_s),
                                       settings.sparql_timeout_s, settings.sparql_max_results)
        self.jvm_cache = cache_folder()  # where the reasoners' class caches go (`jvm`)
        self.jobs = ReasoningJobs(self._reason, self._keep, settings.reasoning_queue)

    def close(self) -> None:
        self.jobs.close()
        with self.graph.lock:  # after the query that runs, if one does
            self.endpoint.close()

    # -- SPARQL ---------------------------------------------------------------------------------------------
    def sparql(self, request: SparqlRequest) -> SparqlAnswer:
        return self.endpoint.run(request)

    # -- subsumption ----------------------------------------------------------------------------------------
    def subsumption(self, state_id: str, by_state_id: str) -> dict[str, Any]:
        return explain_subsumption(self.store, state_id, by_state_id).public()

    # -- reasoning ------------------------------------------------------------------------------------------
    def submit_reasoning(self, body: dict[str, Any]) -> Job:
        """Queue a reasoning job (`{"reasoner": "pellet"|"hermit", "object_id"?: ..., "scope"?: ...}`); an unknown object is
        refused here, before the job is queued."""
        request = check_request(body.get("reasoner"), body.get("object_id"), body.get("scope", ReasoningScope.STATES))
        if request.object_id is not None:
            self.store.current_roots(request.object_id)  # NotFoundError now rather than a failed job later
        return self.jobs.submit(request)

    def wait(self, job: Job, seconds: float) -> dict[str, Any]:
        job.finished.wait(seconds)
        return job.public()

    def reasoning_job(self, job_id: str) -> dict[str, Any]:
        return self.jobs.get(job_id).public()

    def _reason(self, request: ReasoningRequest) -> ReasoningResult:
        return reason(self.store, request, self.settings.reasoning_timeout_s, self.graph.vocabulary, self.jvm_cache)

    def _keep(self, result: ReasoningResult) -> None:
        """Store what a consistent run inferred, apart from the asserted facts (an inconsistent one infers
        nothing and leaves what earlier runs stored)."""
        if not result.consistent:
            return
        scope = scope_of(ReasoningRequest(result.reasoner, result.object_id))  # where the store keeps them
        self.store.replace_inferred(scope, result.inferred)
        with self.graph.lock:
            self.graph.inferred_changed()
        log.info("reasoning: %s inferred %d facts (%s) in %.2f s", result.reasoner, len(result.inferred), scope,
                 result.seconds)
