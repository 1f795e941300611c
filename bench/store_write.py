"""What a re-planning perception's write costs on each store backend, side by side:
`python -m planhrc.bench.store_write --db postgresql://user@host:port/database [--links 20] [--orientations 12]`.

Per formulation, one random task on a links x orientations object is planned in process and replayed into the
plan's actions and expected states; each perception then writes, in one transaction, what the service writes for a
re-plan: the perceived state, the problem, the plan, two events, the execution cursor and the idempotent response.
Per backend it reports the medians of the transaction's wall time and of this process's CPU during it (every
thread), and of what follows it: the store's writer writing the plan's triples behind the answer (`settle`), and the
mean CPU of the PostgreSQL server process serving the connection in either (read from /proc: a server on this
machine). Prints one JSON object, times in milliseconds. The PostgreSQL database should be empty (a fresh one).
"""
from __future__ import annotations

import argparse
import json
import os
import random
import statistics
import tempfile
import time
from pathlib import Path
from typing import Any, Callable, Sequence

from planhrc.kb_service.store import KnowledgeStore, open_store
from planhrc.kb_service.store.records import Execution
from planhrc.model import ArticulatedObject, Formulation, Perception, State, make_object, perceive
from planhrc.paths import default_tbox_path
from planhrc.planner.inproc import InprocPlanner
from planhrc.transition import replay
from planhrc.translator.domain import get_domain, read_domain_model
from planhrc.translator.problem import get_problem
from planhrc.vocabulary import ExecutionStatus


def make_task(formulation: Formulation, links: int, orientations: int, seed: int
              ) -> tuple[ArticulatedObject, Perception, State, tuple[Any, ...], Sequence[State]]:
    """An object, a perception of a random configuration, a random goal, and the plan's actions and states."""
    obj = make_object("obj1", formulation, links, orientations)
    rng = random.Random(seed)
    links_deg = [float(rng.choice(obj.orientation_degrees)) for _ in range(obj.n_links)]
    perception = perceive(obj, links_deg, "link_orientations_deg")
    goal = obj.configuration_atoms([rng.choice(obj.orientation_degrees) for _ in obj.joint_indices])
    domain = get_domain(default_tbox_path(), formulation.value)
    plan = InprocPlanner().solve(domain, get_problem(obj, perception.atoms, goal, "bench"), 60.0).plan
    actions, states = replay(read_domain_model(default_tbox_path(), formulation.value), perception.atoms, plan)
    return obj, perception, frozenset(goal), actions, states


def server_cpu_s(kb: KnowledgeStore) -> Callable[[], float]:
    """CPU seconds so far of the PostgreSQL server process behind the store's connection (0 when unknown)."""
    session = getattr(kb, "_session", None)
    if session is None:
        return lambda: 0.0
    row = session.execute("SELECT pg_backend_pid()").fetchone()
    stat = Path(f"/proc/{row[0]}/stat")
    tick = os.sysconf("SC_CLK_TCK")

    def read() -> float:
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            return 0.0
        return (int(fields[11]) + int(fields[12])) / tick  # utime, stime

    return read


def measure(kb: KnowledgeStore, formulation: Formulation, links: int, orientations: int, perceptions: int,
            seed: int) -> dict[str, float]:
    obj, perception, goal, actions, states = make_task(formulation, links, orientations, seed)
    kb.create_object(obj)
    goal_state = kb.add_state(obj.ident, "goal", goal)
    server = server_cpu_s(kb)
    wall, cpu, behind, served, served_behind = [], [], [], [], []
    for k in range(perceptions + 1):  # the first one warms the caches and is not counted
        t0, c0, s0 = time.perf_counter(), time.process_time(), server()
        with kb.transaction():
            state = kb.add_perception(perception)
            problem = kb.add_problem(obj.ident, state.id, goal_state.id)
            plan = kb.add_plan(problem.id, "inproc", actions, states)
            kb.add_event(obj.ident, "perception", "", {"perceived_state_id": state.id})
            kb.add_event(obj.ident, "replan", "", {"plan_id": plan.id, "perceived_state_id": state.id})
            kb.set_execution(obj.ident, Execution(plan.id, 1, ExecutionStatus.READY))
            kb.remember_response(obj.ident, f"key-{k}", {"plan_id": plan.id})
        t1, c1, s1 = time.perf_counter(), time.process_time(), server()
        kb.settle()  # the plan's triples, written behind the answer
        c2, s2 = time.process_time(), server()
        if k:
            wall.append(t1 - t0)
            cpu.append(c1 - c0)
            behind.append(c2 - c1)
            served.append(s1 - s0)
            served_behind.append(s2 - s1)
    ms = {name: round(statistics.median(values) * 1000, 2)
          for name, values in (("answer_wall_ms", wall), ("answer_cpu_ms", cpu), ("write_behind_cpu_ms", behind))}
    # means: /proc counts in clock ticks
    ms["answer_server_cpu_ms"] = round(statistics.mean(served) * 1000, 2)
    ms["write_behind_server_cpu_ms"] = round(statistics.mean(served_behind) * 1000, 2)
    return {"plan_steps": len(actions), **ms, "total_cpu_ms": round(sum(ms[k] for k in ms if "cpu" in k), 2)}


def run(db: str, links: int = 20, orientations: int = 12, perceptions: int = 20, seed: int = 7) -> dict[str, Any]:
    out: dict[str, Any] = {"links": links, "orientations": orientations, "perceptions": perceptions}
    with tempfile.TemporaryDirectory() as folder:
        for name, location in (("sqlite", str(Path(folder) / "kb.sqlite3")), ("postgresql", db)):
            out[name] = {}
            for formulation in Formulation:
                with open_store(location, default_tbox_path()) as kb:
                    if kb.object_count():
                        raise SystemExit(f"--db: {name} store at {location} is not empty")
                    out[name][formulation.value] = measure(kb, formulation, links, orientations, perceptions, seed)
                if name == "sqlite":
                    os.remove(location)
                else:
                    _empty(location)
    return out


def _empty(db: str) -> None:
    """Drop the store's tables (the next formulation starts from an empty database)."""
    import psycopg
    from psycopg import sql

    with psycopg.connect(db, autocommit=True) as conn:
        for table in ("planhrc_triple", "planhrc_counter", "planhrc_event", "planhrc_execution", "planhrc_response",
                      "planhrc_meta"):
            conn.execute(sql.SQL("DROP TABLE IF EXISTS {}").format(sql.Identifier(table)))


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m planhrc.bench.store_write", description=__doc__.splitlines()[0])
    parser.add_argument("--db", required=True, help="an empty PostgreSQL database: postgresql://user@host:port/db")
    parser.add_argument("--links", type=int, default=20)
    parser.add_argument("--orientations", type=int, default=12)
    parser.add_argument("--perceptions", type=int, default=20)
    parser.add_argument("--seed", type=int, default=7)
    args = parser.parse_args(argv)
    print(json.dumps(run(args.db, args.links, args.orientations, args.perceptions, args.seed), indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
