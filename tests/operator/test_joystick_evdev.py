"""The evdev source against a fake device (the hardware is the only thing mocked)."""

from __future__ import annotations

from dataclasses import dataclass

import pytest
from egc_operator.joystick_evdev import (
    CODES,
    EV_ABS,
    EV_KEY,
    PRESETS,
    AxisCalibration,
    ButtonMap,
    EvdevJoystick,
    resolve_code,
)

ABS_X, ABS_Y = CODES["ABS_X"], CODES["ABS_Y"]
BTN_TL, BTN_EAST, BTN_SELECT = CODES["BTN_TL"], CODES["BTN_EAST"], CODES["BTN_SELECT"]


@dataclass
class AbsInfo:
    value: int
    min: int
    max: int
    fuzz: int = 0
    flat: int = 0
    resolution: int = 0


@dataclass
class Event:
    type: int
    code: int
    value: int


class FakePad:
    """An Xbox-like pad: axes -32768..32767, or a PlayStation-like one: 0..255."""

    def __init__(self, lo: int = -32768, hi: int = 32767, rest: int = 0, flat: int = 0):
        self.info = {a: AbsInfo(rest, lo, hi, flat=flat) for a in (ABS_X, ABS_Y)}
        self.queue: list[Event] = []
        self.unplugged = False

    def absinfo(self, code: int) -> AbsInfo:
        return self.info[code]

    def read_one(self) -> Event | None:
        if self.unplugged:
            raise OSError(19, "No such device")
        return self.queue.pop(0) if self.queue else None

    def push(self, *events: tuple[int, int, int]) -> None:
        self.queue += [Event(*e) for e in events]


def test_calibration_from_absinfo_full_forward_and_left():
    pad = FakePad()
    js = EvdevJoystick(pad)
    pad.push((EV_ABS, ABS_Y, -32768), (EV_ABS, ABS_X, -32768), (EV_KEY, BTN_TL, 1))
    s = js.sample(0.0)
    assert (s.x, s.y, s.deadman) == (1.0, 1.0, True)  # stick up = forward, left = +y


def test_playstation_range_centre_reads_zero_and_deadzone_applies():
    pad = FakePad(lo=0, hi=255, rest=128)
    js = EvdevJoystick(pad, deadzone=0.05)
    assert js.sample(0.0).x == 0.0
    pad.push((EV_ABS, ABS_Y, 124))  # 3 % deflection: inside the deadzone
    assert js.sample(0.1).x == 0.0
    pad.push((EV_ABS, ABS_Y, 0))
    assert js.sample(0.2).x == 1.0


def test_device_flat_band_widens_the_deadzone():
    cal = AxisCalibration.from_absinfo(AbsInfo(0, -100, 100, flat=20), deadzone=0.05)
    assert cal.deadzone == pytest.approx(0.2)
    assert cal.normalise(15) == 0.0
    assert cal.normalise(100) == 1.0


def test_deadman_release_and_mode_toggle_on_press_edges_only():
    pad = FakePad()
    js = EvdevJoystick(pad)
    pad.push((EV_KEY, BTN_TL, 1))
    assert js.sample(0.0).deadman
    pad.push((EV_KEY, BTN_SELECT, 1), (EV_KEY, BTN_SELECT, 2), (EV_KEY, BTN_SELECT, 0))
    assert js.sample(0.1).mode == "direct"  # auto-repeat (2) does not toggle back
    pad.push((EV_KEY, BTN_SELECT, 1), (EV_KEY, BTN_TL, 0))
    s = js.sample(0.2)
    assert s.mode == "shared" and not s.deadman


def test_estop_tap_is_held_for_the_latch_time():
    pad = FakePad()
    js = EvdevJoystick(pad, latch_s=0.5)
    pad.push((EV_KEY, BTN_EAST, 1), (EV_KEY, BTN_EAST, 0))
    assert js.sample(1.0).estop
    assert js.sample(1.4).estop
    assert not js.sample(1.6).estop


def test_unplugged_device_reads_released_and_comes_back():
    pad = FakePad()
    fresh = FakePad()
    js = EvdevJoystick(pad, reopen=lambda: fresh)
    pad.push((EV_KEY, BTN_TL, 1), (EV_ABS, ABS_Y, -32768))
    assert js.sample(0.0).deadman
    pad.unplugged = True
    s = js.sample(0.1)
    assert (s.x, s.y, s.deadman) == (0.0, 0.0, False)
    fresh.push((EV_KEY, BTN_TL, 1))
    assert not js.sample(0.5).deadman  # retried after 1 s, not before
    assert js.sample(1.2).deadman


def test_mapping_from_a_config_table():
    m = ButtonMap.from_table({"deadman": "BTN_TR", "turn_axis": 3, "turn_invert": False})
    assert (m.deadman, m.turn_axis, m.turn_invert) == (CODES["BTN_TR"], 3, False)
    assert PRESETS["generic"].deadman == CODES["BTN_TRIGGER"]
    assert resolve_code("BTN_DPAD_UP") == 0x220  # any evdev name, via python-evdev
    with pytest.raises(ValueError):
        ButtonMap.from_table({"deadmen": "BTN_TL"})
    with pytest.raises(ValueError):
        resolve_code("BTN_NOPE")


BTN_NORTH, BTN_WEST, BTN_TR = CODES["BTN_NORTH"], CODES["BTN_WEST"], CODES["BTN_TR"]


def test_filter_button_cycles_the_shared_filters_in_design_order(caplog):
    pad = FakePad()
    js = EvdevJoystick(pad)
    assert js.sample(0.0).filter is None  # no pick: the robot runs its default
    picks = []
    with caplog.at_level("INFO", logger="egc.operator.joystick"):
        for i in range(6):
            pad.push((EV_KEY, BTN_NORTH, 1), (EV_KEY, BTN_NORTH, 2), (EV_KEY, BTN_NORTH, 0))
            picks.append(js.sample(0.1 * (i + 1)).filter)
    # FILTER_NAMES without "none", then round again
    assert picks == ["egc", "ek-egc", "assist", "dwa", "cbf", "egc"]
    assert "filter ek-egc" in caplog.text  # each pick is logged


def test_filter_button_starts_from_the_given_default_and_leaves_direct_mode():
    pad = FakePad()
    js = EvdevJoystick(pad, mode="direct", filter="assist")
    s = js.sample(0.0)
    assert (s.mode, s.filter) == ("direct", "assist")
    pad.push((EV_KEY, BTN_NORTH, 1), (EV_KEY, BTN_NORTH, 0))
    s = js.sample(0.1)
    assert (s.mode, s.filter) == ("shared", "assist")  # first press: that filter, shared mode
    pad.push((EV_KEY, BTN_NORTH, 1), (EV_KEY, BTN_NORTH, 0))
    assert js.sample(0.2).filter == "dwa"
    with pytest.raises(ValueError, match="filter must be one of"):
        EvdevJoystick(FakePad(), filter="none")


def test_via_buttons_read_true_while_held_and_a_short_tap_is_not_lost():
    pad = FakePad()
    js = EvdevJoystick(pad)
    pad.push((EV_KEY, BTN_TR, 1))
    assert js.sample(0.0).via_next and js.sample(0.02).via_next  # held
    pad.push((EV_KEY, BTN_TR, 0))
    assert not js.sample(0.04).via_next
    pad.push((EV_KEY, BTN_WEST, 1), (EV_KEY, BTN_WEST, 0))  # press and release between samples
    s = js.sample(0.06)
    assert s.via_clear and not s.via_next
    assert not js.sample(0.08).via_clear  # once, then released


def test_via_and_filter_buttons_in_presets_and_config_table():
    xbox = PRESETS["xbox"]
    assert (xbox.filter_cycle, xbox.via_next, xbox.via_clear) == (BTN_NORTH, BTN_TR, BTN_WEST)
    assert PRESETS["ps"] == xbox  # the Linux gamepad API reports the same codes by position
    for name, preset in PRESETS.items():
        buttons = [
            preset.deadman,
            preset.mode_toggle,
            preset.estop,
            preset.reset,
            preset.filter_cycle,
            preset.via_next,
            preset.via_clear,
        ]
        assert len(set(buttons)) == len(buttons), name  # no button does two things
    m = ButtonMap.from_table({"filter_cycle": "BTN_WEST", "via_clear": "BTN_NORTH"})
    assert (m.filter_cycle, m.via_clear) == (BTN_WEST, BTN_NORTH)
    pad = FakePad()
    js = EvdevJoystick(pad, PRESETS["generic"])
    pad.push((EV_KEY, CODES["BTN_THUMB2"], 1), (EV_KEY, CODES["BTN_TOP"], 1))
    s = js.sample(0.0)
    assert s.filter == "egc" and s.via_next


def test_an_unplugged_pad_keeps_its_filter_pick():
    pad = FakePad()
    js = EvdevJoystick(pad, filter="dwa")
    pad.unplugged = True
    s = js.sample(0.0)
    assert (s.deadman, s.filter, s.via_next) == (False, "dwa", False)


def test_the_d_pad_switches_robots_as_a_hat_or_as_buttons():
    """DESIGN 15: D-pad right/left (a hat on xpad and hid-playstation, buttons on others)
    read as robot_next/robot_prev while held, and at least once after a tap."""
    hat = CODES["ABS_HAT0X"]
    pad = FakePad()
    js = EvdevJoystick(pad)
    pad.push((EV_ABS, hat, 1))
    assert js.sample(0.0).robot_next and js.sample(0.02).robot_next  # held right
    pad.push((EV_ABS, hat, 0), (EV_ABS, hat, -1), (EV_ABS, hat, 0))  # a tap left between samples
    s = js.sample(0.04)
    assert s.robot_prev and not s.robot_next
    assert not js.sample(0.06).robot_prev
    pad.push((EV_KEY, CODES["BTN_DPAD_RIGHT"], 1), (EV_KEY, CODES["BTN_DPAD_RIGHT"], 0))
    assert js.sample(0.08).robot_next
    generic = PRESETS["generic"]
    assert (generic.robot_next, generic.robot_prev) == (CODES["BTN_BASE6"], CODES["BTN_BASE5"])
    assert ButtonMap.from_table({"robot_next": "BTN_SOUTH"}).robot_next == CODES["BTN_SOUTH"]
