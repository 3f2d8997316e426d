"""The web-viewer screenshot (issue 5): the script runs in headless Chromium when it is installed."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from egc_operator import view_blueprint as paths
from egc_operator.view_scene import SENT_RED, TRAJECTORY_TEAL
from PIL import Image

from tests.view.rrd import read_recording

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "docs" / "screenshot_web_viewer.py"
sys.path.insert(0, str(SCRIPT.parent))
import screenshot_web_viewer  # noqa: E402


def test_the_synthetic_corridor_run_is_a_full_operator_recording(tmp_path: Path) -> None:
    """What the screenshot shows by default: EGC acting, scans of 720 points, a map."""
    run = screenshot_web_viewer.corridor_run(14.0)
    assert {t.limiter for t in run} >= {"none", "egc"}
    assert all(len(t.scan_xy) == screenshot_web_viewer.BEAMS for t in run)
    rrd = screenshot_web_viewer.record_corridor_run(tmp_path / "corridor.rrd", 14.0)
    rec = read_recording(rrd)
    assert len(rec["/" + paths.SCAN]) == len(run)
    assert "/" + paths.MAP in rec and len(rec["/" + paths.TEXT_LOG]) >= 3


def _pixels_near(image: np.ndarray, colour: tuple[int, int, int], tolerance: int = 25) -> int:
    return int((np.abs(image - np.array(colour)).max(axis=2) <= tolerance).sum())


@pytest.mark.browser
@pytest.mark.slow
@pytest.mark.skipif(
    screenshot_web_viewer.find_chromium() is None,
    reason="chromium is not installed (apt-get install chromium; CI installs it)",
)
def test_screenshot_of_the_web_viewer_shows_the_recording(tmp_path: Path) -> None:
    png = tmp_path / "web_viewer.png"
    done = subprocess.run(
        [sys.executable, str(SCRIPT), "--out", str(png)],
        capture_output=True,
        text=True,
        timeout=180,
    )
    assert done.returncode == 0, done.stderr
    image = Image.open(png)
    assert image.size == (1600, 1000)
    pixels = np.asarray(image.convert("RGB")).astype(int)
    assert len(np.unique(pixels.reshape(-1, 3), axis=0)) > 100  # not a flat or blank page
    # The recording itself is drawn, not just the viewer's chrome: the world view's trajectory
    # (teal) and the sent command / expanded guide circle (red) are on screen.
    assert _pixels_near(pixels, TRAJECTORY_TEAL) > 50
    assert _pixels_near(pixels, SENT_RED) > 200


def test_script_without_chromium_says_so(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setattr(shutil, "which", lambda name: None)
    assert screenshot_web_viewer.main(["--out", "unused.png"]) == 2
    assert "chromium is not installed" in capsys.readouterr().err
