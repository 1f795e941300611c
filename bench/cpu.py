"""The CPU a re-plan costs, whole: the service's CPU per re-plan beside a planner's whole process.

`measure_service_cpu` starts a real `planhrc serve`, posts re-planning perceptions paced as a robot's (each
`ROBOT_PAUSE_S` after the last answer has settled) and reads the server's CPU around each perception and the work
behind its answer: its threads' run time to the nanosecond (`/proc/<pid>/task/*/schedstat`; /proc's own count, in
clock ticks, for a window in which a thread ended), its reaped children's (VAL's processes) and its live
descendants' (the planning pool's workers, where an absolute task is planned and replayed, and VAL's fork server
with the runs it reaped, or the VAL processes armed for the next plan: they are not reaped while the service runs;
VAL's are told from the others by their command name). So everything a re-plan costs is in its
window: the request, its VAL runs, the work behind the answer (the plan's later pieces under VAL, the next VAL
armed, anything the store writes after the commit). After each answer the bench waits until that work is done:
every later piece of the plan has its `val_verdict` event and the store writes nothing more (`/health`'s
`plans_to_write` holds still from one probe to the next). Those probes cost the server CPU of their own; it is
measured on the idle service with the probes spaced as the wait spaces them (a request after a pause costs the
server about twice one right after another) and taken off (`probe_ms`). A random perception now and then lets the
plan go on instead (the cooperation model's `continue`): its window is reported apart (`other_ms`), not shared
out among the re-plans. What the idle service spends per second (`idle_ms_per_s`, its threads' time-outs) is
measured apart too, and stays in the figures: it is what the service costs while it re-plans.

`measure_process_cpu` is the anchor measured in the same run: a planner's whole process (driver, translator,
search, plan file) on a random task of the same size, its CPU read from this process's reaped children. Madagascar
is the issue's anchor; it is used when it is configured (`PLANHRC_MADAGASCAR`), Fast Downward LAMA otherwise.
"""
from __future__ import annotations

import os
import random
import resource
import tempfile
import time
from pathlib import Path
from typing import Any, Mapping

import httpx

from planhrc.event_log import DecisionData, ValVerdictData, data_of
from planhrc.planner.registry import available_planners, get_planner
from planhrc.stats import percentile
from planhrc.translator.domain import get_domain
from planhrc.translator.problem import get_problem
from planhrc.paths import default_tbox_path
from planhrc.model import make_object

ROBOT_PAUSE_S = 0.25  # as `grid.ROBOT_PAUSE_S`: a robot's next perception follows its action
SETTLE_POLL_S = 0.05
SETTLE_LIMIT_S = 60.0
ANCHORS = ("madagascar", "fd-lama")  # the anchor planners, in order of preference
VAL_COMMAND = "Validate"  # VAL's processes, by their command name


def process_cpu_s(pid: int) -> tuple[float, float]:
    """(own user + system, reaped children's user + system) seconds of a process (Linux /proc)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    tick = os.sysconf("SC_CLK_TCK")
    return (int(fields[11]) + int(fields[12])) / tick, (int(fields[13]) + int(fields[14])) / tick


def _total(cpu: tuple[float, float]) -> float:
    return cpu[0] + cpu[1]


def live_descendants_cpu_s(pid: int) -> float:
    """User + system seconds (with their reaped children's) of a process's descendants still running (Linux /proc);
    one that ends while it is read is left out."""
    return sum(live_children_cpu_s(pid).values())


def live_children_cpu_s(pid: int) -> dict[str, float]:
    """`live_descendants_cpu_s` by the name of the process's child each descendant descends from (its command
    name, /proc's `comm`: `Validate` for VAL's fork server and armed processes, `python` for planning workers)."""
    found: dict[str, float] = {}
    for child in _children(pid):
        try:
            name = Path(f"/proc/{child}/comm").read_text().strip()
            cpu = _total(process_cpu_s(child)) + live_descendants_cpu_s(child)
        except (OSError, IndexError, ValueError):  # gone meanwhile
            continue
        found[name] = found.get(name, 0.0) + cpu
    return found


def _children(pid: int) -> list[int]:
    found: list[int] = []
    try:
        tasks = list(Path(f"/proc/{pid}/task").iterdir())
    except OSError:
        return found
    for task in tasks:
        try:
            found.extend(int(c) for c in (task / "children").read_text().split())
        except OSError:
            continue
    return found


def measure_service_cpu(formulation: str, links: int = 20, orientations: int = 12, runs: int = 20, seed: int = 7,
                        env: Mapping[str, str] | None = None, pause_s: float = ROBOT_PAUSE_S) -> dict[str, Any]:
    """The service's whole CPU per re-plan (see the module's note), in ms, read around each perception and the work
    behind its answer: `per_replan_ms` (own + children + live descendants, the settle probes taken off, averaged
    over the perceptions that re-planned), `own_ms`, `val_children_ms` (VAL's processes: those that ended, VAL's
    fork server and its runs, the armed ones) and `descendants_ms` (the planning workers) of those, and the
    answers' latency. A random perception now and then lets the plan go on (`decisions`): its CPU is reported apart
    (`other_ms`), and `per_perception_ms` averages every perception."""
    from planhrc.bench.service_calls import TOKEN, create_object, random_angles, running_service, set_goal

    rng = random.Random(seed)
    with tempfile.TemporaryDirectory(prefix="planhrc-bench-cpu-") as tmp, \
            running_service(Path(tmp), dict(env or {})) as server, \
            httpx.Client(base_url=server.url, timeout=120, headers={"Authorization": f"Bearer {TOKEN}"}) as client:
        ident = create_object(client, links, orientations, formulation, f"cpu-{formulation}")
        set_goal(client, ident, random_angles(rng, links, orientations))
        settle = Settle(client, ident)
        for _ in range(3):  # the first re-plan grounds the task and arms VAL for its domain
            _replan(client, ident, random_angles(rng, links, orientations))
            settle.wait()
        time.sleep(pause_s)
        settle.wait()
        probe_s = _probe_cost(settle, server.pid)
        idle_s = _idle_rate(server.pid)
        latencies: list[float] = []
        decisions: dict[str, int] = {}
        spent: dict[str, list[tuple[float, float, float]]] = {}  # decision -> (own, VAL, other live) per perception
        probes = 0
        mark = _Reading(server.pid)
        for _ in range(runs):
            seconds, answer = _replan(client, ident, random_angles(rng, links, orientations))
            decisions[answer["decision"]] = decisions.get(answer["decision"], 0) + 1
            latencies.append(seconds)
            time.sleep(pause_s)
            count = settle.wait()
            probes += count
            now = _Reading(server.pid)
            own, val, live = now.since(mark)
            spent.setdefault(answer["decision"], []).append((own - count * probe_s, val, live))
            mark = now
    replans = spent.get("replan") or [(0.0, 0.0, 0.0)]
    others = [row for kind, rows in spent.items() if kind != "replan" for row in rows]
    everything = [row for rows in spent.values() for row in rows]

    def mean_ms(rows: list[tuple[float, float, float]], *parts: int) -> float:
        return round(sum(sum(row[i] for i in parts) for row in rows) / max(1, len(rows)) * 1000, 2)

    return {"formulation": formulation, "links": links, "orientations": orientations, "runs": runs,
            "pause_s": pause_s, "decisions": decisions,
            "per_replan_ms": mean_ms(replans, 0, 1, 2), "own_ms": mean_ms(replans, 0),
            "val_children_ms": mean_ms(replans, 1), "descendants_ms": mean_ms(replans, 2),
            "other_ms": mean_ms(others, 0, 1, 2) if others else None,
            "per_perception_ms": mean_ms(everything, 0, 1, 2),
            "idle_ms_per_s": round(idle_s * 1000, 2), "idle_share_ms": round(idle_s * (pause_s + SETTLE_POLL_S) * 1000, 2),
            "probes": probes, "probe_ms": round(probe_s * 1000, 3),
            "latency_median_ms": round(percentile(latencies, 0.5) * 1000, 2)}


class _Reading:
    """A process's CPU at one moment: its threads' to the nanosecond, its own as /proc counts it (in clock ticks,
    with the threads that ended), its reaped children's and its live descendants' seconds."""

    def __init__(self, pid: int) -> None:
        self.threads = _threads_ns(pid)
        self.own, self.children = process_cpu_s(pid)
        live = live_children_cpu_s(pid)
        self.val = self.children + live.pop(VAL_COMMAND, 0.0)  # VAL's processes, reaped or (a fork server) not
        self.live = sum(live.values())

    def since(self, before: _Reading) -> tuple[float, float, float]:
        """(own, VAL, other live descendants) seconds from `before` to this reading; the own part from the threads'
        times while every thread of `before` still runs, else (a thread ended) as /proc counts it."""
        if set(before.threads) <= set(self.threads):
            own = sum(self.threads.values()) / 1e9 - sum(before.threads.values()) / 1e9
        else:
            own = self.own - before.own
        return own, self.val - before.val, self.live - before.live


def _replan(client: httpx.Client, ident: str, angles: list[float]) -> tuple[float, dict[str, Any]]:
    t = time.perf_counter()
    r = client.post(f"/objects/{ident}/perceptions", json={"link_orientations_deg": angles})
    seconds = time.perf_counter() - t
    r.raise_for_status()
    return seconds, dict(r.json())


class Settle:
    """Waits until the work behind an object's last answer is done: every later piece of its latest plan has its
    verdict in the object's log (read from where it stopped), and the store's count of plans still to write
    (`/health`) stays the same from one probe to the next (its writer, if any, is done)."""

    def __init__(self, client: httpx.Client, ident: str) -> None:
        self.client = client
        self.ident = ident
        self.seq = 0
        self.plan_id: str | None = None
        self.pending = 0  # later pieces of `plan_id` without a verdict yet
        self.to_write: int | None = None  # `plans_to_write` at the last probe

    def done(self) -> bool:
        to_write, self.to_write = self.to_write, int(self.client.get("/health").json()["plans_to_write"])
        events = self.client.get(f"/objects/{self.ident}/events", params={"after_seq": self.seq}).json()
        for event in events:
            self.seq = int(event["seq"])
            record = data_of(event["kind"], event["data"])
            if isinstance(record, ValVerdictData):
                if record.plan_id == self.plan_id:
                    self.pending -= 1
            elif isinstance(record, DecisionData) and record.plan_id is not None and record.plan_id != self.plan_id:
                self.plan_id = record.plan_id
                self.pending = len(record.val_pieces) - len(record.val_accepted)
        return self.pending <= 0 and to_write == self.to_write

    def wait(self, limit_s: float = SETTLE_LIMIT_S) -> int:
        """Wait until `done`; how many probes that took."""
        self.to_write = None
        probes, end = 1, time.monotonic() + limit_s
        while not self.done():
            if time.monotonic() > end:
                raise TimeoutError(f"the service did not settle within {limit_s:g} s")
            time.sleep(SETTLE_POLL_S)
            probes += 1
        return probes


def _probe_cost(settle: Settle, pid: int, count: int = 60) -> float:
    """The server's CPU seconds for one settle probe, on the idle service, the probes spaced as `Settle.wait` spaces
    them (a request after a pause costs the server more than one right after another), the CPU read to the
    nanosecond from its threads' scheduler statistics."""
    before = threads_cpu_s(pid)
    for _ in range(count):
        time.sleep(SETTLE_POLL_S)
        settle.done()
    return max(0.0, (threads_cpu_s(pid) - before) / count)


def threads_cpu_s(pid: int) -> float:
    """The CPU seconds a process's threads have run (Linux `/proc/<pid>/task/*/schedstat`, nanoseconds; a thread
    that ended is no longer counted, so only differences over a time when its threads stay are meaningful)."""
    return sum(_threads_ns(pid).values()) / 1e9


def _threads_ns(pid: int) -> dict[str, int]:
    """Each live thread's run time in nanoseconds, by thread id."""
    found: dict[str, int] = {}
    for task in Path(f"/proc/{pid}/task").iterdir():
        try:
            found[task.name] = int((task / "schedstat").read_text().split()[0])
        except (OSError, IndexError, ValueError):
            continue
    return found


def _idle_rate(pid: int, seconds: float = 2.0) -> float:
    """The idle service's CPU seconds per second."""
    before = _total(process_cpu_s(pid))
    time.sleep(seconds)
    return max(0.0, (_total(process_cpu_s(pid)) - before) / seconds)


def measure_process_cpu(planner: str, formulation: str, links: int = 20, orientations: int = 12, runs: int = 5,
                        timeout_s: float = 10.0, seed: int = 7) -> dict[str, Any]:
    """A planner's whole process (every process it starts, reaped) on random tasks of this size: CPU ms per run,
    median; a run that hits `timeout_s` is reported and not repeated."""
    tbox = default_tbox_path()
    domain = get_domain(tbox, formulation)
    rng = random.Random(seed)
    obj = make_object("obj1", formulation, links, orientations)
    degs = obj.orientation_degrees
    solver = get_planner(planner)
    cpu_ms: list[float] = []
    for _ in range(runs):
        init = obj.configuration_atoms([rng.choice(degs) for _ in obj.joint_indices])
        goal = obj.configuration_atoms([rng.choice(degs) for _ in obj.joint_indices])
        problem = get_problem(obj, init, goal, "bench")
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        result = solver.solve(domain, problem, timeout_s)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        if not result.solved:
            return {"planner": planner, "formulation": formulation, "runs": len(cpu_ms) + 1,
                    "status": result.status.value, "note": f"no plan within {timeout_s:g} s; not repeated",
                    "cpu_median_ms": round(percentile(cpu_ms, 0.5) * 1000, 2) if cpu_ms else None}
        cpu_ms.append((after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime))
    return {"planner": planner, "formulation": formulation, "runs": len(cpu_ms), "status": "solved",
            "cpu_median_ms": round(percentile(cpu_ms, 0.5) * 1000, 2)}


def anchor_planner() -> str | None:
    """The anchor measured beside the service: Madagascar where it is configured, else Fast Downward LAMA."""
    usable = set(available_planners())
    return next((name for name in ANCHORS if name in usable), None)


def cpu_row(formulation: str, runs: int, anchor_runs: int = 5, anchor_timeout_s: float = 10.0) -> dict[str, Any]:
    """The CPU column of the re-planning table for one formulation: the service's whole CPU per re-plan, the
    anchor's whole process measured right after it in the same run, and their ratio."""
    row: dict[str, Any] = {"service": measure_service_cpu(formulation, runs=runs)}
    anchor = anchor_planner()
    if anchor is not None:
        row["anchor"] = measure_process_cpu(anchor, formulation, runs=anchor_runs, timeout_s=anchor_timeout_s)
        base = row["anchor"].get("cpu_median_ms")
        if base and row["anchor"]["status"] == "solved":
            row["ratio"] = round(row["service"]["per_replan_ms"] / base, 3)
    return row


def cpu_text(row: dict[str, Any] | None) -> str:
    """The table's cells: the service's CPU per re-plan (VAL's processes in it), and the anchor's whole process."""
    if row is None:
        return "- | - |"
    service = row["service"]
    text = f"{service['per_replan_ms']} (VAL {service['val_children_ms']}) | "
    anchor = row.get("anchor")
    if anchor is None:
        return text + "- |"
    if anchor["status"] != "solved":
        return text + f"{anchor['planner']}: {anchor['note']} |"
    return text + f"{anchor['planner']} {anchor['cpu_median_ms']}, ratio {row.get('ratio', '-')} |"
