"""A Linux gamepad through evdev as a command source (DESIGN 4).

- **Calibration** from the device's absinfo: each axis is normalised from its [min, max] to
  [-1, 1] (``egc_common.joystick.normalise_axis``), then the deadzone is removed and the rest
  rescaled (``apply_deadzone``). The deadzone is the configured one (default 0.05) or the
  device's own ``flat`` band, whichever is larger.
- **Mapping**, configurable by evdev code name or number (``[joystick]`` table of the operator
  config, or ``--gamepad`` presets). Defaults for Xbox and PlayStation pads under the Linux
  gamepad API (xpad, xone, hid-playstation, hid-sony report the same codes by position):

  ============  ==============  =========================================================
  role          code            Xbox / PlayStation
  ============  ==============  =========================================================
  forward       ABS_Y inverted  left stick up
  turn          ABS_X inverted  left stick left
  deadman       BTN_TL          LB / L1, hold to drive; releasing it stops the robot
  mode toggle   BTN_SELECT      View (Back) / Share (Create): direct <-> shared
  e-stop        BTN_EAST        B / Circle
  reset         BTN_START       Menu (Start) / Options
  filter cycle  BTN_NORTH       Y / Triangle: next filter of shared mode (egc, ek-egc, assist,
                                dwa, then egc again); in direct mode it switches to shared
  via next      BTN_TR          RB / R1: skip the active via point
  via clear     BTN_WEST        X / Square: clear all via points
  next robot    ABS_HAT0X +1    D-pad right (DESIGN 15: the operator drives the next robot)
                BTN_DPAD_RIGHT  (the same, for drivers that report the D-pad as buttons)
  prev. robot   ABS_HAT0X -1    D-pad left; BTN_DPAD_LEFT
  ============  ==============  =========================================================

  The ``generic`` preset is for USB joysticks with BTN_TRIGGER-style buttons (trigger is the
  deadman, thumb the e-stop, thumb 2 cycles the filter, top skips a via point, top 2 clears
  them, base 3 and base 4 toggle the mode and reset, base 5 and base 6 or the hat switch the
robot). Some drivers report the Xbox X and Y
  buttons the other way round (``evtest`` shows the codes): swap ``filter_cycle`` and
  ``via_clear`` in the ``[joystick]`` table then.
- E-stop and reset are sent for at least ``latch_s`` after a press, so a tap survives a lost
  packet (the robot latches the e-stop itself, DESIGN 8).
- The filter pick is sent with every command (``JoystickSample.filter``; None until the first
  press unless a default is given: the robot's own default runs). ``via_next`` and
  ``via_clear`` read true while the button is held, and at least once after a press however
  short, so a tap between two samples is not lost; the operator node acts on the press edge.
  ``robot_next`` and ``robot_prev`` likewise (``robot_axis``, a hat, counts as pressed while it
  is pushed to that side).
- A device that disappears (unplugged: ``OSError``) reads as a centred stick with the deadman
  released, and the source tries to reopen it once a second.

The device object is duck-typed (``absinfo(code)``, ``read_one()``), so tests drive this class
with a fake device; ``open_device`` is the only function that touches ``evdev`` itself.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from typing import Any, Protocol

from egc_common.joystick import apply_deadzone, normalise_axis
from egc_common.joystick_file import SHARED_FILTERS, JoystickSample

log = logging.getLogger("egc.operator.joystick")

EV_KEY = 1
EV_ABS = 3

# Codes from linux/input-event-codes.h (used when python-evdev is not importable).
CODES: dict[str, int] = {
    "ABS_X": 0x00,
    "ABS_Y": 0x01,
    "ABS_Z": 0x02,
    "ABS_RX": 0x03,
    "ABS_RY": 0x04,
    "ABS_RZ": 0x05,
    "ABS_HAT0X": 0x10,
    "BTN_TRIGGER": 0x120,
    "BTN_THUMB": 0x121,
    "BTN_THUMB2": 0x122,
    "BTN_TOP": 0x123,
    "BTN_TOP2": 0x124,
    "BTN_PINKIE": 0x125,
    "BTN_BASE3": 0x128,
    "BTN_BASE4": 0x129,
    "BTN_BASE5": 0x12A,
    "BTN_BASE6": 0x12B,
    "BTN_SOUTH": 0x130,
    "BTN_EAST": 0x131,
    "BTN_NORTH": 0x133,
    "BTN_WEST": 0x134,
    "BTN_TL": 0x136,
    "BTN_TR": 0x137,
    "BTN_SELECT": 0x13A,
    "BTN_START": 0x13B,
    "BTN_MODE": 0x13C,
    "BTN_DPAD_LEFT": 0x222,
    "BTN_DPAD_RIGHT": 0x223,
}


def resolve_code(value: str | int) -> int:
    """An evdev code from a name (``"BTN_TL"``) or a number; ValueError if unknown."""
    if isinstance(value, int) and not isinstance(value, bool):
        if value < 0:
            raise ValueError(f"evdev code must be >= 0, got {value}")
        return value
    if isinstance(value, str):
        if value in CODES:
            return CODES[value]
        try:
            from evdev import ecodes

            code = ecodes.ecodes.get(value)
        except ImportError:
            code = None
        if isinstance(code, int):
            return code
    raise ValueError(f"unknown evdev code {value!r}")


@dataclass(frozen=True, slots=True)
class ButtonMap:
    forward_axis: int = CODES["ABS_Y"]
    forward_invert: bool = True
    turn_axis: int = CODES["ABS_X"]
    turn_invert: bool = True
    deadman: int = CODES["BTN_TL"]
    mode_toggle: int = CODES["BTN_SELECT"]
    estop: int = CODES["BTN_EAST"]
    reset: int = CODES["BTN_START"]
    filter_cycle: int = CODES["BTN_NORTH"]
    via_next: int = CODES["BTN_TR"]
    via_clear: int = CODES["BTN_WEST"]
    robot_next: int = CODES["BTN_DPAD_RIGHT"]
    robot_prev: int = CODES["BTN_DPAD_LEFT"]
    robot_axis: int = CODES["ABS_HAT0X"]  # a hat: +1 next robot, -1 previous

    @staticmethod
    def from_table(table: Mapping[str, Any], base: ButtonMap | None = None) -> ButtonMap:
        """Override a preset with a ``[joystick]`` table (codes by name or number)."""
        changes: dict[str, Any] = {}
        for key, value in table.items():
            if key in ("forward_invert", "turn_invert"):
                if not isinstance(value, bool):
                    raise ValueError(f"joystick.{key} must be true or false")
                changes[key] = value
            elif key in ButtonMap.__dataclass_fields__:
                changes[key] = resolve_code(value)
            else:
                raise ValueError(f"unknown joystick key {key!r}")
        return replace(base or ButtonMap(), **changes)


PRESETS: dict[str, ButtonMap] = {
    "xbox": ButtonMap(),
    "ps": ButtonMap(),
    "generic": ButtonMap(
        deadman=CODES["BTN_TRIGGER"],
        estop=CODES["BTN_THUMB"],
        mode_toggle=CODES["BTN_BASE3"],
        reset=CODES["BTN_BASE4"],
        filter_cycle=CODES["BTN_THUMB2"],
        via_next=CODES["BTN_TOP"],
        via_clear=CODES["BTN_TOP2"],
        robot_next=CODES["BTN_BASE6"],
        robot_prev=CODES["BTN_BASE5"],
    ),
}


class Device(Protocol):
    def absinfo(self, axis_num: int) -> Any: ...
    def read_one(self) -> Any: ...


@dataclass(frozen=True, slots=True)
class AxisCalibration:
    raw_min: float
    raw_max: float
    deadzone: float

    @staticmethod
    def from_absinfo(info: Any, deadzone: float) -> AxisCalibration:
        """``info`` has evdev's AbsInfo fields (value, min, max, fuzz, flat, resolution)."""
        lo, hi = float(info.min), float(info.max)
        if not hi > lo:
            raise ValueError(f"axis range [{lo}, {hi}] is empty")
        flat = 2.0 * float(getattr(info, "flat", 0) or 0) / (hi - lo)
        return AxisCalibration(lo, hi, min(max(deadzone, flat), 0.5))

    def normalise(self, raw: float) -> float:
        return apply_deadzone(normalise_axis(raw, self.raw_min, self.raw_max), self.deadzone)


class EvdevJoystick:
    """Turns evdev events into samples (see the module docstring)."""

    def __init__(
        self,
        device: Device,
        mapping: ButtonMap = PRESETS["xbox"],
        deadzone: float = 0.05,
        mode: str = "shared",
        latch_s: float = 0.5,
        reopen: Callable[[], Device] | None = None,
        filter: str | None = None,
    ) -> None:
        if filter is not None and filter not in SHARED_FILTERS:
            raise ValueError(f"filter must be one of {', '.join(SHARED_FILTERS)}, got {filter!r}")
        self._mapping = mapping
        self._filter = filter
        self._via_next_pending = False
        self._via_clear_pending = False
        self._robot_pending = {"next": False, "prev": False}
        self._hat = 0  # the robot_axis hat's position: -1, 0, +1
        self._deadzone = deadzone
        self._latch_s = latch_s
        self._reopen = reopen
        self._mode = mode
        self._pressed: set[int] = set()
        self._estop_until = -1.0
        self._reset_until = -1.0
        self._device: Device | None = None
        self._retry_at = 0.0
        self._attach(device)

    def _attach(self, device: Device) -> None:
        m = self._mapping
        self._cal = {
            axis: AxisCalibration.from_absinfo(device.absinfo(axis), self._deadzone)
            for axis in (m.forward_axis, m.turn_axis)
        }
        self._raw = {axis: float(device.absinfo(axis).value) for axis in self._cal}
        self._pressed.clear()
        self._hat = 0
        self._device = device

    @property
    def finished(self) -> bool:
        return False

    def sample(self, t_s: float) -> JoystickSample:
        if self._device is None:
            self._try_reopen(t_s)
        if self._device is not None:
            try:
                self._drain(t_s)
            except OSError as exc:
                log.warning("joystick lost (%s): stick released until it is back", exc)
                self._device = None
                self._pressed.clear()
                self._retry_at = t_s + 1.0
        m = self._mapping
        if self._device is None:
            self._via_next_pending = self._via_clear_pending = False
            self._robot_pending = {"next": False, "prev": False}
            self._hat = 0
            return JoystickSample(
                t_s, 0.0, 0.0, deadman=False, mode=self._mode, filter=self._filter
            )
        x = self._cal[m.forward_axis].normalise(self._raw[m.forward_axis])
        y = self._cal[m.turn_axis].normalise(self._raw[m.turn_axis])
        via_next = self._via_next_pending or m.via_next in self._pressed
        via_clear = self._via_clear_pending or m.via_clear in self._pressed
        self._via_next_pending = self._via_clear_pending = False
        robot_next = self._robot_pending["next"] or self._hat > 0 or m.robot_next in self._pressed
        robot_prev = self._robot_pending["prev"] or self._hat < 0 or m.robot_prev in self._pressed
        self._robot_pending = {"next": False, "prev": False}
        return JoystickSample(
            t_s,
            -x if m.forward_invert else x,
            -y if m.turn_invert else y,
            deadman=m.deadman in self._pressed,
            mode=self._mode,
            estop=t_s <= self._estop_until or m.estop in self._pressed,
            reset=t_s <= self._reset_until or m.reset in self._pressed,
            filter=self._filter,
            via_next=via_next,
            via_clear=via_clear,
            robot_next=robot_next,
            robot_prev=robot_prev,
        )

    def _drain(self, t_s: float) -> None:
        assert self._device is not None
        m = self._mapping
        while (event := self._device.read_one()) is not None:
            if event.type == EV_ABS and event.code in self._raw:
                self._raw[event.code] = float(event.value)
            elif event.type == EV_ABS and event.code == m.robot_axis:
                hat = (event.value > 0) - (event.value < 0)
                if hat and hat != self._hat:  # pushed to a side: a press, however short
                    self._robot_pending["next" if hat > 0 else "prev"] = True
                self._hat = hat
            elif event.type == EV_KEY:
                if event.value == 0:
                    self._pressed.discard(event.code)
                    continue
                if event.value != 1 or event.code in self._pressed:
                    continue  # 2 is auto-repeat
                self._pressed.add(event.code)
                if event.code == m.mode_toggle:
                    self._mode = "direct" if self._mode == "shared" else "shared"
                    log.info("mode: %s", self._mode)
                elif event.code == m.estop:
                    self._estop_until = t_s + self._latch_s
                elif event.code == m.reset:
                    self._reset_until = t_s + self._latch_s
                elif event.code == m.filter_cycle:
                    self._cycle_filter()
                elif event.code == m.via_next:
                    self._via_next_pending = True
                elif event.code == m.via_clear:
                    self._via_clear_pending = True
                elif event.code == m.robot_next:
                    self._robot_pending["next"] = True
                elif event.code == m.robot_prev:
                    self._robot_pending["prev"] = True

    def _cycle_filter(self) -> None:
        """The next filter of shared mode; from direct mode, shared mode with the current pick."""
        if self._mode == "direct":
            self._mode = "shared"
            self._filter = self._filter or SHARED_FILTERS[0]
        elif self._filter is None:
            self._filter = SHARED_FILTERS[0]
        else:
            i = SHARED_FILTERS.index(self._filter)
            self._filter = SHARED_FILTERS[(i + 1) % len(SHARED_FILTERS)]
        log.info("mode: %s, filter %s", self._mode, self._filter)

    def _try_reopen(self, t_s: float) -> None:
        if self._reopen is None or t_s < self._retry_at:
            return
        self._retry_at = t_s + 1.0
        try:
            self._attach(self._reopen())
            log.info("joystick back")
        except OSError:
            pass

    def close(self) -> None:
        close = getattr(self._device, "close", None)
        if callable(close):
            close()


def open_device(path: str, mapping: ButtonMap) -> Device:
    """Open an evdev device and check that it has the mapped axes (clear ValueError if not)."""
    try:
        import evdev
    except ImportError:
        raise ValueError("--joystick needs python-evdev (Linux only)") from None
    try:
        device = evdev.InputDevice(path)
    except OSError as exc:
        raise ValueError(f"cannot open joystick {path}: {exc.strerror}") from None
    axes = set(device.capabilities(absinfo=False).get(EV_ABS, []))
    missing = [a for a in (mapping.forward_axis, mapping.turn_axis) if a not in axes]
    if missing:
        device.close()
        raise ValueError(f"{path} ({device.name}) lacks the mapped axes {missing}")
    result: Device = device
    return result
