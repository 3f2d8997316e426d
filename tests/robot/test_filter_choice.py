"""The operator picks the shared-mode filter at run time (DESIGN 6, OperatorCommand ``filter``)."""

from __future__ import annotations

import pytest
from egc_common.profiles import get_profile
from egc_robot.controller import ControllerConfig, RobotController
from egc_robot.filters.family import SHARED_FILTERS, available_filters
from egc_robot.pipeline import PipelineConfig

from tests.robot.test_controller import T0, Rig, open_scan, raw

RUNNABLE = [name for name in available_filters() if name != "none"]


@pytest.mark.parametrize("name", RUNNABLE)
def test_the_operators_pick_runs_and_telemetry_names_it(name: str) -> None:
    rig = Rig()
    rig.send(0.0, 0.0, filter=name)
    rig.cycle()
    rig.send(0.5, 0.0, filter=name)
    out = rig.cycle()
    assert out.telemetry.state == "DRIVING"
    assert out.telemetry.filter == name
    assert out.result is not None and out.result.filter_name == name


def test_without_a_pick_the_robot_runs_its_own_and_direct_mode_runs_none() -> None:
    rig = Rig()
    rig.send(0.0, 0.0)
    rig.cycle()
    rig.send(0.5, 0.0)
    assert rig.cycle().telemetry.filter == "egc"
    rig.send(0.5, 0.0, mode="direct", filter="egc")
    assert rig.cycle().telemetry.filter == "none"


def test_a_robot_configured_without_a_filter_ignores_the_pick() -> None:
    cfg = ControllerConfig(PipelineConfig(get_profile("pioneer3dx"), filter="none"))
    c = RobotController(cfg, T0)
    now = T0
    for seq, x in ((1, 0.0), (2, 0.5)):
        c.on_command(raw(seq, now, x=x, filter="egc"), now)
        now += 20_000_000
        c.on_scan(open_scan(), now)
        out = c.step(now)
    assert out.telemetry.filter == "none"


def test_an_unknown_filter_name_is_rejected_on_the_wire() -> None:
    rig = Rig()
    verdict = rig.send(0.0, 0.0, filter="teleport")
    assert verdict.rejection is not None and verdict.rejection.reason.value == "out_of_range"


def test_every_shared_filter_name_is_pinned() -> None:
    assert SHARED_FILTERS == ("egc", "ek-egc", "assist", "dwa", "cbf")
