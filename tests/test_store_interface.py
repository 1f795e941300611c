"""Every backend implements the store's interface (`kb_service/store/interface.py`): each method of each protocol,
with the protocol's parameters, at run time; and mypy accepts the SQLite store as a `KnowledgeStore` and refuses a
store that differs from the protocol in one parameter's type."""
from __future__ import annotations

import inspect
import subprocess
import sys
from pathlib import Path
from typing import Generic, Protocol

import pytest

from planhrc.kb_service.store import (BACKENDS, Export, Inferences, KBError, KnowledgeStore, PlanChecks, PlanJournal,
                                      Reads, Retention, SqliteStore, Writes, open_store)
from planhrc.kb_service.store.errors import UnavailableError
from planhrc.kb_service.store.backends import backend_of
from planhrc.paths import default_tbox_path
from tests.store_backends import kb, place  # noqa: F401 (fixtures)
from tests.test_types import REPO, stage_namespace

PROTOCOLS = (Writes, Reads, PlanChecks, PlanJournal, Export, Retention, Inferences, KnowledgeStore)


def members(protocol: type) -> list[str]:
    """The methods a protocol asks for, its own and its bases' (the context manager's included)."""
    return sorted({name for base in protocol.__mro__ if base not in (object, Protocol, Generic)
                   for name, value in vars(base).items()
                   if callable(value) and (not name.startswith("_") or name in ("__enter__", "__exit__"))})


def signature_mismatches(protocol: type, implementation: type) -> list[str]:
    """Methods of `protocol` that `implementation` lacks, or whose parameters differ in name, kind or default."""
    out = []
    for name in members(protocol):
        found = getattr(implementation, name, None)
        if not callable(found):
            out.append(f"{name}: missing")
            continue
        want, got = _parameters(getattr(protocol, name)), _parameters(found)
        if got != want:
            out.append(f"{name}({got}) != {name}({want})")
    return out


def _parameters(method: object) -> str:
    """`self, state_id, limit=None, *exc`: names, kinds and defaults, not annotations (mypy checks those)."""
    empty = inspect.Parameter.empty
    return ", ".join(str(p.replace(annotation=empty)) for p in inspect.signature(method).parameters.values())


def test_the_protocols_ask_for_what_the_service_calls():
    service_calls = {"transaction", "add_perception", "check_plan", "check_steps", "add_plan", "get_state", "get_plan", "get_action",
                     "get_problem", "add_event", "list_events", "get_execution", "set_execution", "recall_response",
                     "remember_response", "new_object_id", "create_object", "get_object", "list_objects", "add_state",
                     "add_problem", "latest_plan", "latest_problem", "export", "export_lines", "settle",
                     "plans_to_write", "triple_count", "object_count", "compact", "close"}
    assert service_calls <= set(members(KnowledgeStore))
    for protocol in PROTOCOLS[:-1]:
        assert set(members(protocol)) <= set(members(KnowledgeStore)), protocol.__name__


@pytest.mark.parametrize("protocol", PROTOCOLS, ids=lambda p: p.__name__)
def test_every_backend_implements_every_protocol(kb, protocol):
    assert isinstance(kb, protocol)
    assert signature_mismatches(protocol, type(kb)) == []


def test_a_store_that_differs_from_the_protocol_is_caught():
    class Renamed(SqliteStore):
        def get_state(self, ident):  # the parameter the protocol calls state_id
            return super().get_state(ident)

    class Incomplete:
        def get_state(self, state_id):
            raise NotImplementedError

    assert signature_mismatches(Reads, Renamed) == ["get_state(self, ident) != get_state(self, state_id)"]
    assert not isinstance(Incomplete(), Reads)
    assert "get_plan: missing" in signature_mismatches(Reads, Incomplete)


def test_a_location_names_its_backend():
    assert backend_of(None) == backend_of("/var/lib/planhrc/kb.sqlite3") == "sqlite"
    assert backend_of("postgresql://planhrc@db:5432/kb") == "postgresql"
    assert backend_of("postgres://planhrc@db/kb") == "postgresql"
    assert set(BACKENDS) == {"sqlite", "postgresql"}
    for memory in (None, "", ":memory:"):
        with open_store(memory, default_tbox_path()) as store:
            assert isinstance(store, SqliteStore) and store.object_count() == 0
    with pytest.raises(KBError, match=r"^db: no store backend for mysql:// \(this version has: postgresql, sqlite\)$"):
        open_store("mysql://planhrc@db:3306/kb", default_tbox_path())
    with pytest.raises(KBError, match=r"^db_password: the embedded SQLite store takes no password"):
        open_store(None, default_tbox_path(), password="secret")


def test_a_server_that_cannot_be_reached_is_refused_in_one_line_without_its_password():
    with pytest.raises(UnavailableError) as info:  # port 1 of loopback: nobody listens there
        open_store("postgresql://planhrc:hunter2@127.0.0.1:1/kb", default_tbox_path())
    message = str(info.value)
    assert message.startswith("db: cannot connect to postgresql://planhrc:***@127.0.0.1:1/kb (")
    assert "hunter2" not in message and "\n" not in message


def _stub(class_name: str, retyped: tuple[str, str, str] | None = None) -> str:
    """Source of a class with every method of `KnowledgeStore`, as the protocol types them; `retyped` = (method,
    parameter, type) gives one parameter another type."""
    lines = [f"class {class_name}:"]
    for name in members(KnowledgeStore):
        signature = inspect.signature(getattr(KnowledgeStore, name))
        params = []
        for p in signature.parameters.values():
            annotation = p.annotation
            if retyped and (name, p.name) == retyped[:2]:
                annotation = retyped[2]
            text = p.name if annotation is inspect.Parameter.empty else f"{p.name}: {annotation}"
            if p.kind is inspect.Parameter.VAR_POSITIONAL:
                text = "*" + text
            if p.default is not inspect.Parameter.empty:
                text += f" = {p.default!r}"
            params.append(text)
        lines.append(f"    def {name}(self, {', '.join(params[1:])}) -> {signature.return_annotation}:")
        lines.append("        raise NotImplementedError")
    return "\n".join(lines) + "\n"


@pytest.mark.slow
def test_mypy_sees_the_sqlite_store_as_a_knowledge_store_and_refuses_one_parameter_off(tmp_path: Path):
    stage = stage_namespace(tmp_path / "stage")
    source = "\n".join([
        "from contextlib import AbstractContextManager",
        "from typing import Any, Iterator, Self, Sequence",
        "from planhrc.kb_service.store.knowledge_base import SqliteStore",
        "from planhrc.kb_service.store.interface import KnowledgeStore",
        "from planhrc.kb_service.store.records import (ActionSpec, CheckedPlan, Compaction, Execution, StoredAction,",
        "    StoredEvent, StoredPlan, StoredProblem, StoredState)",
        "from planhrc.model import ArticulatedObject, Atom, Perception",
        "",
        "store: KnowledgeStore = SqliteStore(None, 'planhrc.owl')",
        _stub("AsTheProtocolSays"),
        _stub("OneParameterOff", ("get_state", "state_id", "int")),
        "same: KnowledgeStore = AsTheProtocolSays()",
        "off: KnowledgeStore = OneParameterOff()  # line of the one error",
    ])
    (stage / "check_store.py").write_text(source)
    line = source.splitlines().index("off: KnowledgeStore = OneParameterOff()  # line of the one error") + 1
    result = subprocess.run(
        [sys.executable, "-m", "mypy", "--config-file", str(REPO / "pyproject.toml"), "--cache-dir",
         str(tmp_path / "cache"), "check_store.py"], cwd=stage, capture_output=True, text=True, timeout=600)
    errors = [row for row in result.stdout.splitlines() if ": error:" in row]
    assert len(errors) == 1 and errors[0].startswith(f"check_store.py:{line}: error: Incompatible types in "
                                                     "assignment"), result.stdout[-4000:]
