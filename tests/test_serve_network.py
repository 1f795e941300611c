"""`planhrc serve` on a network: a service bound to an address other than loopback refuses to start without a
token unless told `--insecure` (then it warns at every start); secrets come from files (the token, the database
password) and one on the command line is warned about; HTTPS with uvicorn's certificate options. The one-line
refusals of bad settings are in `tests/test_cli_errors.py`."""
from __future__ import annotations

import os
import shutil
import ssl
import subprocess
import time
from pathlib import Path

import httpx
import pytest

from planhrc.kb_service.cli import SERVE_OPTIONS, SettingsProblem, check_serve_settings
from planhrc.kb_service.command_settings import read_settings
from planhrc.kb_service.network import is_loopback
from planhrc.service_process import die_with_parent, free_port, serve_command, stop_process_group
from tests.servers import serve_env, served

PASSWORD = "correct horse battery staple"


def _check(given: dict, env: dict | None = None, monkeypatch: pytest.MonkeyPatch | None = None):
    """check_serve_settings as `planhrc serve` calls it: (settings, warnings)."""
    for key, value in (env or {}).items():
        assert monkeypatch is not None
        monkeypatch.setenv(key, value)
    read = read_settings({field: (SERVE_OPTIONS[field], value) for field, value in
                          {"port": free_port(), **given}.items()})
    warnings = list(read.warnings)
    check_serve_settings(read.settings, read.name, warnings)
    return read.settings, warnings


def _secret_file(folder: Path, name: str, text: str, mode: int = 0o600) -> str:
    path = folder / name
    path.write_text(text + "\n")
    path.chmod(mode)
    return str(path)


def test_loopback_is_what_only_this_machine_reaches():
    for host in ("127.0.0.1", "127.0.0.53", "::1", "[::1]", "localhost"):
        assert is_loopback(host), host
    for host in ("0.0.0.0", "::", "192.0.2.7", "no-such-host.invalid"):
        assert not is_loopback(host), host


def test_a_service_open_to_the_network_needs_a_token_or_insecure(tmp_path, monkeypatch):
    for key in list(os.environ):
        if key.startswith("PLANHRC_"):
            monkeypatch.delenv(key)
    with pytest.raises(SettingsProblem, match=r"^--host: 0\.0\.0\.0 is not a loopback address.*--insecure"):
        _check({"host": "0.0.0.0"})
    _, warnings = _check({"host": "0.0.0.0", "insecure": True})
    assert len(warnings) == 1 and warnings[0].startswith("--insecure: serving 0.0.0.0:") and "without a token" in warnings[0]
    token_file = _secret_file(tmp_path, "token", "s3cret")
    settings, warnings = _check({"host": "0.0.0.0", "token_file": token_file})
    assert settings.token == "s3cret"
    assert len(warnings) == 1 and "clear text" in warnings[0] and "--ssl-certfile" in warnings[0]
    _, warnings = _check({"host": "127.0.0.1"})  # loopback, no token: as before
    assert warnings == []
    # clients' keys in the store guard it as a token does
    from planhrc.kb_service.clients import ClientRegistry, open_table

    db = str(tmp_path / "kb.sqlite3")
    registry = ClientRegistry(open_table(db))
    registry.add("baxter-1", "robot")
    registry.close()
    _, warnings = _check({"host": "0.0.0.0", "db_path": db})
    assert len(warnings) == 1 and "clear text" in warnings[0]


def test_secrets_come_from_files_and_one_on_the_command_line_is_warned_about(tmp_path, monkeypatch):
    for key in list(os.environ):
        if key.startswith("PLANHRC_"):
            monkeypatch.delenv(key)
    _, warnings = _check({"token": "s3cret"})
    assert len(warnings) == 1 and warnings[0].startswith("--token: a secret on the command line shows in the process "
                                                         "list (ps)")
    _, warnings = _check({}, {"PLANHRC_TOKEN": "s3cret"}, monkeypatch)  # the environment: not shown by ps
    assert warnings == []
    monkeypatch.delenv("PLANHRC_TOKEN")
    readable = _secret_file(tmp_path, "read-token", "r3ad", mode=0o644)
    settings, warnings = _check({}, {"PLANHRC_READ_TOKEN_FILE": readable}, monkeypatch)
    assert settings.read_token == "r3ad"
    assert warnings == [f"PLANHRC_READ_TOKEN_FILE: {readable} is readable by other users of this machine "
                        f"(chmod 600 {readable})"]
    monkeypatch.delenv("PLANHRC_READ_TOKEN_FILE")
    with pytest.raises(SettingsProblem, match="^--db: cannot connect"):  # the URL's password is warned about first
        _check({"db_path": "postgresql://planhrc:hunter2@127.0.0.1:1/kb"})


def test_the_database_password_comes_from_its_file(pg_cluster, tmp_path, monkeypatch):
    """A role that must give its password: refused without it, served with the file's, and `planhrc compact`
    takes the same file."""
    for key in list(os.environ):
        if key.startswith(("PLANHRC_", "PG")):
            monkeypatch.delenv(key)
    url = pg_cluster.database_with_password(PASSWORD)
    with pytest.raises(SettingsProblem, match="^--db: cannot connect to postgresql://secured@127.0.0.1"):
        _check({"db_path": url})
    password_file = _secret_file(tmp_path, "pgpass", PASSWORD)
    settings, warnings = _check({"db_path": url, "db_password_file": password_file})
    assert warnings == [] and settings.db_password.get_secret_value() == PASSWORD
    with served(url, args=("--db-password-file", password_file), folder=tmp_path) as server:
        assert httpx.get(f"{server.url}/health").json()["objects"] == 0
        assert PASSWORD not in Path(f"/proc/{server.pid}/cmdline").read_text()
        assert PASSWORD not in server.log_path.read_text()
    from planhrc.cli import main

    assert main(["compact", "--db", url, "--db-password-file", password_file]) == 0


@pytest.mark.integration
def test_an_insecure_service_warns_at_every_start_and_a_token_file_guards_writes(tmp_path):
    db = tmp_path / "kb.sqlite3"
    for _ in range(2):
        with served(db, args=("--host", "0.0.0.0", "--insecure")) as server:
            assert httpx.get(f"{server.url}/health").json()["auth"] is False
        log = server.log_path.read_text()
        assert "planhrc serve: warning: --insecure: serving 0.0.0.0:" in log, log
    token_file = _secret_file(tmp_path, "token", "t0ken-from-a-file")
    with served(db, env={"PLANHRC_TOKEN_FILE": token_file}) as server:
        body = {"name": "rod", "links": 3, "orientations": 4, "formulation": "relative"}
        assert httpx.post(f"{server.url}/objects", json=body).status_code == 401
        created = httpx.post(f"{server.url}/objects", json=body,
                             headers={"Authorization": "Bearer t0ken-from-a-file"})
        assert created.status_code == 201
        assert "warning" not in server.log_path.read_text()


@pytest.mark.integration
def test_https_with_a_certificate_and_its_key(tmp_path):
    openssl = shutil.which("openssl")
    if openssl is None:
        pytest.skip("the openssl command, which makes the test's certificate, is not installed")
    cert, key = tmp_path / "cert.pem", tmp_path / "key.pem"
    subprocess.run([openssl, "req", "-x509", "-newkey", "rsa:2048", "-nodes", "-days", "1", "-subj", "/CN=127.0.0.1",
                    "-addext", "subjectAltName=IP:127.0.0.1", "-keyout", str(key), "-out", str(cert)],
                   check=True, capture_output=True)
    trusted = ssl.create_default_context(cafile=str(cert))
    port = free_port()
    cmd = serve_command(port, tmp_path / "kb.sqlite3",
                        ("--log-level", "warning", "--ssl-certfile", str(cert), "--ssl-keyfile", str(key)))
    with open(tmp_path / "serve.log", "wb") as log:
        proc = subprocess.Popen(cmd, cwd=tmp_path, env=serve_env(), stdout=log, stderr=subprocess.STDOUT,
                                start_new_session=True, preexec_fn=die_with_parent)
        try:
            answer = None
            for _ in range(600):
                assert proc.poll() is None, (tmp_path / "serve.log").read_text()
                try:
                    answer = httpx.get(f"https://127.0.0.1:{port}/health", verify=trusted, timeout=2)
                    break
                except httpx.TransportError:
                    time.sleep(0.1)
            assert answer is not None and answer.status_code == 200
            with pytest.raises(httpx.TransportError):  # plain HTTP is not served
                httpx.get(f"http://127.0.0.1:{port}/health", timeout=2)
        finally:
            stop_process_group(proc)
