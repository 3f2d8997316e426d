"""Robot profiles with shapes beyond the rectangle, for tests (DESIGN 14): the documented
pentagon, a non-convex L and the round TurtleBot 4."""

from __future__ import annotations

from pathlib import Path

from egc_common.profiles import TURTLEBOT4, load_profile

ROOT = Path(__file__).resolve().parents[1]
PENTAGON_FILE = ROOT / "docs" / "profiles" / "pentagon.toml"
L_SHAPE_FILE = ROOT / "tests" / "profiles" / "l_shape.toml"

PENTAGON = load_profile(str(PENTAGON_FILE))
L_SHAPE = load_profile(str(L_SHAPE_FILE))
DISC = TURTLEBOT4
