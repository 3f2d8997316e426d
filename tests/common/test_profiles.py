"""Robot profiles as data (DESIGN 3, 14): the built-in files, user files, and one clear line
for every kind of bad file."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
from egc_common.footprint import Footprint
from egc_common.profiles import (
    HUSKY,
    JACKAL,
    PIONEER3DX,
    PROFILES,
    TURTLEBOT4,
    ProfileError,
    load_profile,
    profile_from_toml,
)

DOCS_PENTAGON = Path(__file__).resolve().parents[2] / "docs" / "profiles" / "pentagon.toml"

GOOD = """
[profile]
name = "cart"
source = "measured with a tape, 2024"
footprint = [[0.4, 0.0], [0.1, 0.3], [-0.3, 0.3], [-0.3, -0.3], [0.1, -0.3]]
v_max = 0.5
w_max = 1.0
a_max = 0.5
a_dec = 1.0
alpha_max = 2.0
r_max = 1.2
"""


def test_pinned_figures_are_unchanged():
    p = PIONEER3DX
    assert (p.length_m, p.width_m, p.v_max_mps, p.w_max_radps) == (0.455, 0.381, 0.14, 0.5)
    assert (p.r_min_m, p.r_max_m, p.wheel_base_m) == (0.455, 0.595, 0.33)
    assert (p.accel_max_mps2, p.decel_max_mps2, p.angular_accel_max_radps2) == (0.3, 0.5, 1.5)
    j = JACKAL
    assert (j.length_m, j.width_m, j.v_max_mps, j.w_max_radps) == (0.508, 0.430, 2.0, 2.0)
    assert (j.r_min_m, j.r_max_m, j.wheel_base_m) == (0.508, 2.508, 0.37)
    assert (j.accel_max_mps2, j.decel_max_mps2, j.angular_accel_max_radps2) == (2.0, 3.0, 6.0)
    assert p.half_size_m == (0.2275, 0.1905)
    assert p.half_diagonal_m == 0.5 * math.hypot(0.455, 0.381)


def test_new_builtins_from_their_makers_figures():
    t = TURTLEBOT4
    assert t.footprint.is_disc and t.footprint.radius_m == 0.171
    assert (t.v_max_mps, t.w_max_radps, t.r_min_m, t.r_max_m) == (0.31, 1.9, 0.342, 0.652)
    h = HUSKY
    assert (h.length_m, h.width_m, h.v_max_mps, h.r_min_m, h.r_max_m) == (
        0.99,
        0.67,
        1.0,
        0.99,
        1.99,
    )
    assert set(PROFILES) == {"pioneer3dx", "jackal", "turtlebot4", "husky"}
    for profile in PROFILES.values():
        assert len(profile.source) > 40 and "\n" not in profile.source
        assert load_profile(profile.name) is profile


def test_builtin_files_load_by_path(tmp_path):
    import egc_common

    folder = Path(egc_common.__file__).parent / "profiles"
    for name, profile in PROFILES.items():
        assert load_profile(str(folder / f"{name}.toml")) == profile


def test_a_user_file_with_defaults(tmp_path):
    path = tmp_path / "cart.toml"
    path.write_text(GOOD)
    cart = load_profile(str(path))
    assert cart.name == "cart"
    assert cart.footprint.centred_box is None and len(cart.footprint.vertices_m) == 5
    assert cart.d_robot_m == pytest.approx(0.7)  # the length along x
    assert cart.wheel_base_m == pytest.approx(0.6)  # the width along y
    assert cart.half_size_m == (0.4, 0.3)
    assert cart.laser_pose is None


def test_the_documented_pentagon_loads():
    pentagon = load_profile(str(DOCS_PENTAGON))
    assert not pentagon.footprint.is_disc and pentagon.footprint.centred_box is None


def test_disc_forms():
    base = GOOD.replace(
        "footprint = [[0.4, 0.0], [0.1, 0.3], [-0.3, 0.3], [-0.3, -0.3], [0.1, -0.3]]", "{fp}"
    )
    a = profile_from_toml(base.format(fp="radius = 0.2"), "a")
    b = profile_from_toml(base.format(fp="footprint = {radius = 0.2}"), "b")
    assert a.footprint == b.footprint == Footprint.disc(0.2)
    assert a.d_robot_m == 0.4


def test_optional_keys():
    text = GOOD + "laser_pose = [0.2, 0.0, 3.14159]\nwheel_base = 0.45\nd_robot = 0.5\n"
    p = profile_from_toml(text, "x")
    assert p.laser_pose == (0.2, 0.0, 3.14159)
    assert (p.wheel_base_m, p.d_robot_m, p.r_max_m) == (0.45, 0.5, 1.2)


def _without(key: str) -> str:
    return "\n".join(line for line in GOOD.splitlines() if not line.startswith(f"{key} ="))


def _with(key: str, value: str) -> str:
    lines = [line for line in GOOD.splitlines() if not line.startswith(f"{key} =")]
    return "\n".join([*lines, f"{key} = {value}"])


@pytest.mark.parametrize(
    ("text", "key", "problem"),
    [
        *[(_without(k), k, "missing") for k in ("name", "v_max", "w_max", "a_max", "a_dec")],
        *[(_without(k), k, "missing") for k in ("alpha_max", "r_max", "source")],
        (_without("footprint"), "footprint", "missing"),
        (_with("v_max", '"fast"'), "v_max", "must be a number"),
        (_with("w_max", "true"), "w_max", "must be a number"),
        (_with("a_max", "nan"), "a_max", "finite"),
        (_with("a_dec", "inf"), "a_dec", "finite"),
        (_with("alpha_max", "-2.0"), "alpha_max", "positive"),
        (_with("v_max", "0"), "v_max", "positive"),
        (_with("r_max", "0.5"), "r_max", "must exceed d_robot"),
        (_with("vmax", "1.0"), "vmax", "unknown key"),
        (_with("name", "42"), "name", "must be"),
        (_with("name", '"two words"'), "name", "must be"),
        (_with("source", '""'), "source", "one non-empty line"),
        (_with("laser_pose", "[0.1, 0.2]"), "laser_pose", "[x, y, yaw]"),
        (
            _with("footprint", "[[0.3, 0.3], [-0.3, -0.3], [0.3, -0.3], [-0.3, 0.3]]"),
            "footprint",
            "self-intersecting",
        ),
        (_with("footprint", "[[0.0, 0.0], [0.02, 0.0], [0.0, 0.02]]"), "footprint", "too small"),
        (_with("footprint", "[[0.0, 0.0], [1.0, 0.0]]"), "footprint", "at least 3"),
        (_with("footprint", "[[0.0, 0.0], [1.0, 0.0], [1.0, nan]]"), "footprint", "finite"),
        (_with("footprint", '[[0.0, 0.0], [1.0, 0.0], [1.0, "y"]]'), "footprint", "numbers"),
        (_with("footprint", "0.3"), "footprint", "list of [x, y] pairs"),
        (_with("radius", "0.3"), "footprint", "not both"),
        (_without("footprint") + "\nradius = -0.3", "radius", "positive"),
        (_without("footprint") + "\nradius = 0.001", "radius", "out of range"),
        (_without("footprint") + '\nradius = "big"', "radius", "must be a number"),
        (GOOD + "\n[extra]\nx = 1\n", "extra", "unknown key or table"),
        ("name = 'x'\n", "name", "unknown key or table"),
        ("", "profile", "missing [profile] table"),
        ("[profile\nname =", "not valid TOML", ""),
    ],
)
def test_bad_files_are_one_line_naming_the_key(text, key, problem, tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(ProfileError) as err:
        load_profile(str(path))
    message = str(err.value)
    assert "\n" not in message
    assert message.startswith(f"profile {path}: ")
    assert f": {key}" in message or key in message
    assert problem in message


def test_bad_paths_and_names(tmp_path):
    with pytest.raises(ProfileError, match="file not found"):
        load_profile(str(tmp_path / "nope.toml"))
    with pytest.raises(ProfileError, match="is a directory"):
        load_profile(str(tmp_path) + "/")
    binary = tmp_path / "bin.toml"
    binary.write_bytes(b"\xff\xfe\x00garbage")
    with pytest.raises(ProfileError, match="not valid TOML"):
        load_profile(str(binary))
    with pytest.raises(ProfileError, match=r"unknown robot profile .roomba. \(known: husky"):
        load_profile("roomba")


def test_a_changed_file_is_read_again(tmp_path):
    path = tmp_path / "cart.toml"
    path.write_text(GOOD)
    assert load_profile(str(path)).v_max_mps == 0.5
    path.write_text(GOOD.replace("v_max = 0.5", "v_max = 0.25 "))
    assert load_profile(str(path)).v_max_mps == 0.25
