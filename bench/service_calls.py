"""What the service benches share: a `planhrc serve` on a fresh store with the benches' token, and the requests
a robot makes of it (objects, goals, perceptions, the next action and its feedback), timed, with the server's CPU
and memory read from /proc (Linux)."""
from __future__ import annotations

import os
import random
import time
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

import httpx

from planhrc.service_process import RunningService as Server
from planhrc.service_process import running_service as start_service
from planhrc.stats import percentile
from planhrc.vocabulary import DecisionKind

TOKEN = "service-bench-token"


def rss_mb(pid: int) -> float:
    """Resident set size of a process in MiB (Linux /proc)."""
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    except OSError:
        pass
    return float("nan")


def cpu_seconds(pid: int) -> float:
    """CPU time (user + system) a process has used, in seconds (Linux /proc): what a request costs the server,
    whatever else the machine runs."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    except (OSError, IndexError, ValueError):
        return float("nan")


def replanning_with_cpu(client: httpx.Client, server: Server, object_id: str, links: int, orientations: int,
                         count: int, rng: random.Random, acting: bool = False) -> tuple[list[float], float]:
    """`replanning_latencies`, and the server's CPU milliseconds per perception posted meanwhile (with `acting`,
    the robot's calls between two perceptions included)."""
    before = cpu_seconds(server.pid)
    lat = replanning_latencies(client, object_id, links, orientations, count, rng, acting=acting)
    return lat, round((cpu_seconds(server.pid) - before) / max(count, 1) * 1000, 2)


@contextmanager
def running_service(workdir: Path, extra_env: dict[str, str] | None = None) -> Iterator[Server]:
    """`planhrc serve` on a fresh store in `workdir` with the bench's token (`planhrc.service_process`)."""
    with start_service(workdir / "kb.sqlite3", args=("--log-level", "warning"), clean_env=True, cwd=workdir,
                       env={"PLANHRC_TOKEN": TOKEN, **(extra_env or {})}) as server:
        yield server


def client_of(server: Server, timeout: float) -> httpx.Client:
    return httpx.Client(base_url=server.url, timeout=timeout, headers={"Authorization": f"Bearer {TOKEN}"})


def create_object(client: httpx.Client, links: int, orientations: int, formulation: str, name: str) -> str:
    r = client.post("/objects", json={"name": name, "links": links, "orientations": orientations,
                                      "formulation": formulation})
    r.raise_for_status()
    return str(r.json()["id"])


def random_angles(rng: random.Random, links: int, orientations: int) -> list[float]:
    step = 360 // orientations
    return [float(rng.randrange(orientations) * step) for _ in range(links)]


def set_goal(client: httpx.Client, object_id: str, angles: list[float]) -> None:
    client.put(f"/objects/{object_id}/goal", json={"link_orientations_deg": angles}).raise_for_status()


def perceive(client: httpx.Client, object_id: str, angles: list[float]) -> tuple[float, str]:
    """Post one perception; the wall time and the decision."""
    t = time.perf_counter()
    r = client.post(f"/objects/{object_id}/perceptions", json={"link_orientations_deg": angles})
    seconds = time.perf_counter() - t
    r.raise_for_status()
    return seconds, str(r.json()["decision"])


def act(client: httpx.Client, object_id: str) -> None:
    """The robot's part between two perceptions: take the next action, if there is one, and report it done."""
    r = client.post(f"/objects/{object_id}/actions/next")
    r.raise_for_status()
    action = r.json()
    if action:
        client.post(f"/objects/{object_id}/actions/{action['id']}/feedback",
                    json={"outcome": "succeeded"}).raise_for_status()


def replanning_latencies(client: httpx.Client, object_id: str, links: int, orientations: int, count: int,
                         rng: random.Random, pause_s: float = 0.0, acting: bool = False) -> list[float]:
    """Seconds of the perceptions, of `count` random configurations far from the plan, that forced a new plan,
    `pause_s` apart (0: back to back). With `acting` the robot executes the next action before each perception
    (`act`): a bimanual plan begins with grasps, which no link orientation prevents, so without acting every
    perception lets the plan go on (the cooperation model's continue) and none re-plans."""
    out = []
    for _ in range(count):
        if pause_s:
            time.sleep(pause_s)
        if acting:
            act(client, object_id)
        seconds, decision = perceive(client, object_id, random_angles(rng, links, orientations))
        if decision == DecisionKind.REPLAN:
            out.append(seconds)
    return out


def summary_ms(values: list[float]) -> dict[str, float]:
    return {"n": len(values), "p50_ms": round(percentile(values, 0.5) * 1000, 2),
            "p95_ms": round(percentile(values, 0.95) * 1000, 2),
            "max_ms": round(max(values) * 1000, 2) if values else float("nan")}


@dataclass
class Side:
    """One service of the side-by-side part and what was measured on it."""

    server: Server
    client: httpx.Client
    object_id: str
    history: int
    latencies: list[float]
    cpu_s: float = 0.0
    posted: int = 0
