"""map_server semantics on tiny PGM/PNG maps made here, and every MRPB map."""

from __future__ import annotations

import re

import numpy as np
import pytest
from egc_sim.map_server import classify_pixels, load_map_yaml
from egc_sim.worlds import WorldError, load_world
from PIL import Image

from tests.sim.helpers import MRPB, write_map_yaml

# p = (255 - v) / 255 with the default thresholds: occupied if p > 0.65 (v <= 89),
# free if p < 0.196 (v >= 206), unknown in between (90 <= v <= 205).
VALUES = np.array([[0, 89, 90, 150, 205, 206, 254, 255]], dtype=np.uint8)
OCCUPIED = [True, True, False, False, False, False, False, False]
UNKNOWN = [False, False, True, True, True, False, False, False]


def test_thresholds_follow_map_server(tmp_path):
    world = load_map_yaml(write_map_yaml(tmp_path, VALUES))
    assert world.occupied[0].tolist() == OCCUPIED
    assert world.unknown[0].tolist() == UNKNOWN
    assert world.free[0].tolist() == [not (o or u) for o, u in zip(OCCUPIED, UNKNOWN, strict=True)]
    assert world.occupancy[0].tolist() == [o or u for o, u in zip(OCCUPIED, UNKNOWN, strict=True)]


def test_negate_swaps_black_and_white(tmp_path):
    # negate: 1 -> p = v / 255: occupied if v >= 166, free if v <= 49, unknown in between.
    pixels = np.array([[0, 49, 50, 165, 166, 255]], dtype=np.uint8)
    world = load_map_yaml(write_map_yaml(tmp_path, pixels, negate=1))
    assert world.occupied[0].tolist() == [False, False, False, False, True, True]
    assert world.unknown[0].tolist() == [False, False, True, True, False, False]


def test_custom_thresholds(tmp_path):
    pixels = np.array([[100, 128, 200]], dtype=np.uint8)  # p = 0.608, 0.498, 0.216
    world = load_map_yaml(write_map_yaml(tmp_path, pixels, occupied_thresh=0.5, free_thresh=0.3))
    assert world.occupied[0].tolist() == [True, False, False]
    assert world.free[0].tolist() == [False, False, True]


def test_image_row_zero_is_the_top_and_origin_is_the_lower_left_pixel(tmp_path):
    pixels = np.full((3, 4), 254, dtype=np.uint8)
    pixels[0, 0] = 0  # top-left pixel of the image
    world = load_map_yaml(write_map_yaml(tmp_path, pixels, origin=(-1.0, 2.0, 0.0), resolution=0.5))
    assert world.occupancy.shape == (3, 4)
    assert world.occupancy[2, 0] and world.occupancy.sum() == 1  # the top row is the last row
    assert (world.width_m, world.height_m) == (2.0, 1.5)
    assert world.origin == (-1.0, 2.0)
    assert world.blocked_at(-0.75, 3.25)  # centre of the top-left pixel in world coordinates
    assert not world.blocked_at(-0.75, 2.25)  # bottom-left pixel: free
    assert world.blocked_at(-1.01, 2.25)  # outside the grid blocks


def test_trinary_averages_alpha_scale_does_not():
    # RGBA grey 200 with alpha 255: trinary averages 4 channels -> 213.75 (free),
    # scale ignores alpha -> 200 (p = 0.2157, unknown).
    rgba = np.array([[[200, 200, 200, 255]]], dtype=np.uint8)
    occ_t, unk_t = classify_pixels(rgba, False, 0.65, 0.196, "trinary")
    occ_s, unk_s = classify_pixels(rgba, False, 0.65, 0.196, "scale")
    assert not occ_t[0, 0] and not unk_t[0, 0]
    assert not occ_s[0, 0] and unk_s[0, 0]


def test_png_rgb_map(tmp_path):
    rgb = np.zeros((2, 2, 3), dtype=np.uint8)
    rgb[0, 0] = (255, 255, 255)  # free
    rgb[0, 1] = (255, 0, 0)  # mean 85 -> p = 0.667 -> occupied
    rgb[1, :] = (205, 205, 205)  # unknown
    Image.fromarray(rgb, "RGB").save(tmp_path / "map.png")
    (tmp_path / "map.yaml").write_text(
        "image: map.png\nresolution: 0.1\norigin: [0, 0, 0]\nnegate: 0\n"
        "occupied_thresh: 0.65\nfree_thresh: 0.196\nmode: trinary\n"
    )
    world = load_map_yaml(tmp_path / "map.yaml")
    assert world.free[1].tolist() == [True, False]  # image row 0 -> grid row 1
    assert world.occupied[1].tolist() == [False, True]
    assert world.unknown[0].tolist() == [True, True]


@pytest.mark.parametrize(
    ("yaml_text", "message"),
    [
        ("image: map.pgm\nresolution: 0.05\n", "missing key"),
        ("[unclosed", "not valid YAML"),
        ("- a list\n", "expected a YAML mapping"),
        (
            "image: map.pgm\nresolution: -1\norigin: [0, 0, 0]\nnegate: 0\n"
            "occupied_thresh: 0.65\nfree_thresh: 0.196\n",
            "resolution must be positive",
        ),
        (
            "image: map.pgm\nresolution: 0.05\norigin: [0, 0, 0.5]\nnegate: 0\n"
            "occupied_thresh: 0.65\nfree_thresh: 0.196\n",
            "yaw",
        ),
        (
            "image: map.pgm\nresolution: 0.05\norigin: [0, 0, 0]\nnegate: 0\n"
            "occupied_thresh: 0.65\nfree_thresh: 0.196\nmode: raw\n",
            "mode 'raw' is not supported",
        ),
        (
            "image: missing.pgm\nresolution: 0.05\norigin: [0, 0, 0]\nnegate: 0\n"
            "occupied_thresh: 0.65\nfree_thresh: 0.196\n",
            "map image not found",
        ),
        (
            "image: map.pgm\nresolution: 0.05\norigin: [0, 0, 0]\nnegate: 2\n"
            "occupied_thresh: 0.65\nfree_thresh: 0.196\n",
            "negate must be 0 or 1",
        ),
    ],
)
def test_bad_maps_raise_clear_errors(tmp_path, yaml_text, message):
    (tmp_path / "map.pgm").write_bytes(b"P5\n1 1\n255\n\x00")
    (tmp_path / "map.yaml").write_text(yaml_text)
    with pytest.raises(WorldError, match=message):
        load_map_yaml(tmp_path / "map.yaml")


def test_unreadable_image_and_missing_yaml(tmp_path):
    write_map_yaml(tmp_path, VALUES)
    (tmp_path / "map.pgm").write_bytes(b"not an image")
    with pytest.raises(WorldError, match="cannot read map image"):
        load_map_yaml(tmp_path / "map.yaml")
    with pytest.raises(WorldError, match="map file not found"):
        load_world(str(tmp_path / "nope.yaml"))


def _pgm_size(path):
    header = re.match(rb"P5\s+(?:#.*\s+)*(\d+)\s+(\d+)", path.read_bytes())
    assert header, path
    return int(header.group(1)), int(header.group(2))


@pytest.mark.skipif(
    not MRPB.is_dir(), reason=f"MRPB maps not found at {MRPB} (../shared beside the repo)"
)
@pytest.mark.parametrize(
    "name", sorted(p.parent.name for p in MRPB.glob("*/map.yaml")) if MRPB.is_dir() else []
)
def test_every_mrpb_map_loads_with_its_size_in_metres(name):
    folder = MRPB / name
    cols, rows = _pgm_size(folder / "map.pgm")
    meta = (folder / "map.yaml").read_text()
    resolution = float(re.search(r"resolution:\s*([0-9.]+)", meta).group(1))
    world = load_world(str(folder / "map.yaml"))
    assert world.occupancy.shape == (rows, cols)
    assert world.width_m == pytest.approx(cols * resolution)
    assert world.height_m == pytest.approx(rows * resolution)
    # Real maps have free space, walls and (outside the building) unknown cells.
    assert world.free.any() and world.occupied.any()


@pytest.mark.skipif(not MRPB.is_dir(), reason=f"MRPB maps not found at {MRPB}")
def test_shipped_office02_is_the_mrpb_map():
    shipped = load_world("office02")
    original = load_world(str(MRPB / "office02" / "map.yaml"))
    assert (shipped.width_m, shipped.height_m) == (30.0, 30.0)
    assert shipped.origin == original.origin == (-15.0, -15.0)
    assert np.array_equal(shipped.occupancy, original.occupancy)
