"""The robot's shape (DESIGN 14): a simple polygon in base_link, or a disc about its origin.

A profile gives the footprint as it is: a polygon ``[[x, y], ...]`` (metres, base_link, any
number of vertices up to ``MAX_VERTICES``, convex or not) or a ``radius``. Everything that decides
contact (the pipeline's footprint sweep, DWA's first contact, the simulator's collision check, the
scan's self-hits) measures against this shape; the bounding box (``bounds``) is only for code
that needs a bound (filter parameters that scale with the robot's size, the view's camera).

The geometry here is pure and vectorised over points (numpy, no loops over points):

- ``signed_distance``: positive outside, minus the distance to the edge inside. An axis-aligned
  rectangle centred on the origin (the Pioneer's and the Jackal's footprints) takes the closed
  form of ``kinematics.signed_distance_to_rectangle``, so their numbers stay exactly as before.
- ``contains``: point in polygon (crossing number), or in the disc.
- ``mitred_outline``: the polygon grown by ``g`` with sharp corners, a superset of every point
  within ``g`` of it (DWA's margin), and ``mitre_factor``, how far beyond ``g`` its corners reach.
- ``disc_cover``: discs whose union holds the footprint (a filter that reasons in discs, such as
  a control barrier function, stays conservative with them; DESIGN 13).
- ``arc_samples`` / ``swept_min_distance``: the footprint swept along a command's arc, sampled
  so that no point of it moves more than two steps between samples (the footprint sweep).
- ``outline``: the boundary as a closed list of points (the view, the info reply).

Validity (``FootprintError``, one line naming the problem): at least 3 and at most
``MAX_VERTICES`` finite vertices, no repeated vertex, no two edges crossing or touching other
than neighbours at their shared vertex (a simple polygon), and not too small: the bounding box at
least ``MIN_SIZE_M`` along x and along y and the area at least ``MIN_SIZE_M**2 / 2`` (a sliver
or a point is a typo, not a robot). Vertices are stored counter-clockwise whatever the file's
order.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from egc_common.kinematics import signed_distance_to_rectangle

FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]
Vertex = tuple[float, float]

MIN_SIZE_M = 0.05
MAX_SIZE_M = 100.0
MAX_VERTICES = 32
# Discs are drawn, sent and (for DWA's exact contact) circumscribed by this many sides.
DISC_SIDES = 32


class FootprintError(ValueError):
    """A footprint that is not a usable robot shape; the message names the problem."""


@dataclass(frozen=True, slots=True)
class Footprint:
    """A simple polygon (``vertices_m``, counter-clockwise) or a disc (``radius_m`` > 0) about
    the origin of base_link. Build one with ``polygon``, ``rectangle`` or ``disc``."""

    vertices_m: tuple[Vertex, ...] = ()
    radius_m: float = 0.0
    # Derived once (not compared): the vertices as an array, the centred-rectangle half sizes,
    # and the edges (``_edges``: starts (N, 2), vectors (N, 2), squared lengths (N,)).
    _xy: FloatArray = field(init=False, repr=False, compare=False, hash=False)
    _box: tuple[float, float] | None = field(init=False, repr=False, compare=False, hash=False)
    _edges: tuple[FloatArray, FloatArray, FloatArray] | None = field(
        init=False, repr=False, compare=False, hash=False
    )

    def __post_init__(self) -> None:
        if self.vertices_m and self.radius_m:
            raise FootprintError("give a polygon or a radius, not both")
        if not self.vertices_m:
            r = self.radius_m
            if not isinstance(r, (int, float)) or isinstance(r, bool) or not math.isfinite(r):
                raise FootprintError(f"radius must be a finite number of metres, got {r!r}")
            if r < 0.5 * MIN_SIZE_M or r > 0.5 * MAX_SIZE_M:
                raise FootprintError(
                    f"radius {r} m is out of range [{0.5 * MIN_SIZE_M}, {0.5 * MAX_SIZE_M}]"
                )
            object.__setattr__(self, "radius_m", float(r))
            object.__setattr__(self, "_xy", np.empty((0, 2)))
            object.__setattr__(self, "_box", None)
            object.__setattr__(self, "_edges", None)
            return
        xy = _checked_vertices(self.vertices_m)
        if _signed_area(xy) < 0.0:
            xy = xy[::-1].copy()
        xy.setflags(write=False)
        object.__setattr__(self, "vertices_m", tuple((float(x), float(y)) for x, y in xy))
        object.__setattr__(self, "_xy", xy)
        object.__setattr__(self, "_box", _centred_box(xy))
        object.__setattr__(self, "_edges", _edge_arrays(xy))

    # -- constructors -------------------------------------------------------------------------

    @staticmethod
    def polygon(vertices_m: Sequence[Sequence[float]]) -> Footprint:
        """A polygon from (x, y) pairs in metres, either orientation."""
        try:
            pairs = tuple((v[0], v[1]) for v in vertices_m if len(v) == 2)
        except TypeError:
            raise FootprintError("footprint must be a list of [x, y] pairs") from None
        if len(pairs) != len(vertices_m):
            raise FootprintError("footprint must be a list of [x, y] pairs")
        return Footprint(vertices_m=pairs)  # types checked there

    @staticmethod
    def rectangle(length_m: float, width_m: float) -> Footprint:
        """The length x width rectangle centred on the origin, long side along x."""
        hl, hw = 0.5 * length_m, 0.5 * width_m
        return Footprint(vertices_m=((hl, hw), (-hl, hw), (-hl, -hw), (hl, -hw)))

    @staticmethod
    def disc(radius_m: float) -> Footprint:
        return Footprint(radius_m=radius_m)

    # -- what it is ---------------------------------------------------------------------------

    @property
    def is_disc(self) -> bool:
        return not self.vertices_m

    @property
    def centred_box(self) -> tuple[float, float] | None:
        """(half length, half width) if this is an axis-aligned rectangle centred on the
        origin, else None."""
        return self._box

    @property
    def vertices(self) -> FloatArray:
        """(N, 2) counter-clockwise vertices; a disc's circumscribed ``DISC_SIDES``-gon."""
        if self.is_disc:
            return regular_polygon(self.radius_m / math.cos(math.pi / DISC_SIDES), DISC_SIDES)
        return self._xy

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        """(x_min, x_max, y_min, y_max) in metres."""
        if self.is_disc:
            r = self.radius_m
            return -r, r, -r, r
        x, y = self._xy[:, 0], self._xy[:, 1]
        return float(x.min()), float(x.max()), float(y.min()), float(y.max())

    @property
    def length_m(self) -> float:
        """Extent along x."""
        x0, x1, _, _ = self.bounds
        return x1 - x0

    @property
    def width_m(self) -> float:
        """Extent along y."""
        _, _, y0, y1 = self.bounds
        return y1 - y0

    @property
    def half_size_m(self) -> tuple[float, float]:
        """(max |x|, max |y|): the smallest box centred on the origin that holds the footprint."""
        x0, x1, y0, y1 = self.bounds
        return max(-x0, x1), max(-y0, y1)

    @property
    def reach_m(self) -> float:
        """The largest distance of a footprint point from the origin: the radius of the
        circle it sweeps turning in place."""
        if self.is_disc:
            return self.radius_m
        return float(np.hypot(self._xy[:, 0], self._xy[:, 1]).max())

    @property
    def area_m2(self) -> float:
        if self.is_disc:
            return math.pi * self.radius_m**2
        return _signed_area(self._xy)

    def outline(self) -> list[Vertex]:
        """The boundary as a closed list of points (first point repeated at the end); a disc
        as ``DISC_SIDES`` points on its circle."""
        pts = regular_polygon(self.radius_m, DISC_SIDES) if self.is_disc else self._xy
        out = [(float(x), float(y)) for x, y in pts]
        return [*out, out[0]]

    def describe(self) -> str:
        """One short line for logs and --help: 'disc r 0.171 m' or '4-gon 0.455 x 0.381 m'."""
        if self.is_disc:
            return f"disc r {self.radius_m:g} m"
        kind = "rectangle" if self._box is not None else f"{len(self.vertices_m)}-gon"
        return f"{kind} {self.length_m:g} x {self.width_m:g} m"


# -- geometry ----------------------------------------------------------------------------------


def signed_distance(fp: Footprint, x_m: npt.ArrayLike, y_m: npt.ArrayLike) -> FloatArray:
    """Signed distance (m) from points to the footprint: positive outside, minus the distance
    to the edge inside. ``x_m`` and ``y_m`` broadcast together; the result has their shape."""
    x = np.asarray(x_m, dtype=np.float64)
    y = np.asarray(y_m, dtype=np.float64)
    if fp.is_disc:
        out: FloatArray = np.hypot(x, y) - fp.radius_m
        return out
    box = fp.centred_box
    if box is not None:
        return signed_distance_to_rectangle(x, y, *box)
    return polygon_signed_distance(fp.vertices, x, y)


def contains(fp: Footprint, x_m: npt.ArrayLike, y_m: npt.ArrayLike) -> BoolArray:
    """Whether each point is inside the footprint or on its edge."""
    out: BoolArray = signed_distance(fp, x_m, y_m) <= 0.0
    return out


def polygon_signed_distance(vertices: FloatArray, x: FloatArray, y: FloatArray) -> FloatArray:
    """Signed distance from points to a simple polygon ((N, 2) vertices, either orientation):
    the distance to the nearest edge, negative inside (crossing number)."""
    x, y = np.broadcast_arrays(np.asarray(x, np.float64), np.asarray(y, np.float64))
    shape = x.shape
    px, py = x.reshape(-1, 1), y.reshape(-1, 1)
    x0, y0 = vertices[:, 0], vertices[:, 1]
    x1, y1 = np.roll(x0, -1), np.roll(y0, -1)
    ex, ey = x1 - x0, y1 - y0
    dx, dy = px - x0, py - y0  # (M, N)
    t = np.clip((dx * ex + dy * ey) / (ex * ex + ey * ey), 0.0, 1.0)
    qx, qy = dx - t * ex, dy - t * ey
    dist = np.sqrt((qx * qx + qy * qy).min(axis=1))
    # Crossing number: edges that straddle the horizontal line through the point, crossed
    # to the right of it.
    straddle = (y0 > py) != (y1 > py)
    with np.errstate(divide="ignore", invalid="ignore"):
        x_cross = x0 + (py - y0) * ex / ey
    inside = (np.count_nonzero(straddle & (px < x_cross), axis=1) % 2) == 1
    out: FloatArray = np.where(inside, -dist, dist).reshape(shape)
    return out


def closest_boundary_points(
    fp: Footprint, x_m: npt.ArrayLike, y_m: npt.ArrayLike
) -> tuple[FloatArray, FloatArray]:
    """For each point (1-D arrays), the nearest point of the footprint's edge."""
    x = np.asarray(x_m, dtype=np.float64).ravel()
    y = np.asarray(y_m, dtype=np.float64).ravel()
    if fp.is_disc:
        r = np.hypot(x, y)
        safe = np.where(r > 0.0, r, 1.0)
        ux, uy = np.where(r > 0.0, x / safe, 1.0), np.where(r > 0.0, y / safe, 0.0)
        bx: FloatArray = fp.radius_m * ux
        by: FloatArray = fp.radius_m * uy
        return bx, by
    q = closest_boundary_xy(fp, np.column_stack((x, y)))
    return q[:, 0], q[:, 1]


def closest_boundary_xy(fp: Footprint, xy: FloatArray) -> FloatArray:
    """``closest_boundary_points`` of a polygon's (N, 2) points as (N, 2): the nearest point of
    each edge (the projection clamped to the edge), the nearest of those. x and y ride along
    one axis, so each step is one numpy call (a filter calls this on a few dozen points per
    command, where numpy's per-call cost is most of the time)."""
    edges = fp._edges
    if edges is None:
        raise ValueError("closest_boundary_xy takes a polygon footprint")
    start, edge, length2 = edges
    d = xy[:, None, :] - start  # (M, N, 2): point minus edge start
    de = d * edge
    # The projection's parameter along each edge, clamped to it (np.clip's min(max()), cheaper).
    t = np.minimum(np.maximum((de[..., 0] + de[..., 1]) / length2, 0.0), 1.0)
    c = start + t[..., None] * edge  # nearest point of each edge
    r = xy[:, None, :] - c
    r *= r
    k = np.argmin(r[..., 0] + r[..., 1], axis=1)
    out: FloatArray = c[np.arange(xy.shape[0]), k]
    return out


def ray_exit_m(fp: Footprint, x0_m: float, y0_m: float, angles_rad: npt.ArrayLike) -> FloatArray:
    """How far each ray from (x0, y0) at the angles runs before it leaves the footprint (its
    first crossing of the edge); 0 for every ray when (x0, y0) is outside."""
    a = np.asarray(angles_rad, dtype=np.float64)
    if not bool(contains(fp, x0_m, y0_m)):
        return np.zeros_like(a)
    c, s = np.cos(a), np.sin(a)
    if fp.is_disc:
        b = x0_m * c + y0_m * s
        q = x0_m * x0_m + y0_m * y0_m - fp.radius_m**2  # <= 0 inside
        out_disc: FloatArray = -b + np.sqrt(np.maximum(b * b - q, 0.0))
        return out_disc
    v = fp.vertices
    px, py = v[:, 0] - x0_m, v[:, 1] - y0_m  # edge starts relative to the ray's origin
    ex, ey = np.roll(v[:, 0], -1) - v[:, 0], np.roll(v[:, 1], -1) - v[:, 1]
    # origin + t (c, s) = p + u e:  t = cross(p, e) / cross(d, e), u = cross(p, d) / cross(d, e)
    den = c[:, None] * ey - s[:, None] * ex
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (px * ey - py * ex) / den
        u = (px * s[:, None] - py * c[:, None]) / den
    hit = (den != 0.0) & (t >= 0.0) & (u >= 0.0) & (u <= 1.0)
    out: FloatArray = np.where(hit, t, np.inf).min(axis=1)
    return np.where(np.isfinite(out), out, 0.0)


def arc_samples(
    v_mps: float, w_radps: float, t_s: float, step_m: float, step_rad: float, reach_m: float
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Poses (x, y, theta) along the arc of (v, w) at k equal times in (0, t_s], in the start
    frame (chord v t sinc(w t / 2) along w t / 2).

    k is the smallest count with at most ``step_m`` of travel, ``step_rad`` of turn, and
    ``step_m`` of the turn's sweep at ``reach_m`` (the footprint's farthest point) between
    samples, so no footprint point moves more than 2 ``step_m`` from one sample to the next.
    (The third bound only adds samples for footprints reaching beyond step_m / step_rad.)
    """
    length = abs(v_mps) * t_s
    turn = abs(w_radps) * t_s
    k = max(1, math.ceil(max(length / step_m, turn / step_rad, turn * reach_m / step_m)))
    ts = np.linspace(t_s / k, t_s, k)
    theta = w_radps * ts
    half = 0.5 * theta
    chord = v_mps * ts * np.sinc(half / math.pi)
    return chord * np.cos(half), chord * np.sin(half), theta


def swept_min_distance(
    fp: Footprint,
    points: FloatArray,
    v_mps: float,
    w_radps: float,
    t_s: float,
    step_m: float,
    step_rad: float,
) -> float:
    """The smallest signed distance from ``points`` ((N, 2), start frame) to the footprint at
    the poses ``arc_samples`` gives: the footprint swept along the arc (the start pose not
    included). Between two poses no footprint point moves more than 2 ``step_m``, so the true
    minimum over the whole arc is at most ``step_m`` below the smaller of this and the start
    pose's own distance (the pipeline's sweep knows that one: the clearance now; its margin
    covers the step)."""
    if len(points) == 0 or (v_mps == 0.0 and w_radps == 0.0):
        return math.inf
    x, y, theta = arc_samples(v_mps, w_radps, t_s, step_m, step_rad, fp.reach_m)
    c, s = np.cos(theta)[:, None], np.sin(theta)[:, None]
    dx = points[None, :, 0] - x[:, None]
    dy = points[None, :, 1] - y[:, None]
    return float(signed_distance(fp, c * dx + s * dy, -s * dx + c * dy).min())


def mitre_factor(fp: Footprint) -> float:
    """How far the corners of ``mitred_outline(fp, g)`` reach from a polygon, per metre of g:
    max over the vertices of 1 / cos(half the turn there), at least 1."""
    xy = fp.vertices
    n = _outward_normals(xy)
    cos_turn = np.clip((n * np.roll(n, 1, axis=0)).sum(axis=1), -1.0, 1.0)
    return float(np.sqrt(2.0 / (1.0 + cos_turn)).max())


def mitred_outline(fp: Footprint, grow_m: float) -> FloatArray:
    """(N, 2) vertices of the polygon with every edge moved ``grow_m`` outwards and neighbouring
    edges meeting at sharp corners (a disc: its circumscribed polygon grown). It holds every
    point within ``grow_m`` of the footprint (at a reflex vertex its corner is exact, at a convex
    one the sharp corner covers the round one); no point of it is farther than
    ``mitre_factor * grow_m`` from a polygon (from a disc: than its grown circumscribed
    polygon's corners, (r + g) / cos(pi / DISC_SIDES) - r)."""
    xy = fp.vertices
    n = _outward_normals(xy)  # n[i]: edge i from vertex i to i + 1
    prev = np.roll(n, 1, axis=0)  # the edge ending at vertex i
    s = n + prev
    scale = grow_m / (1.0 + (n * prev).sum(axis=1))
    out: FloatArray = xy + s * scale[:, None]
    return out


def disc_cover(fp: Footprint, discs: int = 3) -> tuple[FloatArray, FloatArray]:
    """Centres (K, 2) and radii (K,) of discs whose union holds the footprint.

    A disc footprint is its own cover. A polygon is cut into ``discs`` equal slices across its
    longer side; each slice's part of the polygon gets the disc around its bounding box (centre
    at the box's middle, radius its half diagonal). For a rectangle this is the usual row of
    overlapping discs; for any polygon each point lies in its slice's box, so in its disc.
    """
    if fp.is_disc:
        return np.zeros((1, 2)), np.array([fp.radius_m])
    if discs < 1:
        raise ValueError("a cover needs at least one disc")
    x0, x1, y0, y1 = fp.bounds
    along_x = (x1 - x0) >= (y1 - y0)
    lo, hi = (x0, x1) if along_x else (y0, y1)
    cuts = np.linspace(lo, hi, discs + 1)
    xy = fp.vertices if along_x else fp.vertices[:, ::-1]
    centres, radii = [], []
    for a, b in itertools.pairwise(cuts):
        part = _clip_to_slab(xy, float(a), float(b))
        if len(part) == 0:
            continue
        bx0, by0 = part.min(axis=0)
        bx1, by1 = part.max(axis=0)
        c = (0.5 * (bx0 + bx1), 0.5 * (by0 + by1))
        centres.append(c if along_x else (c[1], c[0]))
        radii.append(0.5 * math.hypot(bx1 - bx0, by1 - by0))
    return np.array(centres, dtype=np.float64), np.array(radii, dtype=np.float64)


def regular_polygon(circumradius_m: float, sides: int) -> FloatArray:
    """(sides, 2) vertices of a regular polygon about the origin, the first on +x, CCW."""
    a = np.linspace(0.0, 2.0 * math.pi, sides, endpoint=False)
    return np.stack([circumradius_m * np.cos(a), circumradius_m * np.sin(a)], axis=1)


def transform(points: FloatArray, pose: tuple[float, float, float]) -> FloatArray:
    """(N, 2) points of the robot frame in the frame where the robot is at ``pose``."""
    x, y, yaw = pose
    c, s = math.cos(yaw), math.sin(yaw)
    out = np.empty_like(points, dtype=np.float64)
    out[:, 0] = x + c * points[:, 0] - s * points[:, 1]
    out[:, 1] = y + s * points[:, 0] + c * points[:, 1]
    return out


def segments_cross_boxes(
    a: FloatArray, b: FloatArray, centres: FloatArray, half_m: float
) -> BoolArray:
    """(E, M): whether segment a[e] -> b[e] meets the axis-aligned square of half side
    ``half_m`` around centres[m] (closed sets; slab test, vectorised)."""
    d = (b - a)[:, None, :]  # (E, 1, 2)
    lo = (centres - half_m)[None, :, :] - a[:, None, :]
    hi = (centres + half_m)[None, :, :] - a[:, None, :]
    with np.errstate(divide="ignore", invalid="ignore"):
        t0 = lo / d
        t1 = hi / d
    # A segment parallel to a slab is inside it for all t or for none.
    within = (lo <= 0.0) & (hi >= 0.0)
    flat = d == 0.0
    tmin = np.where(flat, np.where(within, -np.inf, np.inf), np.minimum(t0, t1))
    tmax = np.where(flat, np.where(within, np.inf, -np.inf), np.maximum(t0, t1))
    enter = np.maximum(tmin.max(axis=2), 0.0)
    leave = np.minimum(tmax.min(axis=2), 1.0)
    out: BoolArray = enter <= leave
    return out


# -- validation and helpers --------------------------------------------------------------------


def _checked_vertices(vertices: Sequence[Sequence[float]]) -> FloatArray:
    n = len(vertices)
    if n < 3:
        raise FootprintError(f"a polygon needs at least 3 vertices, got {n}")
    if n > MAX_VERTICES:
        raise FootprintError(f"a polygon may have at most {MAX_VERTICES} vertices, got {n}")
    for v in vertices:
        for c in v:
            if not isinstance(c, (int, float)) or isinstance(c, bool):
                raise FootprintError(f"vertex {list(v)!r}: coordinates must be numbers")
            if not math.isfinite(c):
                raise FootprintError(f"vertex {list(v)!r}: coordinates must be finite")
            if abs(c) > MAX_SIZE_M:
                raise FootprintError(f"vertex {list(v)!r}: coordinates beyond {MAX_SIZE_M} m")
    xy = np.array(vertices, dtype=np.float64).reshape(n, 2)
    for i in range(n):
        if np.array_equal(xy[i], xy[(i + 1) % n]):
            raise FootprintError(f"vertex {i + 1} repeats its neighbour {xy[i].tolist()}")
    crossing = _first_crossing(xy)
    if crossing is not None:
        i, j = crossing
        raise FootprintError(f"self-intersecting polygon: edges {i + 1} and {j + 1} cross")
    width, height = np.ptp(xy[:, 0]), np.ptp(xy[:, 1])
    if min(width, height) < MIN_SIZE_M:
        raise FootprintError(
            f"polygon too small: {width:.3g} x {height:.3g} m (at least {MIN_SIZE_M} m each way)"
        )
    area = abs(_signed_area(xy))
    if area < 0.5 * MIN_SIZE_M**2:
        raise FootprintError(
            f"polygon too small: area {area:.3g} m^2 (at least {0.5 * MIN_SIZE_M**2:g} m^2)"
        )
    return xy


def _first_crossing(xy: FloatArray) -> tuple[int, int] | None:
    """The first pair of edges that meet other than neighbours at their shared vertex (or
    neighbours that fold back over each other), else None."""
    n = len(xy)
    for i in range(n):
        a, b = xy[i], xy[(i + 1) % n]
        for j in range(i + 1, n):
            c, d = xy[j], xy[(j + 1) % n]
            if j == i + 1 or (i == 0 and j == n - 1):
                # Neighbours share one vertex; they must not overlap beyond it.
                shared, p, q = (b, a, d) if j == i + 1 else (a, b, c)
                if _cross(p - shared, q - shared) == 0.0 and np.dot(p - shared, q - shared) > 0:
                    return i, j
                continue
            if _segments_meet(a, b, c, d):
                return i, j
    return None


def _cross(u: FloatArray, v: FloatArray) -> float:
    return float(u[0] * v[1] - u[1] * v[0])


def _segments_meet(a: FloatArray, b: FloatArray, c: FloatArray, d: FloatArray) -> bool:
    d1, d2 = _cross(b - a, c - a), _cross(b - a, d - a)
    d3, d4 = _cross(d - c, a - c), _cross(d - c, b - c)
    if ((d1 > 0) != (d2 > 0)) and ((d3 > 0) != (d4 > 0)) and d1 and d2 and d3 and d4:
        return True

    def on(p: FloatArray, q: FloatArray, r: FloatArray, side: float) -> bool:
        return (
            side == 0.0
            and min(p[0], q[0]) <= r[0] <= max(p[0], q[0])
            and min(p[1], q[1]) <= r[1] <= max(p[1], q[1])
        )

    return on(a, b, c, d1) or on(a, b, d, d2) or on(c, d, a, d3) or on(c, d, b, d4)


def _signed_area(xy: FloatArray) -> float:
    x, y = xy[:, 0], xy[:, 1]
    return 0.5 * float((x * np.roll(y, -1) - np.roll(x, -1) * y).sum())


def _centred_box(xy: FloatArray) -> tuple[float, float] | None:
    if len(xy) != 4:
        return None
    hl, hw = float(np.abs(xy[:, 0]).max()), float(np.abs(xy[:, 1]).max())
    corners = {(hl, hw), (-hl, hw), (-hl, -hw), (hl, -hw)}
    return (hl, hw) if {(float(x), float(y)) for x, y in xy} == corners else None


def _edge_arrays(xy: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Edge i from vertex i to i + 1: starts (N, 2), vectors (N, 2), squared lengths (N,);
    read-only, shared by every call on the footprint."""
    x0, y0 = xy[:, 0], xy[:, 1]
    edge = np.column_stack((np.roll(x0, -1) - x0, np.roll(y0, -1) - y0))
    length2 = edge[:, 0] * edge[:, 0] + edge[:, 1] * edge[:, 1]
    start = xy.copy()
    for a in (start, edge, length2):
        a.setflags(write=False)
    return start, edge, length2


def _outward_normals(xy: FloatArray) -> FloatArray:
    """Unit outward normals of the edges of a counter-clockwise polygon (edge i: i -> i + 1)."""
    e = np.roll(xy, -1, axis=0) - xy
    n = np.stack([e[:, 1], -e[:, 0]], axis=1)
    out: FloatArray = n / np.hypot(n[:, 0], n[:, 1])[:, None]
    return out


def _clip_to_slab(xy: FloatArray, lo: float, hi: float) -> FloatArray:
    """The polygon's part with lo <= x <= hi (Sutherland-Hodgman against two half-planes; for a
    non-convex polygon the result may have degenerate edges, its points are still right)."""
    pts = [(float(p[0]), float(p[1])) for p in xy]
    for edge, sign in ((lo, 1.0), (hi, -1.0)):  # keep sign * (x - edge) >= 0
        out: list[tuple[float, float]] = []
        for k in range(len(pts)):
            p, q = pts[k], pts[(k + 1) % len(pts)]
            p_in, q_in = sign * (p[0] - edge) >= 0.0, sign * (q[0] - edge) >= 0.0
            if p_in:
                out.append(p)
            if p_in != q_in:
                t = (edge - p[0]) / (q[0] - p[0])
                out.append((edge, p[1] + t * (q[1] - p[1])))
        pts = out
        if not pts:
            break
    return np.array(pts, dtype=np.float64).reshape(-1, 2)
