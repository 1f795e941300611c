"""Imports run one way: every module's imports (function-level ones included) point to its own layer or below.

    0 model        planhrc.model, .control, .vocabulary, .grounding, .transition, .cooperation, .paths, .settings,
                   .geometry, .ordering, .stats, .errors, .judge and .motion_search (the one judge of a
                   turn, the search for the robot's plans that fit the table),
                   .cli_args (argument checks every command shares), .json_record and .event_log (the records of
                   an object's event log, which the service writes and its clients read), planhrc.ontology
    0.5 client     planhrc.client, planhrc.service_process (layer 0 and httpx only: the service's HTTP client,
                   `planhrc serve` as a child process)
    1 translator   planhrc.translator
    2 planner      planhrc.planner
    3 pipeline     planhrc.pipeline (the folder pipeline/)
    4 service      planhrc.kb_service (HTTP, service layer, the knowledge-base store, reasoners)
    5 top          planhrc (the lazy facade), planhrc.cli, planhrc.bench (the folder bench/), planhrc.robot_sim,
                   planhrc.ros2 (the folder ros2/: the ROS 2 bridge)

`planhrc.robot_sim` may import only layer 0 and the client. `planhrc.ros2` may import only layer 0, the client
and the robot's public names (nothing starting with `_`); nothing else imports it. A module missing from `LAYERS` fails the test, so a
new module is placed on purpose.
"""
from __future__ import annotations

import ast
from pathlib import Path
from typing import Iterator

import pytest

ROOT = Path(__file__).resolve().parents[1]
# folder of the repository -> its import name (the package-dir mapping of pyproject.toml)
PACKAGES = {"planhrc": "planhrc", "kb_service": "planhrc.kb_service", "translator": "planhrc.translator",
            "planner": "planhrc.planner", "robot_sim": "planhrc.robot_sim", "ontology": "planhrc.ontology",
            "pipeline": "planhrc.pipeline", "bench": "planhrc.bench", "ros2": "planhrc.ros2"}

# Longest prefix wins.
LAYERS: dict[str, float] = {
    "planhrc.model": 0, "planhrc.control": 0, "planhrc.vocabulary": 0, "planhrc.grounding": 0, "planhrc.transition": 0,
    "planhrc.cooperation": 0, "planhrc.paths": 0, "planhrc.settings": 0, "planhrc.geometry": 0, "planhrc.ordering": 0,
    "planhrc.stats": 0, "planhrc.errors": 0, "planhrc.judge": 0, "planhrc.motion_search": 0,
    "planhrc.cli_args": 0, "planhrc.ontology": 0, "planhrc.json_record": 0, "planhrc.event_log": 0,
    "planhrc.client": 0.5, "planhrc.service_process": 0.5,
    "planhrc.translator": 1,
    "planhrc.planner": 2,
    "planhrc.pipeline": 3,
    "planhrc.kb_service": 4,
    "planhrc": 5, "planhrc.cli": 5, "planhrc.bench": 5,
    "planhrc.robot_sim": 5,
    "planhrc.ros2": 5,
}
# Besides its own package, robot_sim reaches only these layers (the service only over HTTP).
ROBOT_SIM_MAY_IMPORT = {0, 0.5}
# Besides its own package, the ROS 2 layer reaches only these layers and the robot (the service only over HTTP).
ROS2_MAY_IMPORT = {0, 0.5}


def layer_of(module: str) -> float | None:
    best = None
    for prefix in LAYERS:
        if (module == prefix or module.startswith(prefix + ".")) and (best is None or len(prefix) > len(best)):
            best = prefix
    return None if best is None else LAYERS[best]


def modules() -> dict[str, Path]:
    out = {}
    for folder, package in PACKAGES.items():
        for path in sorted((ROOT / folder).rglob("*.py")):
            parts = path.relative_to(ROOT / folder).with_suffix("").parts
            if parts[-1] == "__init__":
                parts = parts[:-1]
            out[".".join((package,) + parts)] = path
    return out


def import_statements(module: str, source: str, is_package: bool = False) -> Iterator[tuple[str, list[str]]]:
    """Each import of `module`, at the top or inside functions (TYPE_CHECKING blocks included), as (the module
    imported from, the names imported): `import a.b` is ("a.b", []), `from .x import y` ("<package>.x", ["y"])."""
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield alias.name, []
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = module.split(".")
                base = base[: len(base) - node.level + (1 if is_package else 0)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            yield target, [alias.name for alias in node.names]


def imports_of(module: str, source: str, is_package: bool = False) -> set[str]:
    """Every planhrc module `module` imports (`import_statements`).
    The package `planhrc` itself is left out (its facade is lazy); a name taken from it is not."""
    found = set()
    for target, names in import_statements(module, source, is_package):
        found.add(target)
        found.update(f"{target}.{name}" for name in names)  # `from pkg import module`
    return {name for name in found if name.startswith("planhrc.")}


ALL = modules()


def test_every_module_has_a_layer():
    assert [m for m in ALL if layer_of(m) is None] == []


@pytest.mark.parametrize("module", sorted(ALL))
def test_no_import_points_up(module):
    own = layer_of(module)
    upward = []
    path = ALL[module]
    for target in sorted(imports_of(module, path.read_text(), path.name == "__init__.py")):
        if target not in ALL and target.rsplit(".", 1)[0] in ALL:
            continue  # `from pkg.module import name`: the module itself is checked
        layer = layer_of(target)
        if layer is None or own is None:
            continue
        if not module.startswith("planhrc.ros2") and target.startswith("planhrc.ros2"):
            upward.append(f"{target} (the ROS 2 layer: nothing imports it)")
        elif module.startswith("planhrc.ros2"):
            allowed = (target.startswith(("planhrc.ros2", "planhrc.robot_sim")) or layer in ROS2_MAY_IMPORT)
            private = target.startswith("planhrc.robot_sim") and target.rsplit(".", 1)[-1].startswith("_")
            if not allowed or private:
                upward.append(f"{target} (the ROS 2 layer reaches the service over HTTP, the robot by public names)")
        elif module.startswith("planhrc.robot_sim"):
            if not target.startswith("planhrc.robot_sim") and layer not in ROBOT_SIM_MAY_IMPORT:
                upward.append(f"{target} (layer {layer}; the worker reaches the service only over HTTP)")
        elif layer > own:
            upward.append(f"{target} (layer {layer} above {own})")
    assert upward == [], f"{module} imports upward: {upward}"


def test_the_walk_sees_function_level_and_relative_imports():
    """The checker itself: an import inside a function counts, relative imports resolve, facade names count."""
    source = "from .locks import ObjectLocks\ndef f():\n    from planhrc.kb_service import app\n"
    found = imports_of("planhrc.kb_service.orchestrator", source)
    assert {"planhrc.kb_service.locks", "planhrc.kb_service.app"} <= found
    assert imports_of("planhrc.translator", "from .domain import x\n", is_package=True) >= {"planhrc.translator.domain"}
    assert layer_of("planhrc.kb_service.app") > layer_of("planhrc.model")
    assert layer_of(next(iter(imports_of("planhrc.model", "from planhrc import plan\n")))) == 5


def test_the_shared_folder_holds_only_the_ground_floor():
    """`planhrc/` keeps what every layer shares (layers 0 and 0.5) plus the command-line entry and the lazy facade:
    the pipeline, the benchmarks, the service and the robot live in folders of their own."""
    shared = [m for m, path in ALL.items() if path.parent == ROOT / "planhrc"]
    above = [m for m in shared if m not in {"planhrc", "planhrc.cli"} and (layer_of(m) or 0) > 0.5]
    assert shared and above == []
