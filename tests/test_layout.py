"""Package layout rules (DESIGN 2): no stdlib shadowing, and the dependency rule by imports."""

from __future__ import annotations

import ast
import os
import re
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = {
    "egc_common": ROOT / "common" / "egc_common",
    "egc_robot": ROOT / "robot" / "egc_robot",
    "egc_operator": ROOT / "operator" / "egc_operator",
    "egc_sim": ROOT / "sim_robot" / "egc_sim",
}
ALLOWED = {
    "egc_common": set(),
    "egc_robot": {"egc_common"},
    "egc_operator": {"egc_common"},
    "egc_sim": {"egc_common"},
}
# The core must stay free of IO libraries (DESIGN 2); transport.py is common's one Zenoh adapter.
CORE_FORBIDDEN = {"zenoh", "rerun", "evdev"}
COMMON_IO_ADAPTERS = {"transport.py"}


def imported_top_levels(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(alias.name.split(".")[0] for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.add(node.module.split(".")[0])
    return names


@pytest.mark.parametrize("package", sorted(PACKAGES))
def test_packages_depend_only_on_common(package):
    others = set(PACKAGES) - {package} - ALLOWED[package] | {"egc_app"}
    for path in PACKAGES[package].rglob("*.py"):
        bad = imported_top_levels(path) & others
        assert not bad, f"{path.relative_to(ROOT)} imports {sorted(bad)} (DESIGN 2)"


def test_common_core_has_no_io_libraries():
    for path in PACKAGES["egc_common"].rglob("*.py"):
        if path.name in COMMON_IO_ADAPTERS:
            continue
        bad = imported_top_levels(path) & CORE_FORBIDDEN
        assert not bad, f"{path.relative_to(ROOT)} imports {sorted(bad)}"


def test_filters_are_pure():
    for path in (ROOT / "robot" / "egc_robot" / "filters").rglob("*.py"):
        names = imported_top_levels(path)
        assert not names & (CORE_FORBIDDEN | {"time", "egc_app"}), path


def test_stdlib_operator_is_not_shadowed_from_the_repo_root():
    code = (
        "import collections, operator, egc_operator, egc_robot, egc_common, egc_sim, egc_app;"
        "assert operator.add(2, 3) == 5 and hasattr(operator, 'itemgetter');"
        "print(operator.__file__)"
    )
    out = subprocess.run(
        [sys.executable, "-c", code],
        cwd=ROOT,
        capture_output=True,
        text=True,
        check=True,
    )
    assert "egc" not in out.stdout


# DESIGN 11: rclpy (and the ROS 2 message packages) only in the two ROS 2 adapters, so that
# everything else runs without ROS 2 installed.
ROS2_MODULES = {
    "rclpy",
    "sensor_msgs",
    "geometry_msgs",
    "nav_msgs",
    "std_msgs",
    "builtin_interfaces",
}
ROS2_ADAPTERS = {
    ROOT / "robot" / "egc_robot" / "ros2_driver.py",
    ROOT / "sim_robot" / "egc_sim" / "ros2_base.py",
}


def test_only_the_ros2_adapters_import_rclpy():
    folders = [*PACKAGES.values(), ROOT / "egc_app", ROOT / "experiments"]
    for folder in folders:
        for path in folder.rglob("*.py"):
            if path in ROS2_ADAPTERS:
                continue
            bad = imported_top_levels(path) & ROS2_MODULES
            assert not bad, f"{path.relative_to(ROOT)} imports {sorted(bad)} (DESIGN 11)"


# Every rclpy executor is spun by ``egc_common.executor_thread.ExecutorThread`` (issue 31): an
# executor shut down, or a node destroyed, under a thread still inside ``spin`` segfaults. The
# tests' fake navigation stack kept the old way (a thread on ``executor.spin``, shut down with a
# timeout) and a CI run (39) segfaulted in the next node's ``destroy_node``.
UNSAFE_SPIN = re.compile(r"target=[\w.]*\.spin\b|\.shutdown\(timeout_sec=|rclpy\.spin\(")


def test_every_ros2_executor_thread_is_an_executor_thread():
    folders = [*PACKAGES.values(), ROOT / "egc_app", ROOT / "experiments", ROOT / "tests"]
    folders.append(ROOT / "bench")
    for folder in folders:
        for path in folder.rglob("*.py"):
            if path == Path(__file__).resolve():
                continue
            for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
                assert not UNSAFE_SPIN.search(line), (
                    f"{path.relative_to(ROOT)}:{n}: spin an rclpy executor with "
                    f"egc_common.executor_thread.ExecutorThread, not {line.strip()!r}"
                )


# ---------------------------------------------------------------------------------------------
# egc_app, the console script (DESIGN 2): nothing imports it, and it holds argument parsing and
# wiring only. The headless episode engine and the log replay used to live there, imported by
# experiments, tests, bench and docs; they are in egc_experiments now.

EGC_APP = ROOT / "egc_app"
SKIPPED_DIRS = {"build", "dist", "node_modules", "__pycache__"}  # and every dot-directory
# Calls that import or reach into a module named by a string: ``importlib.import_module``,
# ``runpy.run_module`` (the console script run in this process), ``monkeypatch.setattr`` and
# ``mock.patch`` with a dotted path. ``[sys.executable, "-m", "egc_app.cli", ...]`` is none of
# them: running the console script as a process is not importing it.
IMPORTING_CALLS = {"import_module", "__import__", "run_module", "setattr", "delattr", "patch"}
EGC_APP_NAME = re.compile(r"^egc_app(\.|$)")

# robot_cmd.py is being changed on other branches (issue 31 allowed only its import lines to
# change here), so its non-CLI parts stay for now: ``SimDriver`` (an in-process simulator as a
# driver), ``build_controller_config``, ``ROBOT_TABLES`` and ``resume_window_caveat`` (the
# robot's configuration), and a test that patches its internals. These are the only
# exceptions, and each must still be needed: the lists can only shrink.
PENDING_IMPORTS: dict[str, set[str]] = {
    "bench/bench_ros2.py": {"egc_app.robot_cmd"},
    "tests/integration/test_deploy_files.py": {"egc_app.robot_cmd"},
    "tests/robot/test_robot_cmd_shutdown.py": {"egc_app", "egc_app.cli", "egc_app.robot_cmd"},
}
PENDING_CLASSES: dict[str, set[str]] = {"robot_cmd.py": {"SimDriver"}}

# egc_app modules that are not subcommands: the package, ``python -m egc_app``, the console
# script's entry point, and tools for tests: the parsers (``python -m egc_app.parse_check``) and
# many command lines in one process (``python -m egc_app.cli_worker``).
ENTRY_MODULES = {"__init__", "__main__", "cli", "parse_check", "cli_worker"}
# What an engine is made of and a wiring module has no use for: numerical and data libraries,
# log and file formats, recordings, progress bars, worker pools and event loops. (Zenoh is
# wiring: ``egc-teleop router`` configures and runs a router.)
ENGINE_LIBRARIES = {
    "numpy",
    "scipy",
    "pyarrow",
    "msgpack",
    "struct",
    "heapq",
    "rerun",
    "rosbags",
    "mcap",
    "av",
    "PIL",
    "matplotlib",
    "tqdm",
    "multiprocessing",
    "concurrent",
    "asyncio",
}


def python_files(root: Path = ROOT) -> Iterator[Path]:
    """Every .py file of the repository but the virtual environment, build output and caches."""
    for folder, dirs, files in os.walk(root):
        dirs[:] = [d for d in dirs if not d.startswith(".") and d not in SKIPPED_DIRS]
        for name in files:
            if name.endswith(".py"):
                yield Path(folder) / name


def egc_app_references(path: Path) -> set[str]:
    """The egc_app modules ``path`` imports (at any depth, lazily or not), or names in a call
    that imports or patches a module by its dotted name."""
    found = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            found |= {a.name for a in node.names if EGC_APP_NAME.match(a.name)}
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            if EGC_APP_NAME.match(node.module):
                found.add(node.module)
                if node.module == "egc_app":  # from egc_app import cli: the module egc_app.cli
                    found |= {f"egc_app.{a.name}" for a in node.names}
        elif isinstance(node, ast.Call) and node.args:
            func = node.func
            name = func.attr if isinstance(func, ast.Attribute) else getattr(func, "id", "")
            first = node.args[0]
            if (
                name in IMPORTING_CALLS
                and isinstance(first, ast.Constant)
                and isinstance(first.value, str)
                and EGC_APP_NAME.match(first.value)
            ):
                found.add(first.value)
    return found


def test_nothing_outside_egc_app_imports_it():
    """DESIGN 2: ``egc_app`` may import the packages and ``experiments``, never the reverse, and
    nothing imports ``egc_app``: not the packages, not experiments, not tests, bench or docs.
    What they share with the console script lives in a package (the episode engine and the log
    replay in ``egc_experiments``, the subcommands' parser class in ``egc_common.cli_args``);
    tests run the console script as a process (``tests.cli_process``)."""
    problems = []
    for path in python_files():
        rel = path.relative_to(ROOT)
        if rel.parts[0] == "egc_app":
            continue
        extra = egc_app_references(path) - PENDING_IMPORTS.get(rel.as_posix(), set())
        if extra:
            problems.append(f"{rel} imports {sorted(extra)}")
    assert not problems, "nothing may import egc_app (DESIGN 2):\n" + "\n".join(problems)


def test_the_pending_exceptions_are_still_needed():
    for rel, modules in PENDING_IMPORTS.items():
        path = ROOT / rel
        assert path.is_file() and egc_app_references(path) >= modules, (
            f"{rel} no longer imports {sorted(modules)}: drop it from PENDING_IMPORTS"
        )
    for name, classes in PENDING_CLASSES.items():
        defined = {n.name for n in _top_level(EGC_APP / name) if isinstance(n, ast.ClassDef)}
        assert defined >= classes, f"{name}: drop {sorted(classes - defined)} from PENDING_CLASSES"


def _top_level(path: Path) -> list[ast.stmt]:
    return ast.parse(path.read_text(encoding="utf-8")).body


def _subcommand_modules() -> set[str]:
    """The modules of ``egc_app.cli.SUBCOMMANDS``, read from its source (not imported)."""
    for node in _top_level(EGC_APP / "cli.py"):
        target = node.target if isinstance(node, ast.AnnAssign) else None
        if isinstance(node, ast.Assign) and len(node.targets) == 1:
            target = node.targets[0]
        if isinstance(target, ast.Name) and target.id == "SUBCOMMANDS":
            assert isinstance(node.value, ast.Dict), "SUBCOMMANDS is a dict literal"
            return {ast.literal_eval(v)[0] for v in node.value.values if v is not None}
    raise AssertionError("egc_app/cli.py has no SUBCOMMANDS")


def _is_argparse_class(node: ast.ClassDef) -> bool:
    names = {ast.unparse(base) for base in node.bases}
    return any(n.startswith("argparse.") or n == "CliArgumentParser" for n in names)


def test_egc_app_holds_argument_parsing_and_wiring_only():
    """What "argument parsing and wiring only" means here, checkably (DESIGN 2):

    - every module of egc_app is a subcommand named in ``cli.SUBCOMMANDS`` that defines
      ``configure(parser)`` and ``run(args)``, or one of the entry modules (``ENTRY_MODULES``):
      no helper or library modules, no subpackages (a library there could only be used by
      importing egc_app);
    - it defines no classes but argparse ones (an engine's state, a recording, a driver
      adapter belong to a package);
    - it imports none of the libraries an engine is made of (``ENGINE_LIBRARIES``: numpy,
      file and log formats, Rerun, progress bars, worker pools, event loops), at any depth: it
      hands arguments to the packages, which do the work.

    Before the episode engine and the replay moved out, this failed on ``episode.py``
    (multiprocessing, tqdm), ``replay_cmd.py`` (numpy, struct, rosbags, tqdm) and
    ``replay_record.py`` (not a subcommand; numpy, rerun, a class).
    """
    subcommands = _subcommand_modules()
    problems = []
    for path in sorted(EGC_APP.rglob("*.py")):
        rel = path.relative_to(EGC_APP)
        if len(rel.parts) > 1:
            problems.append(f"egc_app/{rel}: a subpackage")
            continue
        body = _top_level(path)
        functions = {n.name for n in body if isinstance(n, ast.FunctionDef)}
        if path.stem not in ENTRY_MODULES:
            if f"egc_app.{path.stem}" not in subcommands:
                problems.append(f"egc_app/{rel}: not a subcommand of cli.SUBCOMMANDS")
            if not {"configure", "run"} <= functions:
                problems.append(f"egc_app/{rel}: no configure(parser) and run(args)")
        for node in body:
            if (
                isinstance(node, ast.ClassDef)
                and not _is_argparse_class(node)
                and node.name not in PENDING_CLASSES.get(path.name, set())
            ):
                problems.append(f"egc_app/{rel}: class {node.name}")
        engine = imported_top_levels(path) & ENGINE_LIBRARIES
        if engine:
            problems.append(f"egc_app/{rel}: imports {sorted(engine)}")
    assert not problems, "egc_app holds argument parsing and wiring only:\n" + "\n".join(problems)
