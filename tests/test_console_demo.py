"""`planhrc demo` points a person at the console: it prints the console's address while it runs, and with
`--keep-serving` the service (and its page) stays up after the episode until Ctrl-C."""
from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import httpx
import pytest

REPO = Path(__file__).resolve().parent.parent

pytestmark = [pytest.mark.sim, pytest.mark.integration, pytest.mark.slow]


def test_demo_prints_the_console_and_keeps_serving_until_interrupted(tmp_path):
    env = {k: v for k, v in os.environ.items() if not k.startswith("PLANHRC_")}
    env["PYTHONPATH"] = str(REPO) + os.pathsep + env.get("PYTHONPATH", "")
    cmd = [sys.executable, "-u", "-m", "planhrc.cli", "demo", "--scenario", "paper-3-4", "--perception", "fallback",
           "--out", str(tmp_path / "out"), "--keep-serving"]
    proc = subprocess.Popen(cmd, cwd=tmp_path, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    lines: list[str] = []
    try:
        deadline = time.monotonic() + 240
        while not any("stays up" in line for line in lines):
            line = proc.stdout.readline()
            if not line:
                raise AssertionError("demo ended before it said the service stays up:\n" + "".join(lines))
            lines.append(line)
            assert time.monotonic() < deadline, "".join(lines)
        text = "".join(lines)
        console = re.search(r"\[demo\] console: (http://127\.0\.0\.1:\d+)/ ", text)
        watch = re.search(r"\[demo\] watch paper-3-4 live: (http://\S+/\?object=(\w+))", text)
        assert console and watch, text
        assert watch.group(1).startswith(console.group(1))
        assert "goal reached" in text
        # the episode is over and the page still answers, with the object at its goal
        page = httpx.get(console.group(1) + "/", timeout=10)
        assert page.status_code == 200 and "planHRC cell console" in page.text
        obj = httpx.get(f"{console.group(1)}/objects/{watch.group(2)}", timeout=10).json()
        assert obj["execution"]["status"] == "goal_reached"
        assert (tmp_path / "out" / "summary.json").exists()  # written before waiting
        proc.send_signal(signal.SIGINT)
        assert proc.wait(timeout=30) == 0
        with pytest.raises(httpx.TransportError):
            httpx.get(console.group(1) + "/health", timeout=2)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
