"""``egc-teleop filter`` (pinned CLI) agrees with the equations and survives bad lines."""

from __future__ import annotations

import json
import math
import subprocess
import sys
import zlib

import numpy as np
import pytest

from tests.filters.reference_egc import reference_egc

PINNED_KEYS = {"v", "w", "w_si", "modified", "region", "side", "rc", "igc", "agc", "egc"}


def run_filter(lines, *args):
    proc = subprocess.run(
        [sys.executable, "-m", "egc_app", "filter", *args],
        input="".join(line + "\n" for line in lines),
        capture_output=True,
        text=True,
        timeout=120,
    )
    return proc, [json.loads(x) for x in proc.stdout.splitlines()]


def random_cases(rng, n, v_max, w_max, spread):
    cases = []
    for _ in range(n):
        v = float(rng.uniform(-v_max, v_max))
        w = float(rng.uniform(-w_max, w_max))
        k = int(rng.integers(1, 80))
        pts = rng.uniform(-spread, spread, size=(k, 2)).round(6).tolist()
        cases.append({"v": v, "w": w, "points": pts})
    return cases


# (profile, v_max, w_max, r_min, r_max, scatter half-width of the points, --horizon)
PROFILE_CASES = [
    ("pioneer3dx", 0.14, 0.5, 0.455, 0.595, 1.5, None),
    ("jackal", 2.0, 2.0, 0.508, 2.508, 5.0, None),
    ("pioneer3dx", 0.14, 0.5, 0.455, 0.595, 1.5, 3.0),
]


@pytest.mark.parametrize(
    ("profile", "v_max", "w_max", "r_min", "r_max", "spread", "horizon"), PROFILE_CASES
)
def test_agrees_with_reference_to_1e9(profile, v_max, w_max, r_min, r_max, spread, horizon):
    rng = np.random.default_rng(zlib.crc32(f"{profile}{horizon}".encode()))
    cases = random_cases(rng, 400, v_max, w_max, spread)
    args = ["--profile", profile] + ([] if horizon is None else ["--horizon", str(horizon)])
    proc, outs = run_filter([json.dumps(c) for c in cases], *args)
    assert proc.returncode == 0, proc.stderr
    kT = horizon if horizon is not None else r_max / v_max
    seen = {"left": 0, "right": 0, "safe": 0, "conditional": 0, "unsafe": 0, "reverse": 0}
    for case, out in zip(cases, outs, strict=True):
        assert out.keys() >= PINNED_KEYS
        ref = reference_egc(case["v"], case["w"], case["points"], r_min, r_max, kT)
        if ref is None:
            continue
        for key in ("v", "w", "w_si", "rc"):
            assert math.isclose(out[key], ref[key], abs_tol=1e-9), (key, case, out, ref)
        for key in ("igc", "agc", "egc"):
            if ref[key] is None:
                assert out[key] is None
            else:
                assert np.allclose(out[key], ref[key], atol=1e-9, rtol=0), (key, out, ref)
        assert out["region"] == ref["region"] and out["side"] == ref["side"]
        assert out["modified"] == (ref["agc"] is not None)
        seen[out["region"]] += 1
        if out["side"]:
            seen[out["side"]] += 1
        if case["v"] < 0 and out["modified"]:
            seen["reverse"] += 1
    assert all(count > 0 for count in seen.values()), seen


def test_bad_lines_give_error_lines_and_processing_continues():
    good = json.dumps({"v": 0.1, "w": 0.0, "points": [[5.0, 0.0]]})
    bad = [
        "not json",
        "[1, 2]",
        '{"v": 0.1, "w": 0.0}',
        '{"v": "fast", "w": 0.0, "points": []}',
        '{"v": NaN, "w": 0.0, "points": []}',
        '{"v": 0.1, "w": Infinity, "points": []}',
        '{"v": 0.1, "w": 0.0, "points": [[1.0]]}',
        '{"v": 0.1, "w": 0.0, "points": [[1.0, "a"]]}',
        '{"v": 0.1, "w": 0.0, "points": "none"}',
        '{"v": true, "w": 0.0, "points": []}',
        "[" * 100000,
        "\x00\xff garbage",
        "",
        "   ",
    ]
    lines = [good, *bad, good]
    proc, outs = run_filter(lines)
    assert proc.returncode == 0
    assert "Traceback" not in proc.stderr
    assert len(outs) == len(lines)
    assert outs[0]["v"] == 0.1 and outs[-1]["v"] == 0.1
    for out in outs[1:-1]:
        assert set(out) == {"error"} and out["error"]


def test_final_command_reports_rules_beyond_the_paper():
    # empty scan: the paper's equations are undefined; the rule stops (DESIGN 5.9)
    proc, outs = run_filter(
        ['{"v": 0.1, "w": 0.2, "points": []}', '{"v": 5.0, "w": 0.0, "points": [[50.0, 0.0]]}']
    )
    assert proc.returncode == 0
    assert outs[0]["case"] == "no_points_unknown" and outs[0]["final"]["v"] == 0.0
    assert outs[1]["v"] == 5.0 and outs[1]["final"]["v"] == 0.14  # profile limit after filter
    assert outs[1]["final"]["limiter"] == "limits"


def test_bad_arguments_exit_2_with_one_line():
    proc = subprocess.run(
        [sys.executable, "-m", "egc_app", "filter", "--profile", "nope"],
        input="",
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert proc.returncode == 2 and len(proc.stderr.strip().splitlines()) == 1
    proc = subprocess.run(
        [sys.executable, "-m", "egc_app", "filter", "--horizon", "-1"],
        input="",
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert proc.returncode == 2 and "horizon" in proc.stderr


@pytest.mark.parametrize("horizon", ["1e300", "61", "nan", "inf", "0"])
def test_a_horizon_beyond_a_minute_is_refused(horizon):
    """Outside check: --horizon 1e300 was accepted; numpy overflowed and every command came out
    'clear', the filter bypassed."""
    proc = subprocess.run(
        [sys.executable, "-m", "egc_app", "filter", "--horizon", horizon],
        input='{"v": 0.1, "w": 0.0, "points": [[0.5, 0.0]]}\n',
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert proc.returncode == 2 and "horizon must be" in proc.stderr and not proc.stdout
