"""``egc-teleop filter --filter ek-egc`` agrees with DESIGN 6 (the plain reference) to 1e-9."""

from __future__ import annotations

import json
import math
import zlib

import numpy as np
import pytest

from tests.filters.reference_ek_egc import reference_ek_egc
from tests.filters.test_filter_cli import PINNED_KEYS, PROFILE_CASES, random_cases, run_filter


@pytest.mark.parametrize(
    ("profile", "v_max", "w_max", "r_min", "r_max", "spread", "horizon"), PROFILE_CASES
)
def test_agrees_with_reference_to_1e9(profile, v_max, w_max, r_min, r_max, spread, horizon):
    rng = np.random.default_rng(zlib.crc32(f"ek{profile}{horizon}".encode()))
    cases = random_cases(rng, 400, v_max, w_max, spread)
    for case in cases[:60]:  # straight commands too
        case["w"] = 0.0
    args = ["--filter", "ek-egc", "--profile", profile]
    args += [] if horizon is None else ["--horizon", str(horizon)]
    proc, outs = run_filter([json.dumps(c) for c in cases], *args)
    assert proc.returncode == 0, proc.stderr
    kT = horizon if horizon is not None else r_max / v_max
    L = v_max / w_max
    seen = dict.fromkeys(("left", "right", "safe", "conditional", "unsafe", "reverse"), 0)
    seen |= {"straight": 0, "turning": 0}
    for case, out in zip(cases, outs, strict=True):
        assert out.keys() >= PINNED_KEYS and "final" in out
        ref = reference_ek_egc(case["v"], case["w"], case["points"], r_min, r_max, kT, L)
        if ref is None:
            continue
        for key in ("v", "w", "w_si", "rc"):
            assert math.isclose(out[key], ref[key], rel_tol=1e-9, abs_tol=1e-9), (key, out, ref)
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
        if out["modified"]:
            seen["reverse" if case["v"] < 0 else "straight" if case["w"] == 0 else "turning"] += 1
    assert all(count > 0 for count in seen.values()), seen


def test_same_keys_as_egc_and_circles_in_ek_coordinates():
    line = json.dumps({"v": 0.14, "w": 0.0, "points": [[0.0, 0.3], [1.0, -0.05]]})
    _, (egc,) = run_filter([line])
    proc, (ek,) = run_filter([line], "--filter", "ek-egc")
    assert proc.returncode == 0 and set(ek) == set(egc)
    # (0, 0.3) is 0.3 m away in {R}, but half a turn round a 0.15 m circle: EK (0.23, 0.41),
    # 0.23 m from P_AGC, so the expanded circle is unsafe and the command stops
    assert ek["case"] == "expanded" and ek["agc"] != egc["agc"]
    assert ek["agc"][2] == pytest.approx(0.2354, abs=1e-4) and ek["region"] == "unsafe"
    assert (ek["v"], ek["w"]) == (0.0, 0.0)
    assert ek["final"]["limiter"] == "ek-egc"
    (ek_none,) = run_filter(['{"v": 0.1, "w": 0.2, "points": []}'], "--filter", "ek-egc")[1]
    assert ek_none["case"] == "no_points_unknown" and ek_none["final"]["v"] == 0.0
