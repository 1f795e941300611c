"""Every error planhrc raises sits under its package's root, and every root under `PlanhrcError`: one `except`
catches a package's errors, and the command line reports any of them in one line (tests/test_cli_errors.py).
Running out of time is one exception, `DeadlineExceeded`, whichever layer stops."""
from __future__ import annotations

import ast
import builtins
import importlib
import inspect

import pytest

from planhrc.bench.errors import BenchError
from planhrc.errors import DeadlineExceeded, PlanhrcError
from planhrc.kb_service.store.errors import DeadlineError, KBError
from planhrc.planner.errors import PlannerError
from planhrc.robot_sim.errors import SimError
from planhrc.ros2.errors import Ros2Error
from planhrc.translator.errors import TranslationError
from tests.test_layers import modules

# package -> the root every public error class defined in it derives from (longest prefix wins)
ROOTS: dict[str, type[Exception]] = {
    "planhrc": PlanhrcError,
    "planhrc.translator": TranslationError,
    "planhrc.planner": PlannerError,
    "planhrc.kb_service": KBError,
    "planhrc.robot_sim": SimError,
    "planhrc.bench": BenchError,
    "planhrc.ros2": Ros2Error,
}
# Third-party packages that only `.venv-ros2` has: modules importing them are checked from their source.
ROS2_ONLY = ("rclpy", "builtin_interfaces", "std_msgs", "sensor_msgs", "trajectory_msgs", "visualization_msgs",
             "diagnostic_msgs", "geometry_msgs")
# Not errors: a signal that unwinds the stack like KeyboardInterrupt does.
NOT_ERRORS = {"planhrc.cli.Terminated"}


def root_of(module: str) -> type[Exception]:
    best = max((p for p in ROOTS if module == p or module.startswith(p + ".")), key=len)
    return ROOTS[best]


def test_every_package_root_is_a_planhrc_error():
    for root in ROOTS.values():
        assert issubclass(root, PlanhrcError), root


@pytest.mark.parametrize("module", sorted(modules()))
def test_every_public_error_is_under_its_package_root(module):
    try:
        loaded = importlib.import_module(module)
    except ModuleNotFoundError as exc:
        if not (exc.name or "").split(".")[0] in ROS2_ONLY:
            raise
        assert not builtin_error_subclasses(module), f"{module}: {builtin_error_subclasses(module)} not under a root"
        return
    defined = [cls for _, cls in inspect.getmembers(loaded, inspect.isclass)
               if cls.__module__ == module and issubclass(cls, BaseException) and not cls.__name__.startswith("_")
               and f"{module}.{cls.__name__}" not in NOT_ERRORS]
    root = root_of(module)
    outside = [cls.__name__ for cls in defined if not issubclass(cls, root)]
    assert not outside, f"{module}: {outside} not under {root.__name__}"


def builtin_error_subclasses(module: str) -> list[str]:
    """The public classes a module's source derives directly from a built-in exception (for modules that cannot be
    imported here: their errors must derive from the package's root, which is defined elsewhere)."""
    tree = ast.parse(modules()[module].read_text())
    builtin_errors = {name for name, value in vars(builtins).items()
                      if isinstance(value, type) and issubclass(value, BaseException)}
    return [node.name for node in ast.walk(tree) if isinstance(node, ast.ClassDef) and not node.name.startswith("_")
            and any(isinstance(base, ast.Name) and base.id in builtin_errors for base in node.bases)]


def test_the_service_deadline_is_the_one_deadline():
    assert issubclass(DeadlineError, DeadlineExceeded) and issubclass(DeadlineError, KBError)
    assert not issubclass(DeadlineExceeded, PlannerError | KBError)  # shared by every layer, owned by none
