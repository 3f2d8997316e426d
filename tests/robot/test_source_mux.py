"""Source arbitration (DESIGN 14): properties over random sources, locks and times, and the
cases the design names. ``arbitrate`` is pure: every time is given."""

from __future__ import annotations

import pytest
from egc_robot.source_mux import (
    NO_SOURCE,
    LockFeed,
    LockSpec,
    MuxConfig,
    SourceSpec,
    Verdict,
    arbitrate,
    is_fresh,
    lock_state,
)
from hypothesis import given, settings
from hypothesis import strategies as st

MS = 1_000_000
T0 = 3600 * 1000 * MS

NAV = SourceSpec("nav", "ros2", 10, 0.5, topic="/cmd_vel_nav")
TELEOP = SourceSpec("teleop", "operator", 100, 0.5)
DOCK = SourceSpec("dock", "zenoh", 50, 0.2)


def mux(*locks: LockSpec) -> MuxConfig:
    return MuxConfig((NAV, TELEOP, DOCK), locks)


# -- random configurations -------------------------------------------------------------------

timeouts = st.sampled_from([0.05, 0.2, 0.5, 1.0, 2.0])


@st.composite
def configs(draw: st.DrawFn) -> MuxConfig:
    n = draw(st.integers(1, 5))
    priorities = draw(st.lists(st.integers(-5, 20), min_size=n, max_size=n, unique=True))
    kinds = ["operator"] + ["zenoh"] * (n - 1) if draw(st.booleans()) else ["zenoh"] * n
    sources = tuple(
        SourceSpec(f"s{i}", kind, p, draw(timeouts))
        for i, (kind, p) in enumerate(zip(kinds, priorities, strict=True))
    )
    locks = tuple(
        LockSpec(f"l{i}", draw(st.integers(-5, 25)), draw(timeouts))
        for i in range(draw(st.integers(0, 3)))
    )
    return MuxConfig(sources, locks)


@st.composite
def situations(draw: st.DrawFn) -> tuple[MuxConfig, dict[str, int], dict[str, LockFeed], int]:
    config = draw(configs())
    now = T0 + draw(st.integers(0, 5000)) * MS
    ages_ms = st.integers(-5, 3000)  # a message may arrive just after the cycle read its clock
    claims = {s.name: now - draw(ages_ms) * MS for s in config.sources if draw(st.booleans())}
    locks = {
        lk.name: LockFeed(draw(st.booleans()), now - draw(ages_ms) * MS)
        for lk in config.locks
        if draw(st.booleans())
    }
    return config, claims, locks, now


def active_locks(config: MuxConfig, locks: dict[str, LockFeed], now: int) -> list[LockSpec]:
    return [lk for lk in config.locks if lock_state(lk, locks.get(lk.name), now) is not None]


def fresh_sources(config: MuxConfig, claims: dict[str, int], now: int) -> list[SourceSpec]:
    return [s for s in config.sources if is_fresh(s, claims.get(s.name), now)]


@settings(max_examples=150, deadline=None)
@given(situations())
def test_the_source_that_drives_is_the_highest_fresh_one_and_no_active_lock_outranks_it(case):
    config, claims, locks, now = case
    verdict = arbitrate(config, claims, locks, now)
    fresh = fresh_sources(config, claims, now)
    active = active_locks(config, locks, now)
    if verdict.source is not None:
        spec = config.source(verdict.source)
        assert spec is not None and spec in fresh
        assert all(s.priority <= spec.priority for s in fresh)
        assert all(lk.priority <= spec.priority for lk in active)
        assert verdict.reason == f"source {spec.name}"
        assert verdict.blocked is None
    else:
        top = max(fresh, key=lambda s: s.priority, default=None)
        # Nothing drives only when nothing is fresh or an active lock outranks the best source.
        assert top is None or any(lk.priority > top.priority for lk in active)
        assert verdict.blocked == (None if top is None else top.name)


@settings(max_examples=150, deadline=None)
@given(situations())
def test_the_lock_reported_is_the_highest_active_one(case):
    config, claims, locks, now = case
    verdict = arbitrate(config, claims, locks, now)
    active = active_locks(config, locks, now)
    if not active:
        assert verdict.lock is None
    else:
        assert verdict.lock is not None
        top = max(lk.priority for lk in active)
        held = next(lk for lk in config.locks if lk.name == verdict.lock)
        assert held in active and held.priority == top


@settings(max_examples=100, deadline=None)
@given(situations(), st.integers(-5, 25), timeouts, st.booleans())
def test_a_lock_more_never_lets_a_source_drive_that_would_not_have(case, prio, timeout, value):
    config, claims, locks, now = case
    before = arbitrate(config, claims, locks, now)
    extra = LockSpec("extra", prio, timeout)
    more = MuxConfig(config.sources, (*config.locks, extra))
    fed = {**locks, "extra": LockFeed(value, now)}
    after = arbitrate(more, claims, fed, now)
    assert after.source in (None, before.source)


@settings(max_examples=100, deadline=None)
@given(situations(), st.integers(1, 5000))
def test_a_silent_lock_feed_locks_and_stays_locked_as_time_goes_on(case, later_ms):
    config, _claims, locks, now = case
    for lk in config.locks:
        feed = locks.get(lk.name)
        if feed is None:
            continue
        silent_until = feed.rx_ns + lk.timeout_ns
        if now > silent_until:
            assert lock_state(lk, feed, now + later_ms * MS) is not None


@settings(max_examples=100, deadline=None)
@given(situations(), st.randoms(use_true_random=False))
def test_the_order_of_the_tables_does_not_matter(case, rnd):
    config, claims, locks, now = case
    sources, lks = list(config.sources), list(config.locks)
    rnd.shuffle(sources)
    rnd.shuffle(lks)
    shuffled = MuxConfig(tuple(sources), tuple(lks))
    assert arbitrate(shuffled, claims, locks, now) == arbitrate(config, claims, locks, now)


# -- the cases of DESIGN 14 ---------------------------------------------------------------------


def test_navigation_drives_alone_and_an_operator_of_higher_priority_takes_over():
    config = mux()
    assert arbitrate(config, {"nav": T0}, {}, T0) == Verdict("nav", None, "source nav")
    both = {"nav": T0, "teleop": T0}
    assert arbitrate(config, both, {}, T0).source == "teleop"


def test_a_source_is_fresh_up_to_its_timeout_inclusive():
    config = mux()
    timeout = NAV.timeout_ns
    assert arbitrate(config, {"nav": T0}, {}, T0 + timeout).source == "nav"
    late = arbitrate(config, {"nav": T0}, {}, T0 + timeout + 1)
    assert late == Verdict(None, None, NO_SOURCE)


def test_a_silent_operator_hands_back_to_navigation_after_its_own_timeout():
    config = mux()
    claims = {"nav": T0 + 600 * MS, "teleop": T0}
    assert arbitrate(config, claims, {}, T0 + 500 * MS).source == "teleop"
    assert arbitrate(config, claims, {}, T0 + 501 * MS).source == "nav"


def test_a_true_lock_blocks_lower_sources_but_not_a_higher_or_equal_one():
    pause = LockSpec("pause", 50, 1.0)
    config = mux(pause)
    on = {"pause": LockFeed(True, T0)}
    v = arbitrate(config, {"nav": T0}, on, T0)
    assert v == Verdict(None, "pause", "lock pause: true", "nav")
    assert arbitrate(config, {"dock": T0, "nav": T0}, on, T0).source == "dock"  # 50 == 50
    v = arbitrate(config, {"teleop": T0, "nav": T0}, on, T0)
    assert (v.source, v.lock) == ("teleop", "pause")


def test_a_false_heartbeat_unlocks_until_it_falls_silent():
    hb = LockSpec("hb", 1000, 0.3)
    config = mux(hb)
    feed = {"hb": LockFeed(False, T0)}
    assert arbitrate(config, {"nav": T0}, feed, T0 + 300 * MS).source == "nav"
    v = arbitrate(config, {"nav": T0 + 300 * MS}, feed, T0 + 301 * MS)
    assert v.source is None and v.lock == "hb" and v.reason == "lock hb: silent for 0.30 s"


def test_a_lock_never_heard_from_is_active():
    config = mux(LockSpec("hb", 1000, 0.3))
    v = arbitrate(config, {"teleop": T0}, {}, T0)
    assert v == Verdict(None, "hb", "lock hb: never heard", "teleop")


def test_a_lock_active_with_nothing_fresh_still_says_it_holds():
    config = mux(LockSpec("pause", 5, 1.0))
    v = arbitrate(config, {}, {"pause": LockFeed(True, T0)}, T0)
    assert v == Verdict(None, "pause", "lock pause: true")


def test_the_highest_active_lock_is_named():
    config = mux(LockSpec("low", 20, 1.0), LockSpec("high", 200, 1.0))
    locks = {"low": LockFeed(True, T0), "high": LockFeed(True, T0)}
    assert arbitrate(config, {"teleop": T0}, locks, T0).reason == "lock high: true"


@pytest.mark.parametrize(
    ("sources", "message"),
    [
        ((), "at least one"),
        ((NAV, SourceSpec("nav", "zenoh", 3, 0.5)), "name nav is used twice"),
        ((NAV, SourceSpec("dock", "zenoh", 10, 0.5)), "same priority 10"),
        ((TELEOP, SourceSpec("op2", "operator", 3, 0.5)), "at most one source of kind operator"),
    ],
)
def test_inconsistent_configurations_are_refused(sources, message):
    with pytest.raises(ValueError, match=message):
        MuxConfig(sources)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"kind": "joystick"}, "kind must be one of"),
        ({"timeout_s": 0.0}, "timeout_s"),
        ({"timeout_s": float("nan")}, "timeout_s"),
        ({"priority": 1.5}, "priority must be an integer"),
        ({"kind": "ros2"}, "topic is given for kind ros2"),
        ({"topic": "/x"}, "topic is given for kind ros2"),
    ],
)
def test_a_bad_source_is_refused(kwargs, message):
    fields = {"name": "s", "kind": "zenoh", "priority": 1, "timeout_s": 0.5} | kwargs
    with pytest.raises(ValueError, match=message):
        SourceSpec(**fields)  # type: ignore[arg-type]
