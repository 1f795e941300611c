"""How the reasoners' JVMs are started: a short run's options, and an ahead-of-time cache of Pellet's classes
(JDK 25, JEP 483/514) made once, after a first job, and used by every later one.

A reasoning job is a short JVM: Pellet loads Jena, the OWL API and itself (thousands of classes) for a few seconds
of work. The C1 compiler alone (`TieredStopAtLevel=1`) and the serial collector suit such a run; the AOT cache
holds those classes already loaded and linked. The cache is made by a run of its own (`make_cache`, on the job's
input), never by a job: a JVM that fails to write a cache fails its run. It is a file per reasoner, Java and class
path in the user's cache folder (`$XDG_CACHE_HOME/planhrc`, else `~/.cache/planhrc`); the JVM checks it against the
class path and runs without it if it no longer fits. HermiT's class path holds a folder, which an AOT cache cannot
cover: HermiT gets the short-run options only. No cache either when the folder cannot be made.
"""
from __future__ import annotations

import hashlib
import logging
import os
import subprocess
from pathlib import Path
from typing import Sequence

from planhrc.service_process import die_with_parent

log = logging.getLogger(__name__)

SHORT_RUN = ("-XX:TieredStopAtLevel=1", "-XX:+UseSerialGC")


def cache_file(reasoner: str, java: str, classpath: str, folder: Path | None) -> Path | None:
    """Where the AOT cache of `reasoner` on this Java and class path lives; None when it cannot have one."""
    entries = classpath.split(os.pathsep)
    if folder is None or not all(entry.endswith(".jar") and os.path.isfile(entry) for entry in entries):
        return None
    stamps = []
    for path in [java, *entries]:  # a new JDK or reasoner makes a new cache
        st = os.stat(path)
        stamps.append(f"{path}:{st.st_size}:{st.st_mtime_ns}")
    key = hashlib.sha256("\0".join([reasoner, *stamps]).encode()).hexdigest()
    return folder / f"{reasoner}-{key[:16]}.aot"


def java_options(cache: Path | None) -> tuple[str, ...]:
    """The options of a reasoner's run: the short-run ones, and the AOT cache's when it has been made."""
    if cache is not None and cache.is_file():
        return (*SHORT_RUN, f"-XX:AOTCache={cache}")
    return SHORT_RUN


def make_cache(cache: Path, command: Sequence[str], timeout_s: float) -> bool:
    """Make the AOT cache by running `command` (`java OPTIONS... -cp ... MAIN ARGS...`, a run like a job's) with
    the option that writes it at exit; True when it was made. Written beside and renamed, so a run that reads the
    cache never sees half of it."""
    part = cache.with_suffix(f".{os.getpid()}.part")
    run = [command[0], *SHORT_RUN, f"-XX:AOTCacheOutput={part}", *command[1:]]
    try:
        subprocess.run(run, capture_output=True, timeout=timeout_s, check=True, preexec_fn=die_with_parent)
        os.replace(part, cache)
    except (OSError, subprocess.SubprocessError) as exc:
        log.warning("reasoning: no class cache for %s (%s)", cache.name, type(exc).__name__)
        return False
    finally:
        for leftover in (part, Path(f"{part}.config")):
            leftover.unlink(missing_ok=True)
    log.info("reasoning: class cache made: %s", cache)
    return True
