"""`planhrc service-bench --parts knowledge`: the knowledge service of a `planhrc serve` with a long history,
measured over HTTP (not a test).

* SPARQL: the current state of every object (the query the console offers first) after `perceptions` perceptions
  on one object, with a few other objects stored: p50/p95 when nothing changed since the last query, and right
  after a perception (the query then brings its graph up to date first);
* subsumption: `GET /states/{a}/subsumed-by/{b}` on random pairs of stored states, p50/p95;
* reasoning: `POST /reasoning` with Pellet and HermiT on a 20-link object's current ABox, the job's seconds.
"""
from __future__ import annotations

import random
import tempfile
import time
from pathlib import Path
from typing import Any

import httpx

from .service import _client, create_object, perceive, random_angles, running_service, set_goal, summary_ms

CURRENT_STATE_QUERY = """PREFIX planhrc: <http://planhrc.org/ontology/planhrc.owl#>
SELECT ?object ?joint ?degrees WHERE {
  { SELECT ?object (MAX(?t) AS ?latest) WHERE {
      ?s a planhrc:PerceivedState ; planhrc:stateOf ?object ; planhrc:createdAt ?t } GROUP BY ?object }
  ?state a planhrc:PerceivedState ; planhrc:stateOf ?object ; planhrc:createdAt ?latest ; planhrc:madeof ?p .
  ?p a planhrc:HasOrientation ; planhrc:arg1 ?joint ; planhrc:arg2 ?o . ?o planhrc:degrees ?degrees .
} ORDER BY ?object ?joint"""
OTHER_OBJECTS = 9


def _query(client: httpx.Client) -> float:
    t = time.perf_counter()
    r = client.post("/sparql", data={"query": CURRENT_STATE_QUERY},
                    headers={"Accept": "application/sparql-results+json"})
    seconds = time.perf_counter() - t
    r.raise_for_status()
    if not r.json()["results"]["bindings"]:
        raise RuntimeError("the current-state query answered no rows")
    return seconds


def _reason(client: httpx.Client, reasoner: str, object_id: str) -> dict[str, Any]:
    t = time.perf_counter()
    r = client.post("/reasoning", json={"reasoner": reasoner, "object_id": object_id})
    r.raise_for_status()
    job = r.json()
    while job["status"] in ("queued", "running"):
        time.sleep(0.1)
        job = client.get(f"/reasoning/{job['id']}").json()
    if job["status"] != "done":
        raise RuntimeError(f"reasoning with {reasoner} failed: {job.get('error')}")
    return {"reasoner": reasoner, "seconds": job["seconds"], "wall_s": round(time.perf_counter() - t, 3),
            "inferred": job["inferred"], "consistent": job["consistent"]}


def bench_knowledge(perceptions: int, samples: int, links: int, orientations: int, seed: int) -> dict[str, Any]:
    rng = random.Random(seed)
    with tempfile.TemporaryDirectory(prefix="planhrc-knowledge-bench-") as tmp:
        with running_service(Path(tmp)) as server, _client(server, 300) as client:
            others = []
            for n in range(OTHER_OBJECTS):
                oid = create_object(client, links, orientations, "relative", f"other{n}")
                set_goal(client, oid, random_angles(rng, links, orientations))
                perceive(client, oid, random_angles(rng, links, orientations))
                others.append(oid)
            oid = create_object(client, links, orientations, "relative", "long history")
            set_goal(client, oid, random_angles(rng, links, orientations))
            for _ in range(perceptions):
                perceive(client, oid, random_angles(rng, links, orientations))
            _query(client)  # the first query reads every object's current ABox
            quiet = [_query(client) for _ in range(samples)]
            after = []
            for _ in range(samples):
                perceive(client, oid, random_angles(rng, links, orientations))
                after.append(_query(client))
            states = [f"{o}_state_{k}" for o in [oid, *others] for k in (1, 2, 3)]
            states = [s for s in states if client.get(f"/states/{s}").status_code == 200]
            subsumption = []
            for _ in range(max(samples, 200)):
                a, b = rng.choice(states), rng.choice(states)
                t = time.perf_counter()
                client.get(f"/states/{a}/subsumed-by/{b}").raise_for_status()
                subsumption.append(time.perf_counter() - t)
            big = create_object(client, 20, 12, "relative", "twenty links")
            set_goal(client, big, random_angles(rng, 20, 12))
            perceive(client, big, random_angles(rng, 20, 12))
            reasoning = [_reason(client, name, big) for name in ("pellet", "hermit")]
    return {"perceptions": perceptions, "objects": OTHER_OBJECTS + 1, "links": links, "orientations": orientations,
            "sparql_current_state": summary_ms(quiet), "sparql_after_a_perception": summary_ms(after),
            "subsumption": summary_ms(subsumption), "reasoning_20_links": reasoning}


def knowledge_markdown(k: dict[str, Any]) -> list[str]:
    q, a, s = k["sparql_current_state"], k["sparql_after_a_perception"], k["subsumption"]
    lines = [f"Knowledge service after {k['perceptions']} perceptions on one object ({k['objects']} objects of "
             f"{k['links']} links x {k['orientations']} orientations stored):", "",
             "| measure | p50 | p95 | target |", "|---|---|---|---|",
             f"| SPARQL, current state of every object | {q['p50_ms']} ms | {q['p95_ms']} ms | p95 < 50 ms |",
             f"| the same right after a perception | {a['p50_ms']} ms | {a['p95_ms']} ms | |",
             f"| subsumption over HTTP | {s['p50_ms']} ms | {s['p95_ms']} ms | p95 < 5 ms |"]
    for r in k["reasoning_20_links"]:
        target = "< 3 s" if r["reasoner"] == "pellet" else ""
        lines.append(f"| {r['reasoner']} on a 20-link ABox (job; wall) | {r['seconds']} s | {r['wall_s']} s | "
                     f"{target} |")
    return lines + [""]
