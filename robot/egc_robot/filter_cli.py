"""``egc-teleop filter`` (pinned): the EGC filter as a JSON-lines tool on stdin/stdout.

``--filter egc`` (default) runs EGC, ``--filter ek-egc`` EGC in the ego-kinematic space (DESIGN
6): the same keys, with the circles (``igc``, ``agc``, ``egc``, ``rc``) in EK coordinates (for
v < 0, the mirrored EK space the circles were computed in); ``--filter none`` is direct mode.
``--filter cbf`` (DESIGN 13) prints its own intermediates instead of the circles: ``case``,
``margin_m`` (the fixed margin), ``margin_ahead_m`` (the margin straight ahead at the current
speed), ``tau_s``, ``braking_s`` (K = tau + period + T/2: metres of margin per m/s of
approach),
``considered`` (points within reach), ``rounds``, ``nearest_m`` and ``active``: the
constraints ``a v + b w >= c`` that changed the command, each with its point ``x``, ``y``, its
``distance_m`` from the footprint, ``margin_m``, ``kind`` (``state``: the margin at the current
speed, ``command``: at the commanded one) and ``unseen`` (an edge of what the laser saw).

Each input line is ``{"v": float, "w": float, "points": [[x, y], ...]}`` (points in {R}, metres).
For ``cbf`` a line may also give the robot's current velocity ``v_now``, ``w_now`` (default: the
command itself, as ``egc-teleop replay`` takes a log's robot to move as commanded) and the loop
delay ``tau`` (s; default ``CbfParams.tau_s``, DESIGN 9's tau on a perfect link).
Each output line carries the paper's equations alone (DESIGN 5.1-5.8; DESIGN 6 for ek-egc) in
``v``/``w`` with their intermediates, and, under ``final``, what the robot would send to the base
after the rules of DESIGN 5.9-5.10 and the profile's velocity limits (acceleration limits need
a previous command and are not applied: each line stands alone). In the undefined cases of
DESIGN 5.9, ``v``/``w`` carry that case's documented rule, named by ``case``. A malformed line
(a blank one included) gives ``{"error": "..."}`` and processing continues: there is one output
line per input line.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from dataclasses import dataclass
from typing import Any, TextIO

from egc_common.cli_args import PROFILE_HELP
from egc_common.errors import UsageError
from egc_common.profiles import get_profile

from egc_robot.filters.cbf import CbfResult
from egc_robot.filters.egc import EgcResult
from egc_robot.pipeline import PipelineConfig, filter_velocity

MAX_LINE_CHARS = 50_000_000
# The filters whose intermediates this tool prints: the EgcResult keys (ek-egc's in EK space),
# and cbf's own (``cbf_json``).
CLI_FILTERS = ("egc", "ek-egc", "none", "cbf")


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--filter",
        default="egc",
        choices=CLI_FILTERS,
        help="filter to apply (default: egc; ek-egc reports its circles in EK coordinates, cbf "
        "its active constraints and margins)",
    )
    parser.add_argument(
        "--profile",
        default="pioneer3dx",
        metavar="NAME|FILE",
        help=f"{PROFILE_HELP} (default: pioneer3dx)",
    )
    parser.add_argument(
        "--horizon",
        type=float,
        default=None,
        metavar="SECONDS",
        help="prediction horizon kT in seconds (default: r_max / v_max)",
    )
    parser.add_argument(
        "--no-return-is-free",
        action="store_true",
        help="treat a line with no points as free space instead of unknown",
    )


class LineError(ValueError):
    pass


def _reject_constant(name: str) -> float:
    raise LineError(f"{name} is not a finite number")


def _number(value: Any, what: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise LineError(f"{what} must be a number")
    x = float(value)
    if not math.isfinite(x):
        raise LineError(f"{what} must be finite")
    return x


def parse_line(line: str) -> tuple[float, float, list[tuple[float, float]]]:
    """Validate one input line; raises LineError with a message for the error line."""
    v, w, points, _ = parse_line_with_state(line)
    return v, w, points


@dataclass(frozen=True, slots=True)
class LineState:
    """A line's optional ``v_now``, ``w_now`` (m/s, rad/s) and ``tau`` (s); None: not given."""

    v_now: float | None = None
    w_now: float | None = None
    tau_s: float | None = None


def parse_line_with_state(
    line: str,
) -> tuple[float, float, list[tuple[float, float]], LineState]:
    """``parse_line`` and the optional keys of ``LineState``."""
    if len(line) > MAX_LINE_CHARS:
        raise LineError("line too long")
    try:
        obj = json.loads(line, parse_constant=_reject_constant)
    except LineError:
        raise
    except (ValueError, RecursionError) as exc:
        raise LineError(f"invalid JSON: {exc}") from None
    if not isinstance(obj, dict):
        raise LineError("line must be a JSON object")
    for key in ("v", "w", "points"):
        if key not in obj:
            raise LineError(f"missing key {key!r}")
    v = _number(obj["v"], "v")
    w = _number(obj["w"], "w")
    raw = obj["points"]
    if not isinstance(raw, list):
        raise LineError("points must be a list of [x, y]")
    points = []
    for i, p in enumerate(raw):
        if not isinstance(p, list) or len(p) != 2:
            raise LineError(f"points[{i}] must be [x, y]")
        points.append((_number(p[0], f"points[{i}][0]"), _number(p[1], f"points[{i}][1]")))
    state = LineState(
        *(None if obj.get(key) is None else _number(obj[key], key) for key in ("v_now", "w_now")),
        _tau(obj.get("tau")),
    )
    return v, w, points, state


def _tau(value: Any) -> float | None:
    if value is None:
        return None
    tau = _number(value, "tau")
    if not 0.0 <= tau <= 60.0:
        raise LineError("tau must be a number of seconds within [0, 60]")
    return tau


def cbf_json(res: CbfResult | None, v_ref: float, w_ref: float) -> dict[str, Any]:
    """``cbf``'s answer and intermediates (module docstring)."""
    if res is None:  # a result the family answered for cbf without running it (invalid input)
        return {"v": 0.0, "w": 0.0, "modified": True, "case": "invalid_input", "active": []}
    return {
        "v": res.v_mps,
        "w": res.w_radps,
        "modified": res.modified,
        "case": res.case.value,
        "margin_m": res.margin_m,
        "margin_ahead_m": res.margin_ahead_m,
        "tau_s": res.tau_s,
        "braking_s": res.braking_s,
        "considered": res.considered,
        "rounds": res.rounds,
        "nearest_m": res.nearest_m if math.isfinite(res.nearest_m) else None,
        "active": [
            {
                "x": c.x_m,
                "y": c.y_m,
                "a": c.a,
                "b": c.b,
                "c": c.c,
                "distance_m": c.distance_m,
                "margin_m": c.margin_m,
                "kind": c.kind,
                "unseen": c.unseen,
            }
            for c in res.active
        ],
    }


def _circle(c: tuple[float, float, float] | None) -> list[float] | None:
    return None if c is None else [c[0], c[1], c[2]]


def result_json(res: EgcResult | None, v_ref: float, w_ref: float) -> dict[str, Any]:
    if res is None:  # --filter none
        return {
            "v": v_ref,
            "w": w_ref,
            "w_si": 1.0,
            "modified": False,
            "region": "safe",
            "side": None,
            "rc": 0.0,
            "igc": None,
            "agc": None,
            "egc": None,
            "case": "none",
        }
    return {
        "v": res.v_mps,
        "w": res.w_radps,
        "w_si": res.w_si,
        "modified": res.modified,
        "region": res.region.value,
        "side": None if res.side is None else res.side.value,
        "rc": res.r_rc_m,
        "igc": _circle(res.igc),
        "agc": _circle(res.agc),
        "egc": _circle(res.egc),
        "case": res.case.value,
    }


def process(stream_in: TextIO, stream_out: TextIO, config: PipelineConfig) -> int:
    """Filter every line of ``stream_in``; returns the number of error lines written."""
    errors = 0
    for raw_line in stream_in:
        line = raw_line.strip()
        try:
            if not line:
                raise LineError("empty line")  # still answered: one output line per input line
            v, w, points, state = parse_line_with_state(line)
            mode = "direct" if config.filter == "none" else "shared"
            if config.filter == "cbf":
                # The robot moving as given (default: as commanded), no acceleration limits (an
                # infinite period: each line stands alone), as in a replay.
                now = (
                    v if state.v_now is None else state.v_now,
                    w if state.w_now is None else state.w_now,
                )
                out = filter_velocity(
                    config, v, w, mode, points, now, math.inf, loop_delay_s=state.tau_s
                )
                detail = None if out.family is None else out.family.detail
                doc = cbf_json(detail if isinstance(detail, CbfResult) else None, v, w)
            else:
                out = filter_velocity(config, v, w, mode, points, None, 0.0)
                doc = result_json(out.filtered, v, w)
            doc["final"] = {
                "v": out.v_cmd_mps,
                "w": out.w_cmd_radps,
                "limiter": out.limiter.value,
                "sweep_scale": out.sweep_scale,
                "escape": out.escape,
            }
            text = json.dumps(doc, allow_nan=False)
        except (LineError, ValueError) as exc:
            errors += 1
            text = json.dumps({"error": str(exc)})
        except Exception as exc:  # a bug must cost one line, not the rest of the stream
            errors += 1
            text = json.dumps({"error": f"internal error: {type(exc).__name__}: {exc}"})
        stream_out.write(text + "\n")
        stream_out.flush()
    return errors


def run(args: argparse.Namespace) -> int:
    try:
        profile = get_profile(args.profile)
        config = PipelineConfig(
            profile,
            filter=args.filter,
            horizon_s=args.horizon,
            no_return_is_free=args.no_return_is_free,
        )
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    process(sys.stdin, sys.stdout, config)
    return 0
