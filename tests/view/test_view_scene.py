"""The pure part of the operator view: geometry and styling computed from telemetry."""

from __future__ import annotations

import math

import numpy as np
import pytest
from egc_common.profiles import JACKAL, PIONEER3DX
from egc_operator.view_scene import (
    CIRCLE_NAMES,
    FALLBACK_HORIZON_S,
    REGION_COLOURS,
    ROBOT_TO_SCREEN,
    WORLD_TO_SCREEN,
    command_vector,
    drawable_circle,
    footprint_half_size,
    map_image,
    pose_moved,
    robot_frame_scene,
    status_changes,
    status_text,
    time_series,
)
from egc_robot.filters.egc import EgcParams, egc_filter, predicted_position

from tests.view.conftest import telemetry


def test_only_drawable_circles_are_drawn() -> None:
    assert drawable_circle((0.5, -0.25, 0.3)) == (0.5, -0.25, 0.3)
    assert drawable_circle(None) is None
    for bad in ((0.0, 0.0, 0.0), (0.0, 0.0, -1.0), (0.0, 0.0, math.nan), (math.inf, 0.0, 1.0)):
        assert drawable_circle(bad) is None


@pytest.mark.parametrize("profile", [PIONEER3DX, JACKAL])
def test_footprint_is_the_profiles_rectangle(profile) -> None:  # type: ignore[no-untyped-def]
    assert footprint_half_size(profile) == (profile.length_m / 2, profile.width_m / 2)


def test_operator_arrow_ends_at_the_initial_guide_circle_centre() -> None:
    """With the profile's default horizon the blue arrow's tip is the filter's P_IGC (eq. 6)."""
    p = PIONEER3DX
    params = EgcParams.from_profile(p.r_min_m, p.r_max_m, p.v_max_mps)
    v, w = 0.12, -0.3
    result = egc_filter(v, w, np.array([[0.8, -0.3], [1.5, 0.4]]), params)
    assert command_vector(v, w, p.horizon_s) == pytest.approx(result.p_igc)
    assert command_vector(v, w, p.horizon_s) == pytest.approx(predicted_position(v, w, p.horizon_s))


def test_robot_frame_scene_from_telemetry() -> None:
    t = telemetry(3)
    scene = robot_frame_scene(t)
    np.testing.assert_array_equal(scene.scan_xy, t.scan_xy)
    assert scene.footprint_half_size == footprint_half_size(PIONEER3DX)
    assert scene.region_colour == REGION_COLOURS["conditional"]
    assert scene.circles == {
        "reachable": (0.0, 0.0, t.r_rc),
        "igc": t.igc,
        "agc": t.agc,
        "egc": t.egc,
    }
    horizon = PIONEER3DX.horizon_s
    assert scene.reference_vector == pytest.approx(command_vector(t.v_ref, t.w_ref, horizon))
    assert scene.sent_vector == pytest.approx(command_vector(t.v_cmd, t.w_cmd, horizon))
    assert scene.status_anchor[0] < -PIONEER3DX.length_m / 2  # behind the robot


def test_absent_circles_and_unknown_profile() -> None:
    t = telemetry(1, igc=None, agc=None, egc=None, r_rc=0.0, profile="", region="weird")
    scene = robot_frame_scene(t)
    assert all(scene.circles[name] is None for name in CIRCLE_NAMES)
    assert scene.footprint_half_size is None
    assert scene.sent_vector == pytest.approx(command_vector(t.v_cmd, t.w_cmd, FALLBACK_HORIZON_S))


def test_status_text_names_the_limiter_and_region() -> None:
    assert status_text(telemetry(1, limiter="sweep", region="unsafe", w_si=0.0)) == (
        "DRIVING · shared · limit: footprint sweep · unsafe · w_SI 0.00"
    )
    assert "limit: e-stop" in status_text(telemetry(1, state="ESTOP", limiter="estop"))
    assert "limit: something_new" in status_text(telemetry(1, limiter="something_new"))
    still = telemetry(1, limiter="egc", v_ref=2.0, w_ref=0.0, v_cmd=0.0, w_cmd=0.0)
    assert "limit: EGC, stopped: ease off or steer away ·" in status_text(still)
    assert "stopped" not in status_text(telemetry(1, limiter="egc", v_cmd=0.05))


def test_time_series_follow_paper_fig_11_and_skip_unknown_ages() -> None:
    t = telemetry(2)
    assert time_series(t) == {
        "v/ref": t.v_ref,
        "v/cmd": t.v_cmd,
        "w/ref": t.w_ref,
        "w/cmd": t.w_cmd,
        "w_si": t.w_si,
        "latency/cmd_age_ms": 20.0,
        "latency/scan_age_ms": 30.0,
    }
    assert "latency/cmd_age_ms" not in time_series(telemetry(2, cmd_age_ms=None))


def test_status_changes_reports_only_what_changed() -> None:
    first = telemetry(1)
    assert status_changes(None, first) == {
        "state": "DRIVING",
        "mode": "shared",
        "filter": "unknown",  # the synthetic telemetry does not say (an older robot)
        "limiter": "egc",
        "region": "conditional",
    }
    assert status_changes(first, telemetry(2)) == {}
    assert status_changes(first, telemetry(2, filter="ek-egc")) == {"filter": "ek-egc"}
    assert status_changes(first, telemetry(2, state="HOLD", limiter="watchdog")) == {
        "state": "HOLD",
        "limiter": "watchdog",
    }


def test_trajectory_grows_by_steps() -> None:
    assert pose_moved(None, (0.0, 0.0, 0.0), 0.02)
    assert not pose_moved((0.0, 0.0), (0.01, 0.01, 1.0), 0.02)
    assert pose_moved((0.0, 0.0), (0.02, 0.0, 0.0), 0.02)


def _apply(mat: tuple[tuple[float, ...], ...], xy: tuple[float, float]) -> tuple[float, float]:
    m = np.array(mat)
    out = m @ np.array([xy[0], xy[1], 0.0])
    return float(out[0]), float(out[1])


def test_screen_transforms_show_forward_up_and_north_up() -> None:
    """Rerun's 2D views have +y down: forward must come out up, left out left."""
    assert _apply(ROBOT_TO_SCREEN, (1.0, 0.0)) == (0.0, -1.0)  # forward -> up
    assert _apply(ROBOT_TO_SCREEN, (0.0, 1.0)) == (-1.0, 0.0)  # left -> left
    assert _apply(WORLD_TO_SCREEN, (1.0, 0.0)) == (1.0, 0.0)  # east -> right
    assert _apply(WORLD_TO_SCREEN, (0.0, 1.0)) == (0.0, -1.0)  # north -> up


def test_map_image_places_cells_at_their_world_position() -> None:
    occ = np.zeros((4, 6), bool)
    occ[0, 0] = True  # top-left cell
    occ[3, 5] = True  # bottom-right cell
    image = map_image(occ, 0.5, (-1.0, 2.0))
    assert image.pixels.shape == (4, 6) and image.pixels.dtype == np.uint8
    assert image.pixels[0, 0] < image.pixels[1, 1]  # occupied is dark

    def world(col: float, row: float) -> tuple[float, float]:
        x, y = _apply(image.mat3x3, (col, row))
        return x + image.translation[0], y + image.translation[1]

    # Pixel (col, row) spans [col, col + 1] x [row, row + 1] in image space.
    assert world(0, 4) == pytest.approx((-1.0, 2.0))  # lower-left corner = origin
    assert world(6, 0) == pytest.approx((2.0, 4.0))  # upper-right corner
    assert world(0.5, 0.5) == pytest.approx((-0.75, 3.75))  # centre of the top-left cell


@pytest.mark.parametrize(
    ("occupancy", "resolution", "origin"),
    [
        (np.zeros((0, 3), bool), 0.1, (0.0, 0.0)),
        (np.zeros(5, bool), 0.1, (0.0, 0.0)),
        (np.zeros((2, 2), bool), 0.0, (0.0, 0.0)),
        (np.zeros((2, 2), bool), 0.1, (math.nan, 0.0)),
    ],
)
def test_map_image_rejects_bad_maps(occupancy, resolution, origin) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(ValueError):
        map_image(occupancy, resolution, origin)


def test_shapes_beyond_the_rectangle_are_drawn_as_given() -> None:
    """DESIGN 14: a disc or a polygon is drawn by its outline; a centred rectangle stays a box."""
    from egc_common.profiles import HUSKY, TURTLEBOT4
    from egc_operator.view_scene import footprint_corners

    from tests.shapes import PENTAGON

    round_scene = robot_frame_scene(telemetry(1, profile="turtlebot4"))
    assert round_scene.footprint_outline is not None
    assert np.allclose(np.hypot(*np.array(round_scene.footprint_outline).T), 0.171)
    assert robot_frame_scene(telemetry(1, profile="husky")).footprint_outline is None
    assert footprint_half_size(HUSKY) == (0.495, 0.335)
    corners = footprint_corners((1.0, 2.0, math.pi / 2), PENTAGON)
    assert corners[0] == pytest.approx((1.0, 2.35))  # the nose, turned to +y
    assert corners[0] == corners[-1] and len(corners) == 6
    assert len(footprint_corners((0.0, 0.0, 0.0), TURTLEBOT4)) == 33
