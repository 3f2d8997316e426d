"""The joystick CSV's optional filter and via-point columns (issues 10 and 11)."""

from __future__ import annotations

import pytest
from egc_common.joystick_file import (
    SHARED_FILTERS,
    JoystickFileError,
    JoystickSample,
    parse_joystick_csv,
)
from egc_operator.command_source import load_script, script_names


def test_filter_and_via_columns_are_read():
    samples = parse_joystick_csv(
        "t_s,x,y,filter,via_next,via_clear\n0,0,0,,0,0\n1,1,0,ek-egc,1,0\n2,1,0,assist,0,1\n"
    )
    assert [s.filter for s in samples] == [None, "ek-egc", "assist"]
    assert [s.via_next for s in samples] == [False, True, False]
    assert [s.via_clear for s in samples] == [False, False, True]


def test_files_without_the_new_columns_read_as_before():
    (s,) = parse_joystick_csv("t_s,x,y,deadman,mode\n0,0.5,0,1,direct\n")
    assert s == JoystickSample(0.0, 0.5, 0.0, True, "direct")
    assert (s.filter, s.via_next, s.via_clear) == (None, False, False)
    for name in script_names():  # the shipped scripts still load
        assert load_script(name).samples


def test_shared_filters_are_the_family_without_direct_mode():
    assert SHARED_FILTERS == ("egc", "ek-egc", "assist", "dwa", "cbf")


@pytest.mark.parametrize(
    ("cell", "message"),
    [
        ("EGC", "filter must be one of egc, ek-egc, assist, dwa, cbf or empty, got 'EGC'"),
        ("none", "(direct mode is the mode column)"),
    ],
)
def test_a_bad_filter_names_the_row(cell: str, message: str):
    with pytest.raises(JoystickFileError, match="row 3") as info:
        parse_joystick_csv(f"t_s,x,y,filter\n0,0,0,egc\n1,0,0,{cell}\n", "f.csv")
    assert message in str(info.value) and str(info.value).startswith("f.csv: row 3")


def test_a_bad_via_flag_names_the_column():
    with pytest.raises(JoystickFileError, match="row 2 via_next: expected 0 or 1"):
        parse_joystick_csv("t_s,x,y,via_next\n0,0,0,maybe\n")
