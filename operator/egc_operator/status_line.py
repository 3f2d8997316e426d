"""The operator's one-line terminal status: what the robot does and why, then the link in numbers.

The line starts with the situation in an operator's words (``situation``): why the robot holds
and what to do about it, or why it is slowed, e.g. ``HOLD: link gap (no command for 0.4 s) -
keep the stick, it resumes`` or ``SLOWED: link delay 1.3 s -> speed capped at 0.10 m/s``. Then
the link figures (``link_figures``: clock-sync round trip, the robot's command age p50/p90, the
largest gap between commands, the loss), then w_SI, rejections, mode with the filter that runs
(``shared (ek-egc)``, from telemetry ``filter``), the via points, deadman and control.
The view plane (DESIGN 12, ``view_plane_text``) says what the link carries and what the robot's
downlink budget cut: ``camera 2 fps, scan 90 beams: the link carries 190 kbit/s``.
A robot with command sources (DESIGN 14) says which one drives and which lock holds
(``source nav``, ``LOCKED by pause (true)``), and an operator whose control another operator of
higher priority took is told who (``TAKEN OVER: supervisor took control``; ``Episode`` keeps the
robot's last handover of control).
Every telemetry figure may be unknown (None: an older robot, or none measured yet); unknown
figures are left out.

The line never passes off old or refused data as current: no telemetry accepted since the
robot appeared (or none fresh) says NO TELEMETRY, naming the robot's messages that were
rejected, with their reason, when there are any; a state message older than
``STATE_STALE_S`` is not shown; messages refused lately are counted on the line even while
valid telemetry comes (``Rejections``); the clock is "not synced", with why, while the clock
replies disagree (``ClockSync.note``).

On a terminal the line is redrawn in place a few times a second, cut to the terminal's width
so that it never wraps. When stdout is not a TTY (a log file, a pipe, CI) the same text is
printed as plain lines, only when the robot's state or reason, the latency cap or the control
situation changes and otherwise at most every ``plain_period_s``, so logs stay readable.

An operator driving a fleet (DESIGN 15) gives the line its ``fleet`` part: the driven robot
first, in brackets, and the others with their state at the end (``[r2] ... | fleet: r1 HOLD,
r3 IDLE``); a change there (a switch, another robot's state) prints a plain line too.
``say`` prints a line of its own (a robot listing) without garbling the redrawn one.
"""

from __future__ import annotations

import shutil
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from typing import TextIO

from egc_common.messages import FILTER_NAMES, OperatorCommand, StateMessage, Telemetry

# DESIGN 8 defaults, as the operator cannot read the robot's configuration.
RESUME_WINDOW_S = 2.0
# Telemetry comes every control cycle (20 Hz and more); older than this, the robot is silent.
TELEMETRY_STALE_S = 0.5
# The robot sends its state on change and at 1 Hz (DESIGN 7); older than this, it is not shown.
STATE_STALE_S = 2.5
# Refused messages are said on the line for this long after the last one.
REJECTIONS_SHOWN_S = 2.0
# A telemetry stamp this far behind the newest one is a robot clock that jumped, not a late one.
EPISODE_CLOCK_JUMP_NS = 10_000_000_000
MAX_COMMAND_AGE_MS = {"direct": 300, "shared": 1000}
COMMAND_TIMEOUT_MS = 250.0  # DESIGN 8: a gap shorter than this cannot have tripped the watchdog
# "ramping up" after a short-gap resume: said this long at most (the robot keeps the reason
# while it drives on), and no longer once the robot's speed has reached its reference since the
# resume (``Episode.reached_ref``). A ``limits`` limiter later on is not the resume's ramp (an
# acceleration after an EGC slowdown looks the same), so it does not stretch the text.
RAMP_SHOWN_S = 1.5
# |v_cmd| within this of |v_ref| (m/s): the ramp is done.
RAMP_DONE_MPS = 0.02
# Telemetry limiter values that name the filter of DESIGN 6 that changed the command.
FILTER_LIMITERS = frozenset(name for name in FILTER_NAMES if name != "none")
# ... and those that mean an obstacle changed it: a filter or the footprint sweep.
OBSTACLE_LIMITERS = FILTER_LIMITERS | {"sweep"}


@dataclass(frozen=True, slots=True)
class RecentRejections:
    """The robot's messages this operator refused lately (``Rejections.recent``)."""

    count: int  # refused in the last REJECTIONS_SHOWN_S (1-2 s of counts, see ``Rejections``)
    telemetry: int  # ... of them telemetry
    what: str  # the most frequent kind and reason lately, with the newest detail of it
    total: int  # refused since the start


class Rejections:
    """Counts the robot's messages that this operator refused, by kind and reason (DESIGN 7:
    "rejects with a counted, logged reason"). Not thread-safe; times are passed in.

    ``recent`` counts in whole periods of ``REJECTIONS_SHOWN_S / 2``: the current one and the
    one before it."""

    def __init__(self, period_ns: int = int(REJECTIONS_SHOWN_S / 2 * 1e9)) -> None:
        self._period_ns = period_ns
        self.by_reason: Counter[tuple[str, str]] = Counter()  # (kind, reason) -> count
        self.total = 0
        self._detail: dict[tuple[str, str], str] = {}
        self._bucket_ns: int | None = None  # start of the current period
        self._current: Counter[tuple[str, str]] = Counter()
        self._previous: Counter[tuple[str, str]] = Counter()

    def _roll(self, now_ns: int) -> None:
        if self._bucket_ns is None:
            self._bucket_ns = now_ns
            return
        elapsed = now_ns - self._bucket_ns
        if elapsed < self._period_ns:
            return
        self._previous = self._current if elapsed < 2 * self._period_ns else Counter()
        self._current = Counter()
        self._bucket_ns = now_ns - elapsed % self._period_ns

    def add(self, kind: str, reason: str, detail: str, now_ns: int) -> None:
        self._roll(now_ns)
        key = (kind, reason)
        self.by_reason[key] += 1
        self.total += 1
        self._current[key] += 1
        self._detail[key] = detail

    def recent(self, now_ns: int) -> RecentRejections | None:
        """What was refused lately, or None when nothing was."""
        self._roll(now_ns)
        counts = self._current + self._previous
        if not counts:
            return None
        (kind, reason), _ = counts.most_common(1)[0]
        detail = self._detail.get((kind, reason), "")
        if len(detail) > 60:
            detail = detail[:59] + "~"
        telemetry = sum(n for (k, _), n in counts.items() if k == "telemetry")
        return RecentRejections(
            sum(counts.values()), telemetry, f"{kind} {reason}: {detail}", self.total
        )


@dataclass(frozen=True, slots=True)
class Status:
    rtt_ms: float | None
    synchronised: bool
    robot_state: str | None
    reason: str | None
    w_si: float | None
    rejected: int | None
    mode: str
    deadman: bool
    in_control: bool | None
    # From the newest telemetry (DESIGN 7, 9); None when unknown.
    limiter: str | None = None
    filter: str | None = None
    v_lim_latency: float | None = None  # m/s
    w_lim_latency: float | None = None  # rad/s
    loop_delay_ms: float | None = None  # tau
    cmd_age_ms: float | None = None  # age of the robot's newest command
    cmd_age_p50_ms: float | None = None
    cmd_age_p90_ms: float | None = None
    cmd_gap_max_ms: float | None = None
    link_loss: float | None = None  # fraction, 0-1
    view_age_ms: float | None = None  # what this operator reports with its commands
    # Via points (DESIGN 7): the robot's active one and how many follow; None: none active.
    goal: tuple[float, float] | None = None
    goals_left: int = 0
    # The robot was asked to move and sent its base nothing (``held_still``).
    held_still: bool = False
    # Seconds since the newest telemetry arrived (None: none yet); beyond TELEMETRY_STALE_S
    # the telemetry figures are left out and the line says the robot is silent.
    telemetry_age_s: float | None = None
    controller: str | None = None  # the operator in control, from the robot's state
    robot_present: bool = True  # its liveliness token is held
    # This operator's via points have gone out for a while and the robot never echoed them.
    via_untaken: bool = False
    # The robot's current state and reason, from its telemetry (``Episode``): the largest
    # command gap it reported since they began, and for how long (robot clock) they hold.
    episode_gap_ms: float | None = None
    episode_s: float | None = None
    # Since they began, the robot's speed has reached its reference (a resume's ramp is over).
    episode_ramped: bool = False
    # The robot is present and no telemetry was accepted since it appeared.
    no_telemetry_yet: bool = False
    # The robot's messages this operator refused lately (None: none).
    refused: RecentRejections | None = None
    # What the clock sync says besides the round trip (several repliers, disagreement).
    clock_note: str | None = None
    # The view plane (DESIGN 12): ``view_plane_text`` of the newest telemetry and rx_kbps.
    view_plane: str | None = None
    # Command sources (DESIGN 14): the source that drives and the lock that holds (None: none,
    # or a robot without sources), and the operator that took control from this one.
    source: str | None = None
    lock: str | None = None
    taken_by: str | None = None


def _seconds(ms: float) -> str:
    return f"{ms / 1000.0:.1f} s"


def latency_cap_text(v_lim: float | None, w_lim: float | None) -> str:
    """The latency governor's caps as the status line and the view's link panel say them:
    `` at 0.99 m/s, turn at 1.06 rad/s`` (each part only when the robot reports it)."""
    cap = "" if v_lim is None else f" at {v_lim:.2f} m/s"
    if w_lim is not None:
        cap += f", turn at {w_lim:.2f} rad/s"
    return cap


def _hold(s: Status, reason: str) -> str:
    r = reason.lower()
    if r == "command timeout":
        # The gap that tripped the watchdog: the largest the robot reported during this HOLD
        # (the open gap grows while no command arrives). The window's figure alone drops to the
        # burst's 0.1 s once queued commands arrive after an outage; a gap below the watchdog's
        # timeout cannot be the one that tripped it, so no number rather than a wrong one.
        # Only the robot's gap figures: the command age counts from when the operator sent it,
        # so it adds the uplink delay (at 800 ms one way a 1.5 s outage read as 2.1 s).
        known = [g for g in (s.episode_gap_ms, s.cmd_gap_max_ms) if g is not None]
        gap = max(known) if known else None
        if gap is not None and gap < COMMAND_TIMEOUT_MS:
            gap = None
        what = "link gap" if gap is None else f"link gap (no command for {_seconds(gap)})"
        # Whether the short-gap resume applies is the robot's decision: when it wants a centred
        # stick its reason says so ("waiting for a centred stick"), not this one.
        if gap is not None and gap > RESUME_WINDOW_S * 1000.0:
            return f"HOLD: {what} - keep the stick; the robot says if it needs it centred"
        return f"HOLD: {what} - keep the stick, it resumes"
    if r == "stale commands":
        # The robot does not report the age of the commands it rejected, and its age figures
        # are of the accepted ones (younger than the limit by definition): no number.
        limit = MAX_COMMAND_AGE_MS.get(s.mode)
        why = "" if limit is None else f" (older than the limit, {limit} ms in {s.mode} mode)"
        return f"HOLD: commands arrive too late{why} - keep the stick, it resumes"
    if r == "deadman released":
        return "HOLD: deadman released - hold it and centre the stick to drive"
    if r == "sensor stale":
        return "HOLD: robot's sensor is stale (no fresh scan) - wait, then centre the stick"
    if r == "waiting for a centred stick":
        return "HOLD: centre the stick to drive"
    if r == "estop reset":
        return "HOLD: e-stop reset - centre the stick to drive"
    if "resum" in r:
        return "HOLD: resuming after a link gap - keep the stick"
    if r.startswith("lock "):
        name, _, why = reason[len("lock ") :].partition(": ")
        return f"LOCKED by {name} ({why}) - nothing drives until it releases"
    if r.startswith("operator ") and r.endswith((" lost", " silent")):
        return f"HOLD: {reason} - stopping; hold the deadman, stick centred, to take control"
    return f"HOLD: {reason}"


def _driving(s: Status, reason: str) -> str:
    limiter = s.limiter or "none"
    if limiter == "latency":
        delay = "" if s.loop_delay_ms is None else f" {_seconds(s.loop_delay_ms)}"
        cap = latency_cap_text(s.v_lim_latency, s.w_lim_latency)
        return f"SLOWED: link delay{delay} -> speed capped{cap}"
    if limiter in OBSTACLE_LIMITERS:
        which = f"filter {limiter}" if limiter != "sweep" else "sweep check"
        if s.held_still:
            return (
                f"STOPPED: obstacle too close for this command ({which}) - ease off or steer away"
            )
        if limiter == "sweep":
            return "SLOWED: obstacle next to the footprint (sweep check)"
        return f"SLOWED: obstacle ({which})"
    ramp_s = s.episode_s if "resum" in reason.lower() else None
    if ramp_s is not None and ramp_s < RAMP_SHOWN_S and not s.episode_ramped:
        return "DRIVING: resumed after a link gap, ramping up"
    if limiter == "limits":
        return "DRIVING (at the robot's speed/acceleration limits)"
    return "DRIVING"


def situation(s: Status) -> str:
    """What the robot does and why, in an operator's words (the status line's first part)."""
    state = s.robot_state
    age = s.telemetry_age_s
    if not s.robot_present and age is None:
        return "robot: not seen yet (waiting for its liveliness token)"
    stale = age is not None and age > TELEMETRY_STALE_S
    if not s.robot_present or stale or s.no_telemetry_yet:
        # A withdrawn liveliness token says so at once: the robot's last figures are not its
        # present ones, however young they are.
        refused = s.refused if s.refused is not None and s.refused.telemetry else None
        if not s.robot_present:
            why = "robot gone: its session ended or the link dropped"
        elif refused is not None:
            why = "the robot's telemetry is rejected, see REFUSED"
        elif s.no_telemetry_yet and not stale:
            why = "none received since the robot appeared"
        else:
            why = "robot or link silent"
        what = "NO VALID TELEMETRY" if refused is not None else "NO TELEMETRY"
        for_age = f" for {age:.1f} s" if age is not None and (stale or not s.robot_present) else ""
        view = "the view is old" if age is not None else "nothing to show"
        return (
            f"{what}{for_age} ({why}) - {view}; the robot stops when your commands stop reaching it"
        )
    if state is None:
        return "robot: no telemetry"
    if s.in_control is False and s.controller is not None and state in ("HOLD", "DRIVING"):
        who = s.controller
        if s.taken_by == who:
            return f"TAKEN OVER: {who} took control - you can take over once it quits or is lost"
        return f"WATCHING: {who} is in control - you can take over once it quits or is lost"
    reason = s.reason or ""
    if state == "ESTOP":
        return "ESTOP: latched - release the e-stop, centre the stick, hold the deadman, reset"
    if state == "DRIVING":
        text = _driving(s, reason)
        if s.source is not None and reason == f"source {s.source}":
            return f"{text} - source {s.source} drives"
        return text
    if state == "IDLE":
        why = reason or "no operator"
        return f"IDLE: {why} - hold the deadman with the stick centred to take control"
    if state == "HOLD":
        return _hold(s, reason) if reason else "HOLD"
    return f"{state}: {reason}" if reason else state


def link_figures(s: Status) -> str:
    """The link in numbers: round trip, command age p50/p90, gap max, loss (known ones).

    The round trip is left out with the telemetry figures when the robot is silent (the last
    clock reply is as old as the silence) and once the robot's liveliness changed."""
    parts = ["link --" if s.rtt_ms is None else f"rtt {s.rtt_ms:5.1f} ms"]
    if not s.synchronised:
        why = "" if s.clock_note is None else f": {s.clock_note}"
        parts[0] += f" (clock not synced{why})"
    elif s.clock_note is not None:
        parts[0] += f" (clock: {s.clock_note})"
    if s.cmd_age_p50_ms is not None:
        p90 = "--" if s.cmd_age_p90_ms is None else f"{s.cmd_age_p90_ms:.0f}"
        parts.append(f"cmd age p50/p90 {s.cmd_age_p50_ms:.0f}/{p90} ms")
    if s.cmd_gap_max_ms is not None:
        parts.append(f"gap max {s.cmd_gap_max_ms:.0f} ms")
    if s.link_loss is not None:
        parts.append(f"loss {100.0 * s.link_loss:.1f} %")
    return ", ".join(parts)


def view_plane_text(t: Telemetry | None, rx_kbps: float | None = None) -> str | None:
    """What the view plane carries and what the robot's downlink budget cut (DESIGN 12), e.g.
    ``camera 2 fps, scan 90 beams: the link carries 190 kbit/s`` (after a cut, with the robot's
    estimate of the link) or ``scan 180 beams: view 175 kbit/s`` (nothing cut: what this
    operator receives, else what the robot sent). None when nothing is known (an older robot
    and nothing counted)."""
    rate = rx_kbps if rx_kbps is not None else (None if t is None else t.view_kbps)
    if t is None or t.tel_hz is None:
        return None if rate is None else f"view {rate:.0f} kbit/s"
    parts = []
    if t.cam_fps is not None:
        parts.append("camera off" if t.cam_fps <= 0 else f"camera {t.cam_fps:.0f} fps")
    if t.scan_n is not None:
        parts.append(f"scan {t.scan_n} beams")
    if "rate" in t.cut:
        parts.append(f"telemetry {t.tel_hz:.0f} Hz")
    if t.cut and t.link_kbps is not None:
        carries = f"the link carries {t.link_kbps:.0f} kbit/s"
    elif rate is not None:
        carries = f"view {rate:.0f} kbit/s"
    else:
        carries = ""
    head = ", ".join(parts)
    return f"{head}: {carries}" if head and carries else head or carries or None


def format_status(s: Status) -> str:
    w_si = "w_SI  --" if s.w_si is None else f"w_SI {s.w_si:4.2f}"
    rejected = "rejected --" if s.rejected is None else f"rejected {s.rejected}"
    control = {None: "", True: " | in control", False: " | NOT in control"}[s.in_control]
    deadman = "deadman ON" if s.deadman else "deadman off"
    mode = s.mode if s.filter in (None, "none") else f"{s.mode} ({s.filter})"
    via = ""
    if s.goal is not None:
        more = f" +{s.goals_left}" if s.goals_left else ""
        via = f" | via {s.goal[0]:.1f},{s.goal[1]:.1f}{more}"
    elif s.via_untaken:
        via = " | via points NOT taken by the robot (does the router pass egc/<robot>/goal?)"
    refused = ""
    if s.refused is not None:
        refused = (
            f" | REFUSED {s.refused.count} robot msgs in {REJECTIONS_SHOWN_S:.0f} s"
            f" ({s.refused.what}; {s.refused.total} in all)"
        )
    view = "" if s.view_plane is None else f" | {s.view_plane}"
    sources = "" if s.source is None else f" | source {s.source}"
    if s.lock is not None:
        sources += f" | lock {s.lock}"
    return (
        f"{situation(s)} | {link_figures(s)}{view} | {w_si} | {rejected}{refused} | {mode}{via}"
        f"{sources} | {deadman}{control}"
    )


@dataclass(frozen=True, slots=True)
class FleetLine:
    """The fleet's part of the line (DESIGN 15): the driven robot, and the others' states."""

    driven: str
    others: str


class StatusLine:
    def __init__(
        self,
        stream: TextIO,
        tty: bool | None = None,
        plain_period_s: float = 5.0,
        width: int | None = None,
        fleet: Callable[[], FleetLine | None] | None = None,
    ):
        self._stream = stream
        self._tty = stream.isatty() if tty is None else tty
        self._plain_period_s = plain_period_s
        self._width = width  # None: the terminal's, asked at every redraw
        self._fleet = fleet
        self._last_key: tuple[object, ...] | None = None
        self._last_plain_s = -1e9

    def say(self, text: str) -> None:
        """A line of its own (on a terminal, above the redrawn status line)."""
        self._stream.write(("\r\x1b[2K" if self._tty else "") + text + "\n")
        self._stream.flush()

    def show(self, status: Status, now_s: float) -> None:
        text = format_status(status)
        fleet = None if self._fleet is None else self._fleet()
        if fleet is not None:
            text = f"[{fleet.driven}] {text} | fleet: {fleet.others}"
        if self._tty:
            width = self._width or shutil.get_terminal_size(fallback=(200, 24)).columns
            if len(text) > width - 1:  # a wrapped line cannot be redrawn in place
                text = text[: max(1, width - 2)] + "~"
            self._stream.write("\r\x1b[2K" + text)
            self._stream.flush()
            return
        key = (
            status.robot_state,
            status.reason,
            status.limiter == "latency",  # sustained; egc/none may alternate every cycle
            status.in_control,
            status.synchronised,
            status.filter,  # the operator picked another one (sustained, unlike the limiter)
            status.goal,  # the robot moved on to another via point
            status.no_telemetry_yet,
            status.refused is not None,  # the robot's messages began or stopped being refused
            status.clock_note,
            status.source,  # DESIGN 14: another source drives, a lock engaged
            status.lock,
            fleet,  # a switch, or another robot's state changed
        )
        if key != self._last_key or now_s - self._last_plain_s >= self._plain_period_s:
            self._stream.write(text + "\n")
            self._stream.flush()
            self._last_key = key
            self._last_plain_s = now_s

    def close(self) -> None:
        if self._tty:
            self._stream.write("\n")
            self._stream.flush()


class Episode:
    """The robot's current state and reason as its telemetry says them (not thread-safe).

    Since when (the robot's clock) they hold, and the largest command gap the robot reported
    since then: the status line's HOLD text names the gap that tripped the watchdog even after
    the queued commands of an outage came in as a burst, and says "ramping up" only just after
    a resume (the robot keeps that reason for as long as it drives on).
    """

    def __init__(self) -> None:
        self.key: tuple[str, str | None] | None = None
        self.since_ns = 0
        self.newest_ns = 0
        self.gap_ms: float | None = None
        self.reached_ref = False  # the speed reached its reference since the key changed
        # DESIGN 14: the operator in control, and the last handover seen: (from, to).
        self.operator: str | None = None
        self.handover: tuple[str | None, str | None] | None = None

    def update(self, t: Telemetry) -> None:
        if self.newest_ns - EPISODE_CLOCK_JUMP_NS <= t.stamp_ns < self.newest_ns:
            return  # an older cycle that came late (far older: the robot's clock jumped)
        if t.operator != self.operator:
            self.handover = (self.operator, t.operator)
            self.operator = t.operator
        key = (t.state, t.reason)
        if key != self.key:
            self.key, self.since_ns, self.gap_ms = key, t.stamp_ns, None
            self.reached_ref = False
        self.newest_ns = t.stamp_ns
        if t.cmd_gap_max_ms is not None:
            self.gap_ms = max(self.gap_ms or 0.0, t.cmd_gap_max_ms)
        if abs(t.v_ref) > RAMP_DONE_MPS and abs(t.v_cmd) >= abs(t.v_ref) - RAMP_DONE_MPS:
            self.reached_ref = True

    def of(self, state: str | None, reason: str | None) -> tuple[float | None, float | None]:
        """(largest gap ms, seconds) of this episode if it is ``state``/``reason``, else Nones."""
        if self.key is None or self.key != (state, reason):
            return None, None
        return self.gap_ms, (self.newest_ns - self.since_ns) / 1e9

    def ramped(self, state: str | None, reason: str | None) -> bool:
        """The speed reached its reference during this episode (``state``/``reason``)."""
        return self.key is not None and self.key == (state, reason) and self.reached_ref


def status_of(
    command: OperatorCommand,
    telemetry: Telemetry | None,
    state: StateMessage | None,
    rtt_ms: float | None,
    synchronised: bool,
    robot_alive: bool = True,
    telemetry_age_s: float | None = None,
    episode: Episode | None = None,
    state_age_s: float | None = None,
    rejections: RecentRejections | None = None,
    clock_note: str | None = None,
    rx_kbps: float | None = None,
) -> Status:
    """The status line's inputs from the newest messages (robot gone: none of its state, figures
    or round trip; telemetry older than TELEMETRY_STALE_S, or none since the robot appeared:
    none of its figures, no state, and nothing said about control; a state message older than
    STATE_STALE_S: not shown). Telemetry newer than the state message (sent on change and at
    1 Hz) says the state and reason."""
    stale = telemetry_age_s is not None and telemetry_age_s > TELEMETRY_STALE_S
    no_telemetry_yet = robot_alive and telemetry is None
    t = None if stale or not robot_alive else telemetry
    state_stale = state_age_s is not None and state_age_s > STATE_STALE_S
    s = state if robot_alive and not stale and not no_telemetry_yet and not state_stale else None
    robot_state = None if s is None else s.state
    reason = None if s is None else s.reason
    controller = None if s is None else s.operator
    rejected = None if s is None else s.rejected
    if (
        t is not None
        and (t.reason is not None or s is None)
        and (s is None or t.stamp_ns > s.stamp_ns)
    ):
        robot_state, reason, controller = t.state, t.reason, t.operator
    if t is not None and (s is None or t.stamp_ns > s.stamp_ns):
        # The count only grows: the newest message's (the telemetry's, when it is newer than the
        # state message), never an older count beside a newer state.
        rejected = t.rejected if rejected is None else max(rejected, t.rejected)
    in_control = None if robot_state is None else controller == command.op
    gap_ms, episode_s = (None, None) if episode is None else episode.of(robot_state, reason)
    taken_by = None
    if episode is not None and episode.handover is not None:
        before, after = episode.handover
        if before == command.op and after is not None and after == controller:
            taken_by = after  # straight from this operator to another: it took control
    return Status(
        # a silent robot's round trip is as old as its silence: left out like its figures
        rtt_ms=rtt_ms if robot_alive and not stale else None,
        synchronised=synchronised,
        robot_state=robot_state,
        reason=reason,
        w_si=None if t is None else t.w_si,
        rejected=rejected,
        mode=command.mode,
        deadman=command.deadman,
        in_control=in_control,
        limiter=None if t is None else t.limiter,
        filter=None if t is None else t.filter or None,
        v_lim_latency=None if t is None else t.v_lim_latency,
        w_lim_latency=None if t is None else t.w_lim_latency,
        loop_delay_ms=None if t is None else t.loop_delay_ms,
        cmd_age_ms=None if t is None else t.cmd_age_ms,
        cmd_age_p50_ms=None if t is None else t.cmd_age_p50_ms,
        cmd_age_p90_ms=None if t is None else t.cmd_age_p90_ms,
        cmd_gap_max_ms=None if t is None else t.cmd_gap_max_ms,
        link_loss=None if t is None else t.link_loss,
        view_age_ms=command.view_age_ms,
        goal=None if t is None else t.goal,
        goals_left=0 if t is None else t.goals_left,
        held_still=t is not None and held_still(t),
        telemetry_age_s=telemetry_age_s,
        controller=controller,
        robot_present=robot_alive,
        episode_gap_ms=gap_ms,
        episode_s=episode_s,
        episode_ramped=episode is not None and episode.ramped(robot_state, reason),
        no_telemetry_yet=no_telemetry_yet,
        refused=rejections,
        clock_note=clock_note,
        view_plane=view_plane_text(t, rx_kbps) if robot_alive else None,
        source=None if t is None else t.source,
        lock=None if t is None else t.lock,
        taken_by=taken_by,
    )


_STILL = 1e-3  # m/s, rad/s


def held_still(t: Telemetry) -> bool:
    """The operator asked for motion and a filter or the sweep sent the base none."""
    asked = abs(t.v_ref) > _STILL or abs(t.w_ref) > _STILL
    still = abs(t.v_cmd) <= _STILL and abs(t.w_cmd) <= _STILL
    return t.limiter in OBSTACLE_LIMITERS and asked and still
