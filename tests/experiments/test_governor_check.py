"""governor_check: collisions with the governor on and off, counted and tested (one-sided)."""

from __future__ import annotations

import json

from egc_experiments.governor_check import main, report


def run(op: str, delay: float, on: bool, collided: bool, speed: float | None = None) -> dict:
    return {
        "operator": op,
        "delay_ms": delay,
        "link_aware": on,
        "collided": collided,
        "contact_speed_mps": speed if collided else None,
    }


def test_counts_moving_contacts_and_tests_the_totals():
    runs = [run("a", 0, True, False), run("a", 0, False, True, 1.0)]
    runs += [run("a", 200, True, i < 2, 0.0) for i in range(20)]  # 2 turns in place
    runs += [run("a", 200, False, i < 12, 1.2) for i in range(20)]  # 12 moving contacts
    text = report(runs)
    assert "| `a` | 0 | 1 | 0 / 1 | 0 / 1 |" in text
    assert "| `a` | 200 | 20 | 2 / 12 | 0 / 12 |" in text
    total = next(line for line in text.splitlines() if line.startswith("| `a` | 20 |"))
    cells = [c.strip() for c in total.strip("|").split("|")]
    assert cells[2] == "2 / 12" and float(cells[3]) < 0.01  # fewer with the governor
    assert cells[4] == "0 / 12" and float(cells[5]) < 0.001


def test_no_difference_is_not_significant():
    runs = [run("a", 100, on, i < 5, 1.0) for on in (True, False) for i in range(20)]
    total = next(line for line in report(runs).splitlines() if line.startswith("| `a` | 20 |"))
    assert float(total.strip("|").split("|")[3]) > 0.5


def test_bad_input_is_one_line_and_exit_2(tmp_path, capsys):
    missing = tmp_path / "none.jsonl"
    assert main([str(missing)]) == 2
    bad = tmp_path / "bad.jsonl"
    bad.write_text(json.dumps({"operator": "a"}) + "\n")
    assert main([str(bad)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and all(line.startswith("governor_check: ") for line in err)


def test_the_speed_cap_alone_is_a_third_arm_compared_with_both():
    runs = [run("a", 200, True, i < 2, 1.0) for i in range(20)]
    runs += [run("a", 200, False, i < 10, 1.0) for i in range(20)]
    capped = [run("a", 200, True, i < 12, 1.0) | {"latency_turn_cap": False} for i in range(20)]
    text = report(runs + capped)
    assert "| `a` | 200 | 20 | 2 / 10 | 2 / 10 |" in text  # on / off: the speed cap is not pooled
    assert "collided, speed cap / off" in text and "| `a` | 200 | 20 | 12 / 10 | 12 / 10 |" in text
    assert "collided, on / speed cap" in text and "| `a` | 200 | 20 | 2 / 12 | 2 / 12 |" in text
    assert "speed cap" not in report(runs)
