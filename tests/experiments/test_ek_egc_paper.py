"""The EK-EGC paper's experiment (egc_experiments.ek_egc_paper) on the ek_egc_paper world."""

from __future__ import annotations

import pytest
from egc_experiments import ek_egc_paper as exp
from egc_sim.worlds import builtin_names, load_world


@pytest.fixture(scope="module")
def runs():
    return exp.run_experiment()


def test_the_scene_is_shipped_as_reconstructed():
    assert "ek_egc_paper" in builtin_names()
    world = load_world("ek_egc_paper")
    assert world.start_pose == (0.0, 0.0, 0.0)
    assert world.goal == (5.0, 0.0)
    # The box sits on the straight line from start to goal.
    col = round((2.5 - world.origin_x_m) / world.resolution_m)
    row = round((0.0 - world.origin_y_m) / world.resolution_m)
    assert world.occupancy[row, col]


def test_zigzag_counts_sign_changes_of_dw():
    # dw = +0.1, -0.1, +0.1, 0 (skipped), +0.1: two sign changes
    assert exp.zigzag([0.0, 0.1, 0.0, 0.1, 0.1, 0.2]) == (2, pytest.approx(0.4))
    assert exp.zigzag([0.0, 0.1, 0.2, 0.3]) == (0, pytest.approx(0.3))
    assert exp.zigzag([0.0, 0.0005, 0.0]) == (0, pytest.approx(0.001))  # below DW_EPS


def test_every_method_runs_without_contact_and_dwa_reaches(runs):
    assert set(runs) == set(exp.METHODS)
    for method, r in runs.items():
        assert not r.collided, method
        assert r.outcome in ("reached", "stalled", "timeout"), method
        assert r.min_clearance_m > 0.0, method
        assert len(r.t_s) == len(r.w_radps) == len(r.x_m) > 0, method
    assert runs["dwa"].reached
    assert 5.0 < runs["dwa"].distance_m < 7.0


@pytest.mark.xfail(
    reason="EGC and EK-EGC stop ~0.9 m before the box (UNSAFE region, w_SI = 0) and the goal "
    "operator's command does not pass the no-dead-lock rule: docs/ek-egc-paper.md",
    strict=False,
)
def test_egc_and_ek_egc_reach_the_goal(runs):
    assert runs["egc"].reached and runs["ek-egc"].reached


def test_table_and_orderings(runs, tmp_path):
    table = exp.table_markdown(runs)
    for label in exp.LABELS.values():
        assert label in table
    for distance, time in exp.PAPER.values():
        assert f"| {distance} | {time} |" in table
    claims = exp.orderings(runs)
    assert len(claims) == 3
    assert {o.status for o in claims} <= {"reproduced", "not reproduced", "not testable"}
    # A claim about a method that did not reach cannot be judged.
    involved = (exp.METHODS, exp.METHODS, ("egc", "ek-egc"))
    for o, methods in zip(claims, involved, strict=True):
        if not all(runs[m].reached for m in methods):
            assert o.status == "not testable", o
    md = tmp_path / "ek-egc-paper.md"
    md.write_text(f"# hand\n\n{exp.BEGIN}\nold\n{exp.END}\n\ntail\n", encoding="utf-8")
    exp.write_markdown(md, exp.results_markdown(runs, exp.SCENE, exp.PROFILE, 150.0, 10.0))
    text = md.read_text(encoding="utf-8")
    assert text.startswith("# hand") and text.rstrip().endswith("tail")
    assert "old" not in text and "DWA has the shortest path" in text


def test_cli_writes_the_figure_and_the_block(tmp_path, monkeypatch, runs):
    monkeypatch.setattr(exp, "run_experiment", lambda *a: runs)
    assert exp.main(["--out-dir", str(tmp_path)]) == 0
    assert (tmp_path / "ek-egc-paper.png").stat().st_size > 10_000
    assert exp.BEGIN in (tmp_path / "ek-egc-paper.md").read_text(encoding="utf-8")
