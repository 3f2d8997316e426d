"""deploy/: every Zenoh file loads through the transport adapter, and the TOML files are the
robot's and operator's real parameters (an unknown key fails loudly, so these stay in sync)."""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

import pytest
from egc_common import config as config_mod
from egc_common.errors import UsageError
from egc_common.profiles import get_profile
from egc_common.transport import LEASE_MS, ZenohOptions, build_config
from egc_operator.cli import JOYSTICK_KEYS, OPERATOR_KEYS
from egc_operator.joystick_evdev import ButtonMap
from egc_robot.controller import ControllerConfig
from egc_robot.pipeline import PipelineConfig

from egc_app.robot_cmd import ROBOT_TABLES, build_controller_config, resume_window_caveat

DEPLOY = Path(__file__).resolve().parents[2] / "deploy"


@pytest.mark.parametrize("name", sorted(p.name for p in DEPLOY.glob("*.json5")))
def test_zenoh_files_load_with_the_2s_lease(name):
    config = build_config(ZenohOptions(config_file=str(DEPLOY / name)))
    assert config.get_json("transport/link/tx/lease") == "2000"
    assert config.get_json("scouting/multicast/enabled") == "false"


def test_robot_toml_matches_the_defaults():
    cfg = config_mod.load(DEPLOY / "robot.toml", tables=ROBOT_TABLES)
    args = argparse.Namespace(profile="pioneer3dx", filter="egc", rate_hz=None)
    c = build_controller_config(args, cfg)
    assert (c.max_command_age_s, c.command_timeout_s, c.scan_timeout_s) == (0.3, 0.25, 0.2)
    assert c.nominal_period_s == pytest.approx(0.05)
    defaults = ControllerConfig(c.pipeline)
    for name in ("link_aware", "resume_window_s", "reaction_time_s", "latency_turn_cap"):
        assert getattr(c, name) == getattr(defaults, name)
    assert (c.blind_time_direct_s, c.blind_time_filtered_s) == (0.5, 1.0)


def test_no_return_is_free_follows_each_scan_unless_set(tmp_path):
    """Outside check: `robot --driver sim` read the simulator's lidar (no return = +inf, free)
    as unknown, so in a room larger than the laser's reach the robot stood still, "EGC
    stopped"; unset, the setting now follows each scan's own declaration."""
    args = argparse.Namespace(profile="jackal", filter="egc", rate_hz=None, driver="sim")
    unset = build_controller_config(args, config_mod.load(None))
    assert unset.pipeline.no_return_is_free is False
    assert unset.pipeline_if_free is not None and unset.pipeline_if_free.no_return_is_free
    assert unset.pipeline_if_free.settings.dwa.no_return_is_free
    assert unset.pipeline_if_free.settings.assist.no_return_is_free
    for value in (False, True):
        forced = build_controller_config(
            args, config_mod.load(None, [f"pipeline.no_return_is_free={str(value).lower()}"])
        )
        assert forced.pipeline.no_return_is_free is value and forced.pipeline_if_free is None


def test_robot_config_switches_the_turn_cap_off(tmp_path):
    path = tmp_path / "robot.toml"
    path.write_text("[link]\nlatency_turn_cap = false\n")
    args = argparse.Namespace(profile="jackal", filter="none", rate_hz=None)
    assert build_controller_config(args, config_mod.load(path)).latency_turn_cap is False
    path.write_text("[link]\nlatency_turn_cap = 0\n")
    with pytest.raises(UsageError, match="latency_turn_cap must be true or false"):
        build_controller_config(args, config_mod.load(path))


@pytest.mark.parametrize("key", ["pipeline.no_return_is_free", "safety.require_clock_sync"])
@pytest.mark.parametrize("text", ["False", '"false"', "0", '"no"'])
def test_true_or_false_settings_take_nothing_else(key, text):
    """Outside check: bool() made 'False' and "false" true, and so a scan that saw nothing
    counted as free space (the robot drove 143 of 315 cycles where it must stop)."""
    args = argparse.Namespace(profile="pioneer3dx", filter="egc", rate_hz=None)
    with pytest.raises(UsageError, match="must be true or false"):
        build_controller_config(args, config_mod.load(None, [f"{key}={text}"]))
    table, name = key.split(".")
    off = build_controller_config(args, config_mod.load(None, [f"{key}=false"]))
    on = build_controller_config(args, config_mod.load(None, [f"{key}=true"]))
    where = (lambda c: c.pipeline) if table == "pipeline" else (lambda c: c)
    assert (getattr(where(off), name), getattr(where(on), name)) == (False, True)


@pytest.mark.parametrize(
    "override", ["saftey.command_timeout_s=0.1", "command_timeout_s=0.1", "nosuch.key=3"]
)
def test_a_misspelt_or_missing_table_fails_loudly(override):
    with pytest.raises(config_mod.ConfigError, match="unknown config table"):
        config_mod.load(None, [override], ROBOT_TABLES)


def test_operator_toml_is_the_default_mapping():
    cfg = config_mod.load(DEPLOY / "operator.toml", tables=("operator", "joystick"))
    config_mod.section(cfg, "operator", OPERATOR_KEYS)
    table = config_mod.section(cfg, "joystick", JOYSTICK_KEYS)
    assert ButtonMap.from_table(table) == ButtonMap()


@pytest.mark.parametrize(
    "override",
    [
        "safety.max_command_age_s=1e300",  # overflowed the ns conversion: a traceback, a hang
        "safety.release_timeout_s=1e300",
        "safety.command_timeout_s=1e308",  # started, then every cycle failed (tau inf)
        "robot.telemetry_scan_decimation=inf",
        "pipeline.gamma_v=nan",
    ],
)
def test_absurd_numbers_are_one_clear_error(override):
    args = argparse.Namespace(profile="pioneer3dx", filter="egc", rate_hz=None)
    with pytest.raises(UsageError):
        build_controller_config(args, config_mod.load(None, [override]))


def test_a_resume_window_beyond_the_session_limits_is_named_at_start():
    # An outside check: resume_window_s = 3 did nothing beyond 2 s, silently (the lease and
    # release_timeout end the operator's session first).
    defaults = ControllerConfig(PipelineConfig(get_profile("pioneer3dx")))
    assert resume_window_caveat(defaults, LEASE_MS) is None  # 2 s = 2 s = 2 s, on purpose
    longer = dataclasses.replace(defaults, resume_window_s=3.0)
    text = resume_window_caveat(longer, LEASE_MS)
    assert text is not None and "safety.release_timeout_s 2 s" in text and "--lease-ms" in text
    released_later = dataclasses.replace(longer, release_timeout_s=4.0)
    assert "the Zenoh lease (--lease-ms) 2.5 s" in (
        resume_window_caveat(released_later, 2500) or ""
    )
    assert resume_window_caveat(released_later, 4000) is None
    assert resume_window_caveat(released_later, None) is None  # lease unknown: a config file
    assert resume_window_caveat(dataclasses.replace(longer, link_aware=False), 2000) is None


def test_the_cbf_table_sets_cbf_over_the_profiles_defaults(tmp_path):
    """DESIGN 13: ``[cbf]`` in the robot TOML (and ``--set cbf.KEY=VALUE``); the control period
    follows the robot's rate; a bad key or value is one line."""
    path = tmp_path / "robot.toml"
    path.write_text("[robot]\nrate_hz = 25\n[cbf]\nalpha_per_s = 6\nweight_w = 2.0\n")
    args = argparse.Namespace(profile="jackal", filter="cbf", rate_hz=None)
    cbf = build_controller_config(args, config_mod.load(path)).pipeline.settings.cbf
    assert cbf is not None
    assert (cbf.alpha_per_s, cbf.weight_w, cbf.margin_m) == (6.0, 2.0, pytest.approx(0.12))
    assert cbf.period_s == pytest.approx(0.04)
    over = config_mod.load(path, ["cbf.margin_m=0.2"])
    assert build_controller_config(args, over).pipeline.settings.cbf.margin_m == 0.2
    for bad in ("[cbf]\nalpha = 6\n", "[cbf]\nalpha_per_s = -1\n", "cbf = 3\n"):
        path.write_text(bad)
        with pytest.raises(UsageError, match="cbf"):
            build_controller_config(args, config_mod.load(path))
