"""The trajectory planners (registry ``PLANNERS``) and the shared configuration.

Every planner has the interface ``plan(mask, polygons, config) -> Trajectory``
and works in WFOV pixel coordinates ``(x, y) = (column, row)``.

Conventions (documented in ``docs/planning.md``):

* **Along-track** is image "up" (decreasing row): the spacecraft reaches the
  bottom of the WFOV image first. The sensor starts at the bottom centre
  ``(W/2, H-1)``.
* **step** = 1 % of the scene's x-axis (``W / 100`` px) between consecutive
  pointings along a path; **width** = 2 x step between the starting points of
  consecutive cross-transects. Both can be overridden.
* **Several polygons** are visited nearest-next from the current position
  (largest first on ties; :class:`_NearestNext`); within a polygon a path starts at its end nearest
  the current position. The hop from one polygon to the next is travel: it is
  not sampled and observes nothing (``Trajectory.part`` changes).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
import shapely
from shapely.geometry import Polygon

from dyntarget import defaults
from dyntarget.errors import InvalidParameterError
from dyntarget.masks import check_mask, mask_to_polygons
from dyntarget.plan.geometry import (
    centerline,
    chord,
    chords,
    major_axis,
    sample_polyline,
    sample_ring,
    transect_ends,
)
from dyntarget.registry import Registry
from dyntarget.trajectory import Trajectory

if TYPE_CHECKING:
    from dyntarget.schedule import Agility

PlannerFn = Callable[..., Trajectory]
"""``(mask, polygons, config)`` -> trajectory; ``(mask, polygons, config, context)`` where
the planner has ``needs_context = True``."""
"""A planner: ``(mask, polygons, config) -> Trajectory``. A planner with the attribute
``needs_context = True`` takes a fourth argument, the :class:`PlanContext`; with
``timed = True`` its trajectory is already timed under the kinematics."""

PLANNERS: Registry[PlannerFn] = Registry(
    "planner",
    order=(
        "trace-outline",
        "track-center",
        "diagonal-transect",
        "lawnmower-transect",
        "straight-nadir",
        "naive-transect",
    ),
)
KINEMATIC_PLANNERS = ("utility-max",)
"""Planners that plan under the orbit kinematics: they need a :class:`PlanContext`."""
BASELINES = ("straight-nadir", "naive-transect")
"""Planners that use no look-ahead knowledge of the plume."""
PAPER_PLANNERS = PLANNERS.order
"""The paper's four planners and two baselines: the defaults of the Table 2 evaluations.
Planners beyond the paper (``track-centerline``, ``utility-max``) are registered after them."""

STEP_FRACTION = defaults.STEP_FRACTION
WIDTH_STEPS = defaults.WIDTH_STEPS
MIN_STEP = 0.1
"""Smallest step or width accepted, in pixels (finer steps only repeat the same pixel)."""


@dataclass(frozen=True)
class PlanConfig:
    """Planner settings (all lengths in WFOV pixels).

    Parameters
    ----------
    step : float or None
        Pixels between consecutive pointings (default ``step_fraction * W``, at least 1 px).
    step_fraction : float
        Step as a fraction of the image width (paper: 1 %).
    width : float or None
        Spacing of cross-transects (default ``2 * step``).
    naive_fraction : float
        Side of the naive-transect square, as a fraction of min(H, W).
    """

    step: float | None = None
    step_fraction: float = STEP_FRACTION
    width: float | None = None
    naive_fraction: float = 0.3

    def __post_init__(self) -> None:
        for name in ("step", "width"):
            v = getattr(self, name)
            if v is not None and (not np.isfinite(v) or v < MIN_STEP):
                raise InvalidParameterError(
                    f"{name}: expected a number of pixels >= {MIN_STEP}, got {v!r}"
                )
        if not 0 < self.step_fraction <= 1:
            raise InvalidParameterError(
                f"step_fraction: expected a fraction in (0, 1], got {self.step_fraction!r}"
            )
        if not 0 < self.naive_fraction <= 1:
            raise InvalidParameterError(
                f"naive_fraction: expected a fraction in (0, 1], got {self.naive_fraction!r}"
            )

    def resolved(self, shape: tuple[int, int]) -> tuple[float, float]:
        """``(step, width)`` in pixels for an image of ``shape`` (H, W).

        Parameters
        ----------
        shape : tuple of int
            The image's ``(H, W)``.

        Returns
        -------
        step : float
            Pixels between consecutive pointings.
        width : float
            Spacing of cross-transects, pixels.
        """
        step = self.step if self.step is not None else max(self.step_fraction * shape[1], 1.0)
        width = self.width if self.width is not None else WIDTH_STEPS * step
        return float(step), float(width)

    def as_dict(self, shape: tuple[int, int]) -> dict[str, float]:
        """The settings as a plain dict, with ``step`` and ``width`` resolved for ``shape``.

        Parameters
        ----------
        shape : tuple of int
            The image's ``(H, W)``.

        Returns
        -------
        dict of str to float
            ``step``, ``step_fraction``, ``width`` and ``naive_fraction`` (as recorded in a
            trajectory's ``params``).
        """
        step, width = self.resolved(shape)
        return {**asdict(self), "step": step, "width": width}


def geometric_planners() -> list[str]:
    """The registered planners that plan on the mask alone (all but :data:`KINEMATIC_PLANNERS`).

    Returns
    -------
    list of str
        Planner names, in registration order.

    Examples
    --------
    >>> "utility-max" in geometric_planners(), "track-center" in geometric_planners()
    (False, True)
    """
    return [n for n in PLANNERS.available() if n not in KINEMATIC_PLANNERS]


@dataclass(frozen=True, eq=False)
class PlanContext:
    """What a planner beyond the mask may use (``utility-max``): the plume probability,
    the WFOV image and the kinematics it plans under.

    Parameters
    ----------
    probability : numpy.ndarray or None
        ``(H, W)`` plume probability, 0 on nodata.
    image : numpy.ndarray or None
        ``(4, H, W)`` WFOV image.
    geometry : dyntarget.schedule.OrbitGeometry or None
        Where the scene lies and when the plan starts.
    agility : dyntarget.schedule.Agility or str or None
        Agility preset name.
    objective : str
        What ``utility-max`` maximises.
    budget_s : float or None
        Time budget from the start, seconds.
    max_pointings : int or None
        Pointing budget.
    """

    probability: np.ndarray | None = None
    image: np.ndarray | None = None
    geometry: Any = None
    agility: Agility | str | None = None
    objective: str = "gradient"
    budget_s: float | None = None
    max_pointings: int | None = None


def start_point(shape: tuple[int, int]) -> np.ndarray:
    """Where the NFOV sensor starts: bottom centre (the first ground the spacecraft reaches).

    Parameters
    ----------
    shape : tuple of int
        The image's ``(H, W)``.

    Returns
    -------
    numpy.ndarray
        ``(x, y) = ((W - 1) / 2, H - 1)``, in pixels.
    """
    h, w = shape
    return np.array([(w - 1) / 2.0, h - 1.0])


def _visit(
    polygons: Sequence[Polygon],
    shape: tuple[int, int],
    path_for: Callable[[Polygon, np.ndarray], np.ndarray | list[np.ndarray]],
    name: str,
    params: dict,
) -> Trajectory:
    """Visit polygons nearest-next; ``path_for(polygon, position)`` returns its pointings.

    ``path_for`` may return one array or a list of arrays (pieces of one
    polygon's path flown with travel between them); every non-empty piece
    becomes its own ``part``.
    """
    position = start_point(shape)
    pts, sizes = [], []
    order = _NearestNext(polygons)
    while order.remaining:
        j = order.take(position)
        path = path_for(polygons[j], position)
        for piece in path if isinstance(path, list) else [path]:
            if len(piece) == 0:
                continue
            pts.append(piece)
            sizes.append(len(piece))  # one part per piece, numbered in order
            position = piece[-1]
    if not pts:
        return Trajectory.empty(name, params)
    parts = np.repeat(np.arange(len(sizes), dtype=np.int64), sizes)
    return Trajectory(_clip(np.concatenate(pts), shape), parts, name, params)


class _NearestNext:
    """Nearest-next order over polygons' exterior rings, exact, without a distance per pair.

    At each step the unvisited polygon whose exterior is nearest the current
    position is taken (the lowest index on ties: the largest, as polygons come
    largest first), the same choice as comparing every ring's distance. Each
    ring lies in the disc circumscribing its bounding box (centre ``c``, radius
    ``R``), so its distance from a point ``p`` is between ``|p - c| - R`` and
    ``|p - c| + R``. One vectorised pass over the unvisited discs keeps only the
    rings whose lower bound does not exceed the smallest upper bound; exact
    distances (shapely) are computed for those few only. Visited polygons are
    swapped out of the arrays, so each step costs a handful of numpy operations
    on the unvisited polygons: for 2000 specks at 512 px the whole order takes
    milliseconds, where one shapely distance per pair and step (the plain loop)
    took seconds. See ``benchmarks/plan_speed.py``.
    """

    def __init__(self, polygons: Sequence[Polygon]) -> None:
        self.rings = np.array([p.exterior for p in polygons], dtype=object)
        bounds = shapely.bounds(self.rings).reshape(-1, 4)
        self.cx = (bounds[:, 0] + bounds[:, 2]) / 2
        self.cy = (bounds[:, 1] + bounds[:, 3]) / 2
        self.radius = np.hypot(bounds[:, 2] - bounds[:, 0], bounds[:, 3] - bounds[:, 1]) / 2
        self.ids = np.arange(len(polygons))
        self.remaining = len(polygons)

    def take(self, position: np.ndarray) -> int:
        """The index of the unvisited polygon nearest ``position``; it is marked visited."""
        n = self.remaining
        dx, dy = self.cx[:n] - position[0], self.cy[:n] - position[1]
        dc = np.sqrt(dx * dx + dy * dy)
        near = np.flatnonzero(dc - self.radius[:n] <= (dc + self.radius[:n]).min())
        if len(near) == 1:
            k = int(near[0])
        else:
            d = shapely.distance(self.rings[self.ids[near]], shapely.Point(*position[:2]))
            k = int(near[np.lexsort((self.ids[near], d))[0]])  # nearest, then lowest index
        j = int(self.ids[k])
        n -= 1
        for a in (self.cx, self.cy, self.radius, self.ids):
            a[k] = a[n]
        self.remaining = n
        return j


def _oriented(path: np.ndarray, position: np.ndarray) -> np.ndarray:
    """Reverse ``path`` if its last point is nearer ``position`` than its first."""
    if len(path) > 1 and np.hypot(*(path[-1] - position)) < np.hypot(*(path[0] - position)):
        return path[::-1].copy()
    return path


def off_frame_pieces(points: np.ndarray, shape: tuple[int, int]) -> list[np.ndarray]:
    """Split a path where it runs on the image frame, dropping the points on the frame.

    A point is on the frame when it lies on or beyond the outermost pixel
    centres (``x <= 0``, ``x >= W - 1``, ``y <= 0`` or ``y >= H - 1``): where a
    mask touches the image edge its polygon's boundary runs along those
    pixel centres (or half a pixel beyond, for one-pixel-wide pieces).

    Parameters
    ----------
    points : (n, 2) array of ``(x, y)`` pixel coordinates, in path order.
    shape : the image's ``(H, W)``.

    Returns
    -------
    list of arrays: the runs of consecutive points off the frame, in order.

    Examples
    --------
    >>> pts = np.array([[1.0, 1], [0, 2], [0, 3], [1, 4], [2, 4], [4, 4]])
    >>> [p.tolist() for p in off_frame_pieces(pts, (5, 5))]
    [[[1.0, 1.0]]]
    """
    h, w = shape
    x, y = points[:, 0], points[:, 1]
    on = (x <= 0) | (x >= w - 1) | (y <= 0) | (y >= h - 1)
    return [points[a:b] for a, b in _runs(~on)]


def _runs(keep: np.ndarray) -> list[tuple[int, int]]:
    """``(start, stop)`` of the runs of ``True`` in a boolean vector."""
    edges = np.diff(np.concatenate([[0], keep.astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1), strict=True))


def _clip(points: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Clip to the pixel-centre grid (polygons of edge pixels reach half a pixel beyond it)."""
    h, w = shape
    return np.column_stack([np.clip(points[:, 0], 0, w - 1), np.clip(points[:, 1], 0, h - 1)])


@PLANNERS.register("trace-outline")
def trace_outline(mask: np.ndarray, polygons: Sequence[Polygon], config: PlanConfig) -> Trajectory:
    """Pointings every ``step`` along the outer boundary of each polygon (holes are not traced).

    Where a plume is cut by the image edge, its boundary runs along the image
    frame there; that stretch is the frame, not the plume's edge, so pointings
    on the frame are skipped (:func:`off_frame_pieces`): the outline is flown
    in pieces, with travel between them. A plume whose whole outline is the frame
    (it fills the image) is flown along the frame, so that it is still observed.

    Parameters
    ----------
    mask : numpy.ndarray
        ``(H, W)`` boolean plume mask (its shape sets the frame).
    polygons : sequence of shapely.Polygon
        The plume polygons, in pixel coordinates.
    config : PlanConfig
        The step.

    Returns
    -------
    dyntarget.trajectory.Trajectory
        The untimed pointings; each off-frame piece of an outline is a part of its own.

    Examples
    --------
    >>> m = np.zeros((40, 40), bool); m[0:10, 10:30] = True  # cut by the top edge: 19 px on it
    >>> t = plan("trace-outline", m, config=PlanConfig(step=1.0))
    >>> bool((t.points[:, 1] > 0).all()), len(t), int(t.part.max()) + 1
    (True, 37, 2)
    """
    step, _ = config.resolved(mask.shape)

    def path(poly: Polygon, position: np.ndarray) -> list[np.ndarray]:
        ring = sample_ring(poly, step, position)
        pieces = off_frame_pieces(ring, mask.shape)
        # A plume that fills the image has no edge of its own in view: fly the frame
        # rather than leave it unobserved.
        return pieces if any(len(p) for p in pieces) else [ring]

    return _visit(polygons, mask.shape, path, "trace-outline", config.as_dict(mask.shape))


@PLANNERS.register("track-center")
def track_center(mask: np.ndarray, polygons: Sequence[Polygon], config: PlanConfig) -> Trajectory:
    """Pointings every ``step`` along each polygon's major axis, from where it enters to where it leaves.

    Parameters
    ----------
    mask : numpy.ndarray
        ``(H, W)`` boolean plume mask (only its shape is used).
    polygons : sequence of shapely.Polygon
        The plume polygons, in pixel coordinates.
    config : PlanConfig
        The step.

    Returns
    -------
    dyntarget.trajectory.Trajectory
        The untimed pointings, one ``part`` per polygon.
    """
    step, _ = config.resolved(mask.shape)

    def path(poly: Polygon, position: np.ndarray) -> np.ndarray:
        centre, u = major_axis(poly)
        span = chord(poly, centre, u)
        if span is None:
            return np.zeros((0, 2))
        ends = np.array([centre + span[0] * u, centre + span[1] * u])
        return _oriented(sample_polyline(ends, step), position)

    return _visit(polygons, mask.shape, path, "track-center", config.as_dict(mask.shape))


@PLANNERS.register("track-centerline")
def track_centerline(
    mask: np.ndarray, polygons: Sequence[Polygon], config: PlanConfig
) -> Trajectory:
    """Pointings every ``step`` along a smoothed centreline that follows curved plumes.

    Parameters
    ----------
    mask : numpy.ndarray
        ``(H, W)`` boolean plume mask (only its shape is used).
    polygons : sequence of shapely.Polygon
        The plume polygons, in pixel coordinates.
    config : PlanConfig
        The step, and ``width``, the spacing of the centreline's stations.

    Returns
    -------
    dyntarget.trajectory.Trajectory
        The untimed pointings, one ``part`` per polygon.
    """
    step, width = config.resolved(mask.shape)

    def path(poly: Polygon, position: np.ndarray) -> np.ndarray:
        line = centerline(poly, spacing=width)
        if len(line) == 0:
            return np.zeros((0, 2))
        return _oriented(sample_polyline(line, step), position)

    return _visit(polygons, mask.shape, path, "track-centerline", config.as_dict(mask.shape))


def stations(lo: float, hi: float, width: float) -> np.ndarray:
    """Transect positions along an axis extent ``[lo, hi]``: centred, at most ``width`` apart.

    The extent is cut into ``ceil((hi - lo) / width)`` equal cells (at least
    one) and a station put at the centre of each, so the spacing is at most
    ``width`` and both ends are half a spacing from the nearest station: no
    stretch longer than half a width goes unobserved at either end.

    Parameters
    ----------
    lo, hi : the extent along the axis (``hi >= lo``).
    width : the largest spacing between stations (> 0).

    Returns
    -------
    ndarray of positions, increasing.

    Examples
    --------
    >>> stations(0.0, 10.0, 4.0).tolist()  # 3 cells of 10/3: 1/6, 1/2, 5/6 of the way
    [1.6666666666666667, 5.0, 8.333333333333334]
    >>> stations(0.0, 8.0, 4.0).tolist()
    [2.0, 6.0]
    """
    n = max(int(np.ceil((hi - lo) / width - 1e-9)), 1)
    return lo + (np.arange(n) + 0.5) * (hi - lo) / n


def _transects(
    poly: Polygon, position: np.ndarray, step: float, width: float, *, zigzag: bool
) -> np.ndarray:
    """Cross-transects along the major axis, alternating direction, sampled by ``step``.

    Starting points lie on the major axis, centred on the polygon's extent
    along it (:func:`stations`: at most ``width`` apart, half a spacing in from
    each end). Through each starting
    point the line perpendicular to the axis meets the plume boundary farthest
    out at two ends ``A_k`` and ``B_k`` (first entry and last exit, so concave
    and curved plumes are crossed whole).

    * lawnmower (boustrophedon): ``A_0 -> B_0 -> B_1 -> A_1 -> A_2 -> B_2 ...``:
      perpendicular transects joined by straight chords between consecutive
      transects' ends (not legs along the boundary: where the side is concave
      between two transects, a join crosses background);
    * diagonal (zig-zag): ``A_0 -> B_1 -> A_2 -> B_3 ...``: each transect runs
      at an angle from one side at starting point ``k`` to the other side at
      ``k + 1``, opposite to the previous one.

    The walk starts at the axis end and the side nearer ``position``.
    """
    centre, u = major_axis(poly)
    v = np.array([-u[1], u[0]])
    proj = (np.asarray(poly.exterior.coords) - centre) @ u
    a_min, a_max = float(proj.min()), float(proj.max())
    offsets = stations(a_min, a_max, width)
    origins = centre + offsets[:, None] * u
    spans = chords(poly, origins, v)
    ends = [
        (o + t0 * v, o + t1 * v)
        for o, (t0, t1) in zip(origins, spans, strict=True)
        if not np.isnan(t0)
    ]
    if not ends:
        return np.zeros((0, 2))
    candidates = {  # (reverse the axis walk?, start on side B?)
        (rev, side): (ends[::-1] if rev else ends)[0][1 if side else 0]
        for rev in (False, True)
        for side in (False, True)
    }
    rev, side = min(candidates, key=lambda key: (np.hypot(*(candidates[key] - position)), key))
    ends = ends[::-1] if rev else ends
    if side:
        ends = [(b, a) for a, b in ends]
    vertices = []
    for k, (a, b) in enumerate(ends):
        if zigzag:
            vertices.append(a if k % 2 == 0 else b)
        else:
            vertices += [a, b] if k % 2 == 0 else [b, a]
    return sample_polyline(np.array(vertices), step)


class _Transects:
    """The transect planners' paths over many polygons: geometry for all at once.

    :func:`~dyntarget.plan.geometry.transect_ends` computes every polygon's
    transect ends in a few vectorised passes before the visit; only the choice of
    the starting end (nearest the sensor's position when the polygon's turn comes)
    and the sampling are left per polygon, as :func:`_transects` does them. A mask
    of 2000 specks is planned in tens of milliseconds instead of hundreds
    (``benchmarks/specks_process.py``).
    """

    def __init__(self, polygons: Sequence[Polygon], step: float, width: float, zigzag: bool):
        self.a, self.b, self.first = transect_ends(list(polygons), width)
        self.index = {id(p): i for i, p in enumerate(polygons)}
        self.bounds = self.first.tolist()
        self.al, self.bl = self.a.tolist(), self.b.tolist()  # floats for the one-transect case
        self.step, self.zigzag = step, zigzag

    def __call__(self, poly: Polygon, position: np.ndarray) -> np.ndarray:
        i = self.index[id(poly)]
        lo, hi = self.bounds[i], self.bounds[i + 1]
        if hi == lo:
            return np.zeros((0, 2))
        px, py = float(position[0]), float(position[1])
        if hi - lo == 1:  # one transect (a small polygon): start at its nearer end, A on ties
            (ax, ay), (bx, by) = self.al[lo], self.bl[lo]
            if math.hypot(bx - px, by - py) < math.hypot(ax - px, ay - py):
                ax, ay, bx, by = bx, by, ax, ay
            if self.zigzag or math.hypot(bx - ax, by - ay) <= self.step / 2:
                return np.array([[ax, ay]])  # a zig-zag's first end; a short transect
            return sample_polyline(np.array([[ax, ay], [bx, by]]), self.step)
        a, b = self.a[lo:hi], self.b[lo:hi]
        candidates = (  # (reverse the axis walk?, start on side B?) -> the start point
            ((False, False), a[0]),
            ((False, True), b[0]),
            ((True, False), a[-1]),
            ((True, True), b[-1]),
        )
        _, (rev, side) = min(
            (math.hypot(float(c[0]) - px, float(c[1]) - py), key) for key, c in candidates
        )
        if rev:
            a, b = a[::-1], b[::-1]
        if side:
            a, b = b, a
        even = (np.arange(len(a)) % 2 == 0)[:, None]
        if self.zigzag:
            vertices = np.where(even, a, b)
        else:
            vertices = np.empty((2 * len(a), 2))
            vertices[0::2] = np.where(even, a, b)
            vertices[1::2] = np.where(even, b, a)
        if len(vertices) == 2:  # one transect: short ones are a single pointing
            length = math.hypot(*(vertices[1] - vertices[0]))
            if length <= self.step / 2:
                return vertices[:1].copy()
        return sample_polyline(vertices, self.step)


@PLANNERS.register("diagonal-transect")
def diagonal_transect(
    mask: np.ndarray, polygons: Sequence[Polygon], config: PlanConfig
) -> Trajectory:
    """Zig-zag transects at an angle across each polygon's major axis (see :func:`_transects`).

    Parameters
    ----------
    mask : numpy.ndarray
        ``(H, W)`` boolean plume mask (only its shape is used).
    polygons : sequence of shapely.Polygon
        The plume polygons, in pixel coordinates.
    config : PlanConfig
        Step and transect spacing.

    Returns
    -------
    dyntarget.trajectory.Trajectory
        The untimed pointings, one ``part`` per polygon.
    """
    step, width = config.resolved(mask.shape)
    path = _Transects(polygons, step, width, zigzag=True)
    return _visit(polygons, mask.shape, path, "diagonal-transect", config.as_dict(mask.shape))


@PLANNERS.register("lawnmower-transect")
def lawnmower_transect(
    mask: np.ndarray, polygons: Sequence[Polygon], config: PlanConfig
) -> Trajectory:
    """Boustrophedon transects perpendicular to each polygon's major axis.

    Parameters
    ----------
    mask : numpy.ndarray
        ``(H, W)`` boolean plume mask (only its shape is used).
    polygons : sequence of shapely.Polygon
        The plume polygons, in pixel coordinates.
    config : PlanConfig
        Step and transect spacing.

    Returns
    -------
    dyntarget.trajectory.Trajectory
        The untimed pointings, one ``part`` per polygon.
    """
    step, width = config.resolved(mask.shape)
    path = _Transects(polygons, step, width, zigzag=False)
    return _visit(polygons, mask.shape, path, "lawnmower-transect", config.as_dict(mask.shape))


@PLANNERS.register("straight-nadir")
def straight_nadir(mask: np.ndarray, polygons: Sequence[Polygon], config: PlanConfig) -> Trajectory:
    """Baseline: a line along-track through the scene centre, bottom to top, every ``step``.

    Parameters
    ----------
    mask : numpy.ndarray
        ``(H, W)`` boolean plume mask (only its shape is used).
    polygons : sequence of shapely.Polygon
        Ignored (the baseline does not look at the plume).
    config : PlanConfig
        The step.

    Returns
    -------
    dyntarget.trajectory.Trajectory
        The untimed pointings, all in part 0.
    """
    step, _ = config.resolved(mask.shape)
    h, w = mask.shape
    x = (w - 1) / 2.0
    pts = sample_polyline(np.array([[x, h - 1.0], [x, 0.0]]), step)
    return Trajectory(
        pts, np.zeros(len(pts), np.int64), "straight-nadir", config.as_dict(mask.shape)
    )


@PLANNERS.register("naive-transect")
def naive_transect(mask: np.ndarray, polygons: Sequence[Polygon], config: PlanConfig) -> Trajectory:
    """Baseline: a lawnmower over a fixed central square, ignoring the plume.

    The square is centred on the scene, of side ``naive_fraction * min(H, W)``
    (default 30 %); transects run across-track (along x), spaced by ``width``,
    alternating direction, from the bottom of the square to its top.

    Parameters
    ----------
    mask : numpy.ndarray
        ``(H, W)`` boolean plume mask (only its shape is used).
    polygons : sequence of shapely.Polygon
        Ignored (the baseline does not look at the plume).
    config : PlanConfig
        Step, transect spacing and ``naive_fraction``.

    Returns
    -------
    dyntarget.trajectory.Trajectory
        The untimed pointings, all in part 0.
    """
    step, width = config.resolved(mask.shape)
    h, w = mask.shape
    side = config.naive_fraction * min(h, w)
    cx, cy = (w - 1) / 2.0, (h - 1) / 2.0
    x0, x1 = cx - side / 2, cx + side / 2
    rows = np.arange(cy + side / 2, cy - side / 2 - 1e-9, -width)
    vertices = []
    for k, y in enumerate(rows):
        a, b = (x0, x1) if k % 2 == 0 else (x1, x0)
        vertices += [[a, y], [b, y]]
    pts = _clip(sample_polyline(np.array(vertices), step), mask.shape)
    return Trajectory(
        pts, np.zeros(len(pts), np.int64), "naive-transect", config.as_dict(mask.shape)
    )


def plan(
    name: str,
    mask: np.ndarray,
    polygons: Sequence[Polygon] | None = None,
    config: PlanConfig | None = None,
    context: PlanContext | None = None,
) -> Trajectory:
    """Plan with the registered planner ``name``.

    ``polygons`` default to the mask's polygons (:func:`mask_to_polygons`);
    pass the denoised polygons from :func:`dyntarget.denoise.denoise`
    to plan as the paper does.

    Parameters
    ----------
    name : str
        A registered planner (``dyntarget planners`` lists them).
    mask : numpy.ndarray
        ``(H, W)`` boolean plume mask in WFOV pixels.
    polygons : sequence of shapely.Polygon or None
        The plume polygons to plan over (default: the mask's).
    config : PlanConfig or None
        Planner settings (default ``PlanConfig()``).
    context : PlanContext or None
        What planners beyond the mask use (``utility-max``); ignored by the others.

    Returns
    -------
    dyntarget.trajectory.Trajectory
        The planned pointings, untimed.

    Examples
    --------
    >>> m = np.zeros((100, 100), bool); m[40:60, 10:90] = True
    >>> t = plan("track-center", m)
    >>> len(t), t.points[0].tolist()
    (80, [10.0, 49.5])
    """
    mask = check_mask(mask)
    fn = PLANNERS.get(name)
    if polygons is None:
        polygons = mask_to_polygons(mask)
    if getattr(fn, "needs_context", False):
        return fn(mask, list(polygons), config or PlanConfig(), context)
    return fn(mask, list(polygons), config or PlanConfig())


# beyond the paper, planning under the kinematics (imports dyntarget.schedule when first used)
PLANNERS.register_lazy("utility-max", "dyntarget.plan.utility:utility_max_planner")
