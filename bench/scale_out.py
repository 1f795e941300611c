"""`planhrc service-bench --parts scale-out --db postgresql://...`: perceptions per second, latency and CPU per
perception of one `planhrc serve` on SQLite against 1, 2 and 4 replicas on one PostgreSQL database, in one run
(not a test).

For each configuration (a backend, a number of replicas, a number of objects, a routing) the part starts the
services on a fresh store, creates the objects (`links` x `orientations`, each with a goal and a first perception),
then runs `clients` closed-loop clients for `seconds`: each posts a perception of a random configuration of one of
its objects (nearly always a re-plan), and posts the next once answered. Two routings of several replicas: `turns`
sends each request to the next replica (a round-robin load balancer: an object's requests land on every replica,
each reading what the others wrote), `object` sends each object's requests to one replica (a balancer that hashes
the object's id: each replica's caches of its objects stay warm). It reports the perceptions
answered per second, their p50/p95 latency, the answers that were not 200, and the CPU per perception: the services'
processes (with the VAL and planner processes they ran) and, on PostgreSQL, the server's processes serving the
database's connections (read from /proc: a server on this machine). The PostgreSQL database is emptied before each
configuration: give one the bench may fill (`--db`).

What it can show depends on the machine: replicas add processes, not cores. On a machine with fewer cores than
replicas (and clients, and the database server) the throughput of 4 replicas is bounded by the cores, and the
figure that carries over to a larger machine is the CPU per perception (what a perception costs whichever process
does the work) and how it changes with the number of replicas (the cost of sharing one database).
"""
from __future__ import annotations

import os
import random
import tempfile
import threading
import time
from contextlib import ExitStack
from pathlib import Path
from typing import Any, Callable

import httpx

from planhrc.service_process import RunningService
from planhrc.service_process import running_service as start_service
from planhrc.stats import percentile

from .errors import BenchError
from .service_calls import TOKEN, client_of, create_object, random_angles, set_goal


def process_cpu_s(pid: int) -> float:
    """CPU seconds of a process and of the children it has waited for (VAL, planners): utime, stime, cutime,
    cstime (Linux /proc); 0 when it is gone."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        return sum(int(f) for f in fields[11:15]) / os.sysconf("SC_CLK_TCK")
    except (OSError, IndexError, ValueError):
        return 0.0


def _database_backends(db: str) -> Callable[[], dict[int, float]]:
    """CPU seconds so far of each server process serving a connection to `db` (its processes on this machine)."""
    import psycopg

    def read() -> dict[int, float]:
        with psycopg.connect(db, autocommit=True) as conn:
            pids = [int(r[0]) for r in conn.execute(
                "SELECT pid FROM pg_stat_activity WHERE datname = current_database() AND pid <> pg_backend_pid()")]
        return {pid: process_cpu_s(pid) for pid in pids}

    return read


def _no_server() -> dict[int, float]:
    return {}  # SQLite: the store is in the service's process


def empty_database(db: str) -> None:
    """Drop the store's tables: the next configuration starts from an empty database."""
    import psycopg
    from psycopg import sql

    with psycopg.connect(db, autocommit=True) as conn:
        tables = [r[0] for r in conn.execute("SELECT tablename FROM pg_tables WHERE schemaname = current_schema() "
                                             "AND tablename LIKE 'planhrc\\_%'")]
        for table in tables:
            conn.execute(sql.SQL("DROP TABLE IF EXISTS {} CASCADE").format(sql.Identifier(table)))


ROUTINGS = ("turns", "object")


def _load(clients: list[httpx.Client], objects: list[str], n_clients: int, seconds: float, links: int,
          orientations: int, seed: int, routing: str) -> tuple[list[float], int]:
    """`n_clients` closed-loop clients for `seconds`, client i on objects i, i + n, ..., each request to the next
    replica (`turns`) or to its object's (`object`); the latencies of the 200 answers and the count of the
    others."""
    latencies: list[float] = []
    others = [0]
    guard = threading.Lock()
    end = time.monotonic() + seconds

    def run(i: int) -> None:
        rng = random.Random(seed + i)
        mine = objects[i::n_clients] or objects[i % len(objects):][:1]
        k = 0
        while time.monotonic() < end:
            oid = mine[k % len(mine)]
            client = clients[(i + k if routing == "turns" else objects.index(oid)) % len(clients)]
            k += 1
            t = time.perf_counter()
            try:
                r = client.post(f"/objects/{oid}/perceptions",
                                json={"link_orientations_deg": random_angles(rng, links, orientations)})
                ok = r.status_code == 200
            except httpx.HTTPError:
                ok = False
            with guard:
                if ok:
                    latencies.append(time.perf_counter() - t)
                else:
                    others[0] += 1

    threads = [threading.Thread(target=run, args=(i,)) for i in range(n_clients)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    return latencies, others[0]


def _configuration(db: str, backend: str, replicas: int, n_objects: int, n_clients: int, seconds: float,
                   links: int, orientations: int, seed: int, routing: str = "turns") -> dict[str, Any]:
    with ExitStack() as stack:
        folder = Path(stack.enter_context(tempfile.TemporaryDirectory(prefix="planhrc-scale-")))
        location = str(folder / "kb.sqlite3") if backend == "sqlite" else db
        if backend == "postgresql":
            empty_database(db)
        servers: list[RunningService] = [
            stack.enter_context(start_service(location, args=("--log-level", "warning"), clean_env=True, cwd=folder,
                                              env={"PLANHRC_TOKEN": TOKEN, "PLANHRC_COMPACT_EVERY_S": "0"}))
            for _ in range(replicas)]
        clients = [stack.enter_context(client_of(server, 120)) for server in servers]
        rng = random.Random(seed)
        objects = []
        for n in range(n_objects):
            client = clients[n % len(clients)]
            oid = create_object(client, links, orientations, "relative", f"cell{n}")
            set_goal(client, oid, random_angles(rng, links, orientations))
            client.post(f"/objects/{oid}/perceptions",
                        json={"link_orientations_deg": random_angles(rng, links, orientations)}).raise_for_status()
            objects.append(oid)
        server_cpu = _database_backends(db) if backend == "postgresql" else _no_server
        services_before = [process_cpu_s(s.pid) for s in servers]
        db_before = server_cpu()
        latencies, others = _load(clients, objects, n_clients, seconds, links, orientations, seed, routing)
        services = sum(process_cpu_s(s.pid) for s in servers) - sum(services_before)
        db_after = server_cpu()
        database = sum(cpu - db_before.get(pid, 0.0) for pid, cpu in db_after.items())
    n = len(latencies)
    return {"backend": backend, "replicas": replicas, "routing": routing if replicas > 1 else "-",
            "objects": n_objects, "clients": n_clients,
            "perceptions": n, "per_s": round(n / seconds, 2), "p50_ms": round(percentile(latencies, 0.5) * 1000, 1),
            "p95_ms": round(percentile(latencies, 0.95) * 1000, 1), "not_200": others,
            "service_cpu_ms": round(services / max(n, 1) * 1000, 2),
            "database_cpu_ms": round(database / max(n, 1) * 1000, 2),
            "cpu_ms": round((services + database) / max(n, 1) * 1000, 2)}


def bench_scale_out(db: str | None, replica_counts: list[int], object_counts: list[int], clients: int,
                    seconds: float, links: int, orientations: int, seed: int,
                    log: Callable[[str], None] = lambda line: None) -> dict[str, Any]:
    """Every configuration in turn: SQLite (one process), then PostgreSQL with each replica count, for each object
    count; rows as `_configuration` reports them, and the ratios the part is for."""
    if not db or not db.startswith(("postgresql://", "postgres://")):
        raise BenchError("--db: the scale-out part needs a PostgreSQL database it may fill "
                         "(postgresql://user@host:port/database)")
    try:
        import psycopg  # noqa: F401
    except ImportError as exc:
        raise BenchError(f"--db: a PostgreSQL store needs psycopg 3: pip install 'planhrc[postgresql]' ({exc})") \
            from None
    rows = []
    plan = [("sqlite", 1, "turns")] + [("postgresql", r, routing) for r in replica_counts
                                       for routing in (ROUTINGS if r > 1 else ROUTINGS[:1])]
    for n_objects in object_counts:
        for backend, replicas, routing in plan:
            row = _configuration(db, backend, replicas, n_objects, clients, seconds, links, orientations, seed,
                                 routing)
            rows.append(row)
            log(f"scale-out {backend} x{replicas} ({row['routing']}), {n_objects} objects: {row['per_s']}/s, "
                f"p95 {row['p95_ms']} ms, CPU {row['cpu_ms']} ms per perception")
    empty_database(db)
    return {"object": f"{links} x {orientations}, relative", "clients": clients, "seconds": seconds, "rows": rows,
            "ratios": ratios(rows)}


def ratios(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per object count: each configuration's throughput against one PostgreSQL replica, and its CPU per perception
    against SQLite's."""
    out = []
    for n_objects in sorted({r["objects"] for r in rows}):
        group = [r for r in rows if r["objects"] == n_objects]
        sqlite = next(r for r in group if r["backend"] == "sqlite")
        single = next((r for r in group if r["backend"] == "postgresql" and r["replicas"] == 1), None)
        for r in group:
            out.append({"objects": n_objects, "backend": r["backend"], "replicas": r["replicas"],
                        "routing": r["routing"],
                        "throughput_vs_1_replica": round(r["per_s"] / single["per_s"], 2)
                        if single and single["per_s"] else None,
                        "cpu_vs_sqlite": round(r["cpu_ms"] / sqlite["cpu_ms"], 2) if sqlite["cpu_ms"] else None})
    return out


def scale_out_markdown(part: dict[str, Any]) -> list[str]:
    lines = [f"Scale-out: objects of {part['object']}, {part['clients']} closed-loop clients for {part['seconds']:g} s "
             "per configuration, perceptions of random configurations (re-plans); routing `turns`: each request to "
             "the next replica, `object`: each object's requests to one replica. *CPU* is "
             "per perception answered: the services' processes (with their VAL and planner processes) plus, on "
             "PostgreSQL, the server's processes serving the database.", "",
             "| objects | store | replicas | routing | perceptions/s | p50 | p95 | not 200 | CPU (service + "
             "database) | throughput vs 1 replica | CPU vs SQLite |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    ratio = {(r["objects"], r["backend"], r["replicas"], r["routing"]): r for r in part["ratios"]}
    for r in part["rows"]:
        q = ratio[(r["objects"], r["backend"], r["replicas"], r["routing"])]
        lines.append(f"| {r['objects']} | {r['backend']} | {r['replicas']} | {r['routing']} | {r['per_s']} "
                     f"| {r['p50_ms']} ms "
                     f"| {r['p95_ms']} ms | {r['not_200']} | {r['cpu_ms']} ms ({r['service_cpu_ms']} + "
                     f"{r['database_cpu_ms']}) | {q['throughput_vs_1_replica']} | {q['cpu_vs_sqlite']} |")
    return lines + [""]
