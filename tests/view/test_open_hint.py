"""The hint that says how to open a saved operator view fits the machine it is printed on.

Outside "fresh user" check: after a headless demo the operator printed "open it with: rerun
FILE", which fails on that same machine (winit: no DISPLAY). Without a display the hint now
also gives ``rerun --serve-web FILE`` and the URL that shows the recording (the bare page is
Rerun's welcome screen); checked by hand headless: HTTP on 9090, gRPC on 9876, and headless
Chromium draws the recording at that URL.
"""

from __future__ import annotations

import argparse
import shutil
import urllib.parse
from pathlib import Path

import pytest
from egc_operator import viewer_target
from egc_operator.view import open_view
from egc_operator.viewer_target import add_view_arguments, open_hint

from tests.view.conftest import telemetry

FILE = Path("/data/run 1/egc-operator-sim.rrd")


def test_with_a_display_the_viewer() -> None:
    assert open_hint(FILE, display=True) == "open it with: rerun '/data/run 1/egc-operator-sim.rrd'"


def test_without_one_the_web_viewer_and_the_url_that_shows_the_data() -> None:
    hint = open_hint(FILE, display=False, rerun="/v/bin/rerun")
    assert "on a machine with a display: rerun '/data/run 1/egc-operator-sim.rrd'" in hint
    assert "run /v/bin/rerun --serve-web '/data/run 1/egc-operator-sim.rrd' and open" in hint
    url = hint.split(" and open ")[1].split()[0]
    parts = urllib.parse.urlsplit(url)
    assert (parts.scheme, parts.netloc, parts.path) == ("http", "127.0.0.1:9090", "/")
    # rerun --serve-web's own defaults: the page on 9090 reads the data from gRPC 9876
    assert urllib.parse.parse_qs(parts.query) == {"url": ["rerun+http://127.0.0.1:9876/proxy"]}


def _args(*argv: str) -> argparse.Namespace:
    parser = argparse.ArgumentParser()
    add_view_arguments(parser)
    return parser.parse_args(list(argv))


@pytest.mark.parametrize("display", [None, ":0"])
def test_the_printed_line_follows_the_environment(
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
    display: str | None,
) -> None:
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    if display is None:
        monkeypatch.delenv("DISPLAY", raising=False)
    else:
        monkeypatch.setenv("DISPLAY", display)
    # the venv not on PATH (make demo): the hint names the venv's rerun by its path
    monkeypatch.setattr(shutil, "which", lambda name: None)
    out = tmp_path / "op.rrd"
    view = open_view(_args("--save", str(out)), "sim")  # --save: a file also with a display
    view.on_telemetry(telemetry(0))
    view.close()
    err = capsys.readouterr().err
    rerun = viewer_target._rerun_executable()
    assert rerun is not None and Path(rerun).is_file()
    if display is None:
        assert f"run {rerun} --serve-web {out.resolve()} and open http://127.0.0.1:9090/" in err
    else:
        assert f"open it with: {rerun} {out.resolve()})" in err
        assert "--serve-web" not in err
