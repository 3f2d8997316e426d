"""docs/make_figures.py regenerates the Fig. 9 and Fig. 11 style PNGs."""

from __future__ import annotations

import importlib.util
from pathlib import Path

from PIL import Image

SCRIPT = Path(__file__).resolve().parents[2] / "docs" / "make_figures.py"


def test_make_figures_writes_both_pngs(tmp_path):
    spec = importlib.util.spec_from_file_location("make_figures", SCRIPT)
    assert spec and spec.loader
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    assert module.main(["--out-dir", str(tmp_path)]) == 0
    for name in ("fig9_hallway_trajectory.png", "fig11_commands.png"):
        with Image.open(tmp_path / name) as im:
            assert im.width > 800 and im.height > 300
            assert len(im.convert("RGB").getcolors(1_000_000) or []) > 20  # not a blank canvas
