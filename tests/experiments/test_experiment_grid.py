"""Experiment grids (DESIGN 10): sweeps of products, defaults, worlds, and one-line errors."""

from __future__ import annotations

import tomllib
from pathlib import Path

import pytest
from egc_experiments.experiment_cli import check_point
from egc_experiments.grid import GridError, load_grid, parse_grid
from egc_experiments.run_point import RunPoint


def grid(text: str, check: bool = False):
    return parse_grid(tomllib.loads(text), "g.toml", check_point if check else None)


def test_a_sweep_is_the_product_of_its_lists():
    g = grid(
        """
        operator = "sighted"
        seeds = 2
        [[sweep]]
        world = ["hallway", "random"]
        filter = ["none", "egc"]
        delay_ms = [0, 100, 200]
        link_aware = [true, false]
        """
    )
    assert len(g.points) == 2 * 2 * 3 * 2 * 2
    p = g.points[0]
    assert (p.world, p.operator, p.filter, p.mode, p.transport) == (
        "hallway",
        "sighted",
        "none",
        "direct",
        "tcp",
    )
    assert {q.mode for q in g.points if q.filter == "egc"} == {"shared"}
    assert {q.seed for q in g.points} == {0, 1}
    assert p.max_time_s == 150.0 and p.stall_time_s == 30.0 and p.outages == ()


def test_sweeps_share_defaults_and_common_points_run_once():
    g = grid(
        """
        world = "random:1"
        operator = "goal"
        filter = "egc"
        [[sweep]]
        name = "delay"
        delay_ms = [0, 100]
        [[sweep]]
        name = "jitter"
        delay_ms = 100
        jitter_frac = [0, 0.3]
        [[sweep]]
        name = "outage"
        transport = ["tcp", "udp"]
        delay_ms = 100
        outage_s = [0, 2.5]
        outage_start_s = 4
        """
    )
    assert g.sweeps == ("delay", "jitter", "outage")
    keys = {(p.delay_ms, p.jitter_ms, p.transport, p.outages) for p in g.points}
    assert keys == {
        (0.0, 0.0, "tcp", ()),
        (100.0, 0.0, "tcp", ()),
        (100.0, 30.0, "tcp", ()),
        (100.0, 0.0, "tcp", ((4.0, 2.5),)),
        (100.0, 0.0, "udp", ()),
        (100.0, 0.0, "udp", ((4.0, 2.5),)),
    }
    assert len(g.points) == len(keys)


def test_named_worlds_give_start_goal_and_time():
    g = grid(
        """
        operator = "route"
        [worlds.office]
        map = "office02"
        start = [-7.0, -1.0, 1.5708]
        goal = [-2.0, 3.6]
        max_time_s = 90
        [[sweep]]
        world = ["office", "hallway"]
        mode = ["direct", "shared"]
        filter = "egc"
        transport = "udp"
        loss = [0, 5]
        burst = [0, 3]
        """,
        check=True,
    )
    office = [p for p in g.points if p.world == "office02"]
    assert office and all(p.start == (-7.0, -1.0, 1.5708) for p in office)
    assert all(p.goal == (-2.0, 3.6) and p.max_time_s == 90 for p in office)
    hallway = [p for p in g.points if p.world == "hallway"]
    assert all(p.start is None and p.max_time_s == 150 for p in hallway)
    assert {p.mode for p in g.points} == {"direct", "shared"}


def test_a_grid_file_is_read(tmp_path):
    path = tmp_path / "g.toml"
    path.write_text('world = "hallway"\noperator = "forward"\n[[sweep]]\ndelay_ms = [0, 50]\n')
    assert [p.delay_ms for p in load_grid(path).points] == [0.0, 50.0]


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("world = 'hallway'\noperator = 'goal'\n", "at least one \\[\\[sweep\\]\\]"),
        ("colour = 1\n[[sweep]]\nworld = 'hallway'\noperator = 'goal'\n", "unknown key.*colour"),
        (
            "[[sweep]]\nworld = 'hallway'\noperator = 'goal'\nspeed = 2\n",
            "sweep 1.*unknown key.*speed",
        ),
        ("[[sweep]]\nworld = 'hallway'\n", "no operator"),
        ("[[sweep]]\noperator = 'goal'\nworld = []\n", "world is an empty list"),
        ("[[sweep]]\nname='x'\nworld='hallway'\noperator='goal'\nloss=5\n", "sweep 'x'.*TCP"),
        (
            "[[sweep]]\nworld='hallway'\noperator='goal'\ntransport='udp'\nburst=3\n",
            "burst without loss",
        ),
        (
            "[[sweep]]\nworld='hallway'\noperator='goal'\njitter_ms=[1]\njitter_frac=[0.1]\n",
            "not both",
        ),
        ("[[sweep]]\nworld='hallway'\noperator='goal'\nmode='auto'\n", "mode 'auto'"),
        ("[[sweep]]\nworld='hallway'\noperator='goal'\ntransport='quic'\n", "transport 'quic'"),
        ("[[sweep]]\nworld='hallway'\noperator='goal'\ndelay_ms=-5\n", "outside"),
        ("[[sweep]]\nworld='hallway'\noperator='goal'\nloss=150\n", "outside"),
        ("[[sweep]]\nworld='hallway'\noperator='goal'\nseeds=[1.5]\n", "seeds"),
        ("[[sweep]]\nworld='hallway'\noperator='goal'\nlink_aware='yes'\n", "true or false"),
        ("[worlds.a]\nstart=[0,0,0]\n[[sweep]]\nworld='a'\noperator='goal'\n", "needs map"),
        ("[worlds.a]\nmap='hallway'\nstart=[0,0]\n[[sweep]]\nworld='a'\noperator='goal'\n", "3"),
    ],
)
def test_grid_errors_are_one_clear_line(text, message):
    with pytest.raises(GridError, match=message) as info:
        grid(text)
    assert "\n" not in str(info.value)


@pytest.mark.parametrize(
    ("axes", "message"),
    [
        ("world='atlantis'\noperator='goal'", "world 'atlantis'"),
        ("world='hallway'\noperator='goal'\nfilter='magic'", "unknown filter 'magic'"),
        ("world='hallway'\noperator='pilot'", "operator 'pilot'"),
        ("world='hallway'\noperator='sighted:speed=1'", "unknown option"),
        ("world='hallway'\noperator='goal'\nprofile='tank'", "unknown profile 'tank'"),
    ],
)
def test_unknown_names_are_found_before_running(axes, message):
    with pytest.raises(GridError, match=message):
        grid(f"[[sweep]]\n{axes}\n", check=True)


def test_a_goal_outside_its_map_is_one_line_naming_the_world_entry():
    """As ``egc-teleop episode`` says it, with the [worlds.NAME] entry it came from; a goal on
    the map (or on its edge) passes, and a bad start pose is named the same way."""
    text = "[worlds.far]\nmap='hallway'\ngoal={goal}\n[[sweep]]\nworld='far'\noperator='goal'\n"
    message = r"g.toml: \[worlds.far\]: goal 1000,-3 is outside map 'hallway' \(x -0.2 to 18.2, y"
    with pytest.raises(GridError, match=message) as info:
        grid(text.format(goal="[1000, -3]"), check=True)
    assert "\n" not in str(info.value)
    assert grid(text.format(goal="[18.2, 2]"), check=True).points[0].goal == (18.2, 2.0)
    with pytest.raises(GridError, match=r"\[worlds.far\]: world 'hallway': start pose"):
        grid(text.format(goal="[5, 2]").replace("goal=", "start=[500, 0, 0]\ngoal="), check=True)


def test_files_that_are_not_grids(tmp_path):
    with pytest.raises(GridError, match="does not exist"):
        load_grid(tmp_path / "missing.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("[[sweep]\nworld = ")
    with pytest.raises(GridError, match="not valid TOML"):
        load_grid(bad)


def test_run_point_key_tells_points_apart():
    a = RunPoint("hallway", "sighted", link_aware=True)
    assert a.key() == RunPoint("hallway", "sighted", link_aware=True).key()
    assert a.key() != RunPoint("hallway", "sighted", link_aware=False).key()
    assert a.key() != RunPoint("hallway", "sighted", stall_time_s=10).key()
    # The turn cap, added later, is on by default and leaves the keys of earlier runs alone.
    assert "latency_turn_cap" not in a.key()
    assert a.key() != RunPoint("hallway", "sighted", latency_turn_cap=False).key()


def test_latency_turn_cap_is_an_axis_and_the_report_labels_it():
    from egc_experiments.report import link_aware

    g = grid(
        """
        world = "hallway"
        operator = "sighted"
        filter = "none"
        [[sweep]]
        latency_turn_cap = [true, false]
        """
    )
    assert sorted(p.latency_turn_cap for p in g.points) == [False, True]
    with pytest.raises(GridError, match="latency_turn_cap values must be true or false"):
        grid("[[sweep]]\nworld='hallway'\noperator='goal'\nlatency_turn_cap=1\n")
    assert link_aware({"link_aware": True}) == "on"  # rows written before the option
    assert link_aware({"link_aware": True, "latency_turn_cap": False}) == "speed cap"
    assert link_aware({"link_aware": False, "latency_turn_cap": False}) == "off"


def test_rate_kbps_axis_reaches_the_link_spec(tmp_path: Path) -> None:
    """DESIGN 12's thin links in the lab: rate_kbps sweeps the relay's rate= (0: none), and a
    point without a rate keeps the resume key it had before the axis existed."""
    from egc_experiments.grid import load_grid
    from egc_experiments.run_point import RunPoint

    grid = tmp_path / "rate.toml"
    grid.write_text(
        'world = "corridor"\noperator = "forward"\n[[sweep]]\ndelay_ms = 80\nrate_kbps = [0, 192]\n',
        encoding="utf-8",
    )
    points = load_grid(grid).points
    assert [p.rate_kbps for p in points] == [0.0, 192.0]
    assert points[0].link_spec() == "delay=80"
    assert points[1].link_spec() == "delay=80,rate=192"
    assert "rate_kbps" not in points[0].key() and "rate_kbps" in points[1].key()
    bad = tmp_path / "bad.toml"
    bad.write_text(
        'world = "corridor"\noperator = "forward"\n[[sweep]]\nrate_kbps = -1\n', encoding="utf-8"
    )
    with pytest.raises(ValueError, match="rate_kbps"):
        load_grid(bad)
    assert RunPoint("w", "forward").rate_kbps == 0.0


def test_a_grid_takes_profile_files(tmp_path):
    """DESIGN 14: a grid's profile is a built-in name or a FILE.toml; a bad file is the grid's
    one line naming the key."""
    pentagon = Path(__file__).resolve().parents[2] / "docs" / "profiles" / "pentagon.toml"
    g = grid(
        f"""
        world = "hallway"
        operator = "sighted"
        filter = "egc"
        [[sweep]]
        profile = ["turtlebot4", "{pentagon}"]
        """,
        check=True,
    )
    assert {p.profile for p in g.points} == {"turtlebot4", str(pentagon)}
    bad = tmp_path / "bad.toml"
    bad.write_text(pentagon.read_text().replace("v_max = 0.8", "v_max = -0.8"))
    with pytest.raises(GridError, match=r"bad.toml: v_max: must be positive"):
        grid(f'world = "hallway"\noperator = "sighted"\n[[sweep]]\nprofile = "{bad}"\n', check=True)
