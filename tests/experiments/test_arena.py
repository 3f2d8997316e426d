"""The arena runner end to end on a tiny configuration (2 random worlds, 2 filters)."""

from __future__ import annotations

import json

import pytest
from egc_experiments import arena


def test_arena_runs_every_filter_on_the_same_worlds_and_writes_the_report(tmp_path):
    out = tmp_path / "arena"
    report = tmp_path / "filters.md"
    argv = [
        "--out", str(out), "--report", str(report), "--worlds", "2", "--filters", "none,egc",
        "--suites", "random", "--jobs", "1", "--quiet",
    ]  # fmt: skip
    assert arena.main(argv) == 0

    records = [json.loads(line) for line in (out / "runs.jsonl").read_text().splitlines()]
    assert len(records) == 2 * 2 * 2  # worlds x operators x filters
    assert {r["case"] for r in records} == {"random:0", "random:1"}
    assert {(r["operator"], r["filter"]) for r in records} == {
        (op, f) for op in ("goal", "sighted") for f in ("none", "egc")
    }
    for r in records:
        assert "error" not in r
        assert r["outcome"] in ("reached", "collided", "stalled", "timeout")
        assert r["profile"] == "jackal" and r["via"] == "goal" and r["suite"] == "random"
        assert r["max_time_s"] >= arena.MIN_TIME_S and r["stall_time_s"] == arena.STALL_TIME_S
    # Same world, start, goal and via points for every filter and operator of a case.
    by_case: dict[str, set[str]] = {}
    for r in records:
        s = dict(r["settings"], filter=None, operator=None)
        by_case.setdefault(r["case"], set()).add(json.dumps(s, sort_keys=True))
    assert all(len(v) == 1 for v in by_case.values())
    # Shared mode never touches anything (the must-show); direct mode is counted, not judged.
    assert not arena.shared_collisions(records)

    text = report.read_text()
    assert "python -m egc_experiments.arena --out" in text
    assert "| filter | mode | random | all |" in text
    for f in ("none", "egc"):
        n = sum(r["filter"] == f for r in records)
        collided = sum(r["filter"] == f and r["outcome"] == "collided" for r in records)
        assert f"| {f} | {'direct' if f == 'none' else 'shared'} | {collided} / {n} |" in text
    assert "| goal | egc | 2 |" in text and "| sighted | none | 2 |" in text


def test_reuse_takes_episodes_with_the_same_settings_and_code(tmp_path):
    cases = arena.build_cases(["random"], 1)
    todo = arena.episodes(cases, ["egc"], ["goal"])
    first = arena.run_arena(todo, jobs=1, progress=False)
    marked = [dict(first[0], wall_s=-1.0)]  # a reused record keeps its own values
    again = arena.run_arena(todo, jobs=1, reuse=marked, progress=False)
    assert again[0]["wall_s"] == -1.0
    stale = [dict(marked[0], code="0" * 12)]  # other code: run again
    assert arena.run_arena(todo, jobs=1, reuse=stale, progress=False)[0]["wall_s"] >= 0


@pytest.mark.skipif(not arena.MRPB_DIR.is_dir(), reason="the MRPB maps are not on this machine")
def test_mrpb_tests_are_the_nineteen_start_goal_pairs():
    tests = arena.mrpb_tests()
    assert len(tests) == 19
    _name, path, start, goal = next(t for t in tests if t[0] == "office02#1")
    assert path.name == "map.yaml" and start == (-12.547, 8.542, 0.0) and goal == (13.059, 1.702)


def test_first_world_picks_the_seeds_of_the_random_worlds(capsys):
    cases = arena.build_cases(["random"], 2, first_world=1000)
    assert [c.name for c in cases] == ["random:1000", "random:1001"]
    assert [c.settings.seed for c in cases] == [1000, 1001]
    assert arena.main(["--out", "/nonexistent-never", "--first-world", "-1"]) == 2
    assert "--first-world must be >= 0" in capsys.readouterr().err


def _arena_main(tmp_path, capsys, *extra: str) -> tuple[int, str]:
    out = tmp_path / "out"
    code = arena.main(["--out", str(out), "--jobs", "1", "--quiet", *extra])
    err = capsys.readouterr().err
    assert not out.exists()  # nothing written for a run of nothing
    return code, err


def test_a_suite_that_finds_no_worlds_is_one_error_line_and_exit_2(tmp_path, capsys):
    """Outside check: '--suites mrpb' where the default ../shared does not exist ran 0
    episodes, exit 0, and reported 'no shared-mode episode touched anything'."""
    missing = tmp_path / "no-such-dir"
    code, err = _arena_main(tmp_path, capsys, "--suites", "mrpb", "--mrpb-dir", str(missing))
    assert code == 2 and len(err.splitlines()) == 1
    assert str(missing) in err and "does not exist" in err and "--mrpb-dir" in err
    empty = tmp_path / "empty"
    empty.mkdir()
    code, err = _arena_main(tmp_path, capsys, "--suites", "hallway,mrpb", "--mrpb-dir", str(empty))
    assert code == 2 and len(err.splitlines()) == 1
    assert str(empty) in err and "tests.txt" in err and "--mrpb-dir" in err
    code, err = _arena_main(tmp_path, capsys, "--suites", "random", "--worlds", "0")
    assert code == 2 and len(err.splitlines()) == 1 and "--worlds" in err
