"""`planhrc service-bench --parts knowledge`: the knowledge service of a `planhrc serve` with a long history,
measured over HTTP (not a test).

* SPARQL: the current state of every object (the query the console offers first) after `perceptions` perceptions
  on one object, with a few other objects stored, by each engine (`PLANHRC_SPARQL_ENGINE`): two services on the one
  store, Oxigraph's (the default) and rdflib's (the earlier engine), asked in turn (`PAUSE_S` apart), so that the
  machine's load falls on both alike, with each service's CPU time per query (its query process's included); then right after a perception (the query first brings its graph up to date), Oxigraph's
  service first, then rdflib's alone (a store has one writer);
* subsumption: `GET /states/{a}/subsumed-by/{b}` on random pairs of stored states, in turn with `GET /health`
  (the floor: a route that reads two counters);
* reasoning: `POST /reasoning` on a 20-link object: Pellet with the default scope (`states`) on a fresh class
  cache (the first job, which then makes the cache) and after, Pellet over the whole current ABox, HermiT; beside
  them, in the same run, the time Java takes to start (`java -version`) and to start Pellet (`pellet help`: the
  JVM and Pellet's classes, with a job's options).
"""
from __future__ import annotations

import os
import random
import subprocess
import tempfile
import time
from contextlib import ExitStack
from pathlib import Path
from typing import Any

import httpx

from planhrc.service_process import settled_health

from .service_calls import (client_of, cpu_seconds, create_object, perceive, random_angles, running_service,
                            set_goal, summary_ms)

CURRENT_STATE_QUERY = """PREFIX planhrc: <http://planhrc.org/ontology/planhrc.owl#>
SELECT ?object ?joint ?degrees WHERE {
  { SELECT ?object (MAX(?t) AS ?latest) WHERE {
      ?s a planhrc:PerceivedState ; planhrc:stateOf ?object ; planhrc:createdAt ?t } GROUP BY ?object }
  ?state a planhrc:PerceivedState ; planhrc:stateOf ?object ; planhrc:createdAt ?latest ; planhrc:madeof ?p .
  ?p a planhrc:HasOrientation ; planhrc:arg1 ?joint ; planhrc:arg2 ?o . ?o planhrc:degrees ?degrees .
} ORDER BY ?object ?joint"""
OTHER_OBJECTS = 9
ENGINES = ("oxigraph", "rdflib")
WARM_PELLET_JOBS = 3
# between two queries asked in turn: the other service's work after its answer (rdflib's garbage, mostly) is over
# before the next query starts, as it would be on a machine that runs one of them
PAUSE_S = 0.05


def _query(client: httpx.Client) -> float:
    t = time.perf_counter()
    r = client.post("/sparql", data={"query": CURRENT_STATE_QUERY},
                    headers={"Accept": "application/sparql-results+json"})
    seconds = time.perf_counter() - t
    r.raise_for_status()
    if not r.json()["results"]["bindings"]:
        raise RuntimeError("the current-state query answered no rows")
    return seconds


def _tree_cpu(pid: int) -> float:
    """CPU seconds (user + system) of a service and its live child processes (the query process, the planning
    workers), and of the children it has waited for (a reasoner's JVM): what its work cost, whatever else the
    machine runs (Linux /proc)."""
    total = cpu_seconds(pid)
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        total += (int(fields[13]) + int(fields[14])) / os.sysconf("SC_CLK_TCK")
        for task in Path(f"/proc/{pid}/task").iterdir():
            for child in (task / "children").read_text().split():
                total += cpu_seconds(int(child))
    except (OSError, IndexError, ValueError):
        return float("nan")
    return total


def _timed_get(client: httpx.Client, path: str) -> float:
    t = time.perf_counter()
    client.get(path).raise_for_status()
    return time.perf_counter() - t


def _reason(client: httpx.Client, pid: int, reasoner: str, object_id: str, scope: str) -> dict[str, Any]:
    cpu = _tree_cpu(pid)
    t = time.perf_counter()
    r = client.post("/reasoning", json={"reasoner": reasoner, "object_id": object_id, "scope": scope})
    r.raise_for_status()
    job = r.json()
    while job["status"] in ("queued", "running"):
        time.sleep(0.05)
        job = client.get(f"/reasoning/{job['id']}").json()
    if job["status"] != "done":
        raise RuntimeError(f"reasoning with {reasoner} failed: {job.get('error')}")
    return {"reasoner": reasoner, "scope": scope, "seconds": job["seconds"], "wall_s": round(time.perf_counter() - t, 3),
            "cpu_s": round(_tree_cpu(pid) - cpu, 3), "inferred": job["inferred"], "consistent": job["consistent"],
            "notes": job["notes"]}


def _java_start(cache_home: Path) -> dict[str, float]:
    """Seconds to start Java, and Java with Pellet's classes (`pellet help`, a job's options and class cache)."""
    import os

    import owlready2

    from planhrc.kb_service.knowledge.jvm import cache_file, java_options
    from planhrc.kb_service.reasoner import _configure_java
    from planhrc.kb_service.store.owl import pellet_command

    _configure_java()
    java = str(owlready2.JAVA_EXE)
    classpath = str(owlready2.reasoning._PELLET_CLASSPATH)
    cache = cache_file("pellet", java, classpath, cache_home / "planhrc")
    env = {**os.environ, "XDG_CACHE_HOME": str(cache_home)}
    out = {}
    for name, command in (("java_version_s", [java, "-version"]),
                          ("pellet_start_s", [java, *java_options(cache), *pellet_command(java)[1:], "help"])):
        t = time.perf_counter()
        subprocess.run(command, capture_output=True, env=env, timeout=120, check=True)
        out[name] = round(time.perf_counter() - t, 3)
    return out


def bench_knowledge(perceptions: int, samples: int, links: int, orientations: int, seed: int) -> dict[str, Any]:
    rng = random.Random(seed)
    with tempfile.TemporaryDirectory(prefix="planhrc-knowledge-bench-") as tmp:
        work = Path(tmp)
        cache_home = work / "cache"  # a fresh class cache: the first Pellet job is a cold one
        env = {"XDG_CACHE_HOME": str(cache_home)}
        quiet: dict[str, list[float]] = {name: [] for name in ENGINES}
        after: dict[str, list[float]] = {}
        with ExitStack() as stack:
            server = stack.enter_context(running_service(work, {**env, "PLANHRC_SPARQL_ENGINE": "oxigraph"}))
            client = stack.enter_context(client_of(server, 300))
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
            settled_health(client, 120)  # nothing written behind any more: the next service opens the store as is
            # the earlier engine's service on the same store, read-only: both asked in turn
            old = stack.enter_context(running_service(work, {**env, "PLANHRC_SPARQL_ENGINE": "rdflib"}))
            old_client = stack.enter_context(client_of(old, 300))
            clients = {"oxigraph": client, "rdflib": old_client}
            for c in clients.values():
                _query(c)  # the first query reads every object's current ABox
            pids = {"oxigraph": server.pid, "rdflib": old.pid}
            cpu = {name: 0.0 for name in ENGINES}
            for i in range(samples):
                for name in (ENGINES if i % 2 == 0 else ENGINES[::-1]):
                    time.sleep(PAUSE_S)
                    before = _tree_cpu(pids[name])
                    quiet[name].append(_query(clients[name]))
                    cpu[name] += _tree_cpu(pids[name]) - before
            stack.pop_all().close()  # both services stop; rdflib's answers after a perception come below
            with running_service(work, {**env, "PLANHRC_SPARQL_ENGINE": "oxigraph"}) as server, \
                    client_of(server, 300) as client:
                after["oxigraph"] = _after_perceptions(client, oid, samples, rng, links, orientations)
                states = [f"{o}_state_{k}" for o in [oid, *others] for k in (1, 2, 3)]
                states = [s for s in states if client.get(f"/states/{s}").status_code == 200]
                subsumption, health = [], []
                for _ in range(max(samples, 200)):
                    a, b = rng.choice(states), rng.choice(states)
                    subsumption.append(_timed_get(client, f"/states/{a}/subsumed-by/{b}"))
                    health.append(_timed_get(client, "/health"))
                big = create_object(client, 20, 12, "relative", "twenty links")
                set_goal(client, big, random_angles(rng, 20, 12))
                perceive(client, big, random_angles(rng, 20, 12))
                pid = server.pid
                reasoning = [_reason(client, pid, "pellet", big, "states")]  # cold: no class cache yet
                reasoning += [_reason(client, pid, "pellet", big, "states") for _ in range(WARM_PELLET_JOBS)]
                reasoning += [_reason(client, pid, "pellet", big, "current"),
                              _reason(client, pid, "hermit", big, "states")]
                java = _java_start(cache_home)
            with running_service(work, {**env, "PLANHRC_SPARQL_ENGINE": "rdflib"}) as server, \
                    client_of(server, 300) as client:
                _query(client)
                after["rdflib"] = _after_perceptions(client, oid, samples, rng, links, orientations)
    return {"perceptions": perceptions, "objects": OTHER_OBJECTS + 1, "links": links, "orientations": orientations,
            "sparql_current_state": {name: {**summary_ms(quiet[name]),
                                            "server_cpu_ms": round(cpu[name] / samples * 1000, 2)} for name in ENGINES},
            "sparql_after_a_perception": {name: summary_ms(after[name]) for name in ENGINES},
            "subsumption": summary_ms(subsumption), "health": summary_ms(health),
            "reasoning_20_links": reasoning, "java": java}


def _after_perceptions(client: httpx.Client, oid: str, samples: int, rng: random.Random, links: int,
                       orientations: int) -> list[float]:
    out = []
    for _ in range(samples):
        perceive(client, oid, random_angles(rng, links, orientations))
        out.append(_query(client))
    return out


def knowledge_markdown(k: dict[str, Any]) -> list[str]:
    q, a = k["sparql_current_state"], k["sparql_after_a_perception"]
    s, h = k["subsumption"], k["health"]
    lines = [f"Knowledge service after {k['perceptions']} perceptions on one object ({k['objects']} objects of "
             f"{k['links']} links x {k['orientations']} orientations stored):", "",
             "| measure | p50 | p95 | target |", "|---|---|---|---|"]
    for name in ENGINES:
        target = "p95 < 50 ms" if name == "oxigraph" else "(the earlier engine, asked in turn)"
        lines.append(f"| SPARQL, current state of every object ({name}; server CPU {q[name]['server_cpu_ms']} ms "
                     f"a query) | {q[name]['p50_ms']} ms | {q[name]['p95_ms']} ms | {target} |")
    for name in ENGINES:
        lines.append(f"| the same right after a perception ({name}) | {a[name]['p50_ms']} ms | {a[name]['p95_ms']} ms | |")
    lines += [f"| subsumption over HTTP | {s['p50_ms']} ms | {s['p95_ms']} ms | p95 < 5 ms |",
              f"| /health, in turn with it (the floor) | {h['p50_ms']} ms | {h['p95_ms']} ms | |", "",
              "Reasoning on a 20-link object (one job each; *seconds*: the job's own measure, *wall*: request to "
              "answer; *CPU*: the service's and its processes', the JVM's included):", "",
              "| reasoner | scope | class cache | seconds | wall | CPU | inferred | target |",
              "|---|---|---|---|---|---|---|---|"]
    for i, r in enumerate(k["reasoning_20_links"]):
        cache = "made after this job" if i == 0 else "used" if r["reasoner"] == "pellet" else "none (HermiT)"
        target = "< 3 s" if r["reasoner"] == "pellet" and r["scope"] == "states" else ""
        lines.append(f"| {r['reasoner']} | {r['scope']} | {cache} | {r['seconds']} s | {r['wall_s']} s | "
                     f"{r['cpu_s']} s | {r['inferred']} | {target} |")
    j = k["java"]
    lines += ["", f"In the same run: `java -version` {j['java_version_s']} s; Java with Pellet's classes "
              f"(`pellet help`, a job's options and class cache) {j['pellet_start_s']} s.", ""]
    return lines
