"""Package layout rules (DESIGN 2): no stdlib shadowing, and the dependency rule by imports."""

from __future__ import annotations

import ast
import subprocess
import sys
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
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=True
    )
    assert "egc" not in out.stdout


# DESIGN 11: rclpy (and the ROS 2 message packages) only in the two ROS 2 adapters, so that
# everything else runs without ROS 2 installed.
ROS2_MODULES = {"rclpy", "sensor_msgs", "geometry_msgs", "nav_msgs", "builtin_interfaces"}
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
