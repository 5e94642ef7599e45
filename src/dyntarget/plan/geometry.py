"""Plane geometry for the planners (shapely + numpy), in pixel coordinates."""

from __future__ import annotations

import numpy as np
import shapely
from shapely.geometry import Polygon


def resample_ring(polygon: Polygon, spacing: float = 1.0) -> np.ndarray:
    """Points evenly spaced (about ``spacing`` px) along the exterior ring.

    Parameters
    ----------
    polygon : shapely.Polygon
        The polygon whose exterior ring is sampled.
    spacing : float
        Wanted distance between points, pixels (at least 4 points are returned).

    Returns
    -------
    numpy.ndarray
        ``(n, 2)`` points ``(x, y)`` along the ring from its first vertex, the last
        one short of closing the ring.
    """
    ring = polygon.exterior
    n = max(int(np.ceil(ring.length / spacing)), 4)
    return interpolate_ring(np.asarray(ring.coords), np.linspace(0, ring.length, n, endpoint=False))


def interpolate_ring(coords: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Points at arc lengths ``s`` (0 <= s < length) along a closed ring given by its coordinates.

    The same linear interpolation as shapely's ``line_interpolate_point``, done
    for all points at once with ``np.interp`` (shapely walks the ring once per
    point, which is slow for long rings).

    Parameters
    ----------
    coords : numpy.ndarray
        ``(n, 2)`` coordinates of the closed ring (first point repeated at the end).
    s : numpy.ndarray
        Arc lengths along the ring from its first point, same units as ``coords``.

    Returns
    -------
    numpy.ndarray
        ``(len(s), 2)`` points ``(x, y)``.
    """
    cum = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(coords, axis=0).T))])
    return np.column_stack([np.interp(s, cum, coords[:, 0]), np.interp(s, cum, coords[:, 1])])


def major_axis(polygon: Polygon) -> tuple[np.ndarray, np.ndarray]:
    """The polygon's major axis: a total-least-squares line through its contour.

    Returns ``(centre, direction)``: the mean of the contour points (resampled
    evenly so vertex density does not bias the fit) and the unit principal
    direction, oriented so its larger component is positive (deterministic).

    Parameters
    ----------
    polygon : shapely.Polygon
        The polygon, in pixel coordinates.

    Returns
    -------
    centre : numpy.ndarray
        ``(x, y)`` mean of the resampled contour points.
    direction : numpy.ndarray
        Unit ``(dx, dy)`` principal direction (``(1, 0)`` when no axis is preferred).
    """
    pts = resample_ring(polygon, spacing=max(polygon.exterior.length / 400.0, 0.5))
    centre = pts.mean(axis=0)
    cov = np.cov((pts - centre).T)
    eigval, eigvec = np.linalg.eigh(cov)
    u = eigvec[:, int(np.argmax(eigval))]
    if np.isclose(eigval[0], eigval[1]):  # a circle or a square: no preferred axis, take x
        u = np.array([1.0, 0.0])
    i = int(np.argmax(np.abs(u)))
    if u[i] < 0:
        u = -u
    return centre, u / np.linalg.norm(u)


def chords(polygon: Polygon, origins: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """Farthest boundary points of ``polygon`` on the lines ``origins[k] + t * direction``.

    Returns ``(k, 2)`` arrays of ``(t_min, t_max)``: the first entry into and
    the last exit from the polygon along each line (so a concave plume is
    crossed whole), NaN where a line misses it. Both extremes lie on the
    exterior ring, so only its segments are intersected, all lines at once
    (vectorised: one matrix of line x segment crossings).

    Parameters
    ----------
    polygon : shapely.Polygon
        The polygon to cross (only its exterior ring is used).
    origins : numpy.ndarray
        ``(k, 2)`` points ``(x, y)``, one per line (a single ``(2,)`` point is one line).
    direction : numpy.ndarray
        ``(dx, dy)`` direction shared by all lines.

    Returns
    -------
    numpy.ndarray
        ``(k, 2)`` float array of ``(t_min, t_max)`` in units of ``direction``; both NaN
        for a line that misses the polygon.
    """
    ring = np.asarray(polygon.exterior.coords, dtype=np.float64)
    a, e = ring[:-1], np.diff(ring, axis=0)  # segments a + u e, u in [0, 1]
    d = np.asarray(direction, dtype=np.float64)
    o = np.asarray(origins, dtype=np.float64).reshape(-1, 2)
    denom = d[0] * e[:, 1] - d[1] * e[:, 0]  # cross(d, e), per segment
    ok = np.abs(denom) > 1e-12  # segments parallel to the lines never decide an extreme alone
    ao = a[None, :, :] - o[:, None, :]  # (k, n, 2)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (ao[..., 0] * e[:, 1] - ao[..., 1] * e[:, 0]) / denom
        u = (ao[..., 0] * d[1] - ao[..., 1] * d[0]) / denom
    hit = ok & (u >= -1e-9) & (u <= 1 + 1e-9)
    t_min = np.where(hit, t, np.inf).min(axis=1)
    t_max = np.where(hit, t, -np.inf).max(axis=1)
    out = np.column_stack([t_min, t_max])
    out[~hit.any(axis=1)] = np.nan
    return out


def chord(
    polygon: Polygon, origin: np.ndarray, direction: np.ndarray
) -> tuple[float, float] | None:
    """:func:`chords` for one line: ``(t_min, t_max)``, or ``None`` when the line misses the polygon.

    Parameters
    ----------
    polygon : shapely.Polygon
        The polygon to cross.
    origin : numpy.ndarray
        ``(x, y)`` point of the line.
    direction : numpy.ndarray
        ``(dx, dy)`` direction of the line.

    Returns
    -------
    tuple of float or None
        ``(t_min, t_max)``, the line parameters of the first entry and last exit, in
        units of ``direction``; ``None`` when the line misses the polygon.
    """
    t0, t1 = chords(polygon, np.asarray(origin)[None], direction)[0]
    return None if np.isnan(t0) else (float(t0), float(t1))


SMOOTH_STATIONS = 7
"""Stations in each local fit of the centreline smoother (odd)."""


def centerline(polygon: Polygon, spacing: float) -> np.ndarray:
    """A smooth piecewise-linear line through the middle of a (possibly curved) polygon.

    Stations every ``spacing`` px along the major axis; at each, the chord
    across the polygon perpendicular to the axis and its midpoint (the first
    entry and last exit, as for the transects). The midpoints' offsets from the
    axis, as a function of the position along it, are smoothed with a
    Savitzky-Golay filter (local quadratic fits over :data:`SMOOTH_STATIONS`
    stations, ``scipy.signal.savgol_filter``: it keeps a steady bend and removes
    the jitter of a ragged mask edge) and the ends are extended along their
    direction to the boundary. A straight plume gives its major axis. Plumes
    that bend by more than 90 degrees from their axis are followed only as far
    as the perpendicular chords can see. Returns ``(n, 2)`` vertices (empty if
    the polygon is degenerate).

    Parameters
    ----------
    polygon : shapely.Polygon
        The plume polygon, in WFOV pixel coordinates.
    spacing : float
        Distance between stations along the major axis, pixels.

    Returns
    -------
    numpy.ndarray
        ``(n, 2)`` float vertices ``(x, y)`` of the centreline, from one tip to the
        other; ``(0, 2)`` when no chord meets the polygon.
    """
    centre, u = major_axis(polygon)
    n = np.array([-u[1], u[0]])
    ring = np.asarray(polygon.exterior.coords, dtype=np.float64)
    proj = (ring - centre) @ u
    lo, hi = float(proj.min()), float(proj.max())
    count = max(int(np.floor((hi - lo) / spacing)), 1)
    s = lo + (np.arange(count) + 0.5) * (hi - lo) / count  # stations, inset from the tips
    spans = chords(polygon, centre + s[:, None] * u, n)
    ok = ~np.isnan(spans[:, 0])
    if not ok.any():
        return np.zeros((0, 2))
    s, mid = s[ok], spans[ok].mean(axis=1)
    if len(s) >= 5:  # too few stations to smooth: the midpoints as they are
        from scipy.signal import savgol_filter

        window = min(SMOOTH_STATIONS, len(s) - (1 - len(s) % 2))  # odd, at most len(s)
        mid = savgol_filter(mid, window, polyorder=2, mode="interp")
    line = centre + s[:, None] * u + mid[:, None] * n
    # extend both ends along their direction to the boundary (the plume's tips)
    if len(line) >= 2:
        first, last = line[0] - line[1], line[-1] - line[-2]
    else:
        first, last = -u, u
    return np.vstack(
        [_to_boundary(polygon, line[0], first), line, _to_boundary(polygon, line[-1], last)]
    )


def _to_boundary(polygon: Polygon, point: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """Where the ray from ``point`` along ``direction`` last leaves the polygon (or ``point``)."""
    d = direction / np.hypot(*direction)
    span = chords(polygon, point[None, :], d)[0]
    t = span[1] if np.isfinite(span[1]) and span[1] > 0 else 0.0
    return point + t * d


def sample_polyline(vertices: np.ndarray, step: float) -> np.ndarray:
    """Points every ``step`` px of arc length along a polyline, starting at its first vertex.

    The last vertex is added when the remaining stretch is longer than half a
    step, so paths end near their end point. A single vertex gives itself.

    Parameters
    ----------
    vertices : numpy.ndarray
        ``(n, 2)`` vertices ``(x, y)`` of the polyline, in pixels.
    step : float
        Arc length between samples, pixels.

    Returns
    -------
    numpy.ndarray
        ``(m, 2)`` float points ``(x, y)``; empty for no vertices.
    """
    vertices = np.asarray(vertices, dtype=np.float64).reshape(-1, 2)
    if len(vertices) == 0:
        return vertices
    seg = np.hypot(*np.diff(vertices, axis=0).T)
    total = float(seg.sum())
    if total == 0.0:
        return vertices[:1].copy()
    s = np.arange(0.0, total + 1e-9, step)
    if total - s[-1] > step / 2:
        s = np.append(s, total)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    x = np.interp(s, cum, vertices[:, 0])
    y = np.interp(s, cum, vertices[:, 1])
    return np.column_stack([x, y])


def sample_ring(polygon: Polygon, step: float, start: np.ndarray) -> np.ndarray:
    """Points every ``step`` px along the exterior ring, starting at the ring point nearest ``start``.

    Parameters
    ----------
    polygon : shapely.Polygon
        The polygon whose exterior ring is sampled.
    step : float
        Arc length between samples, pixels.
    start : numpy.ndarray
        ``(x, y)`` point; sampling starts at the ring point nearest it.

    Returns
    -------
    numpy.ndarray
        ``(n, 2)`` points ``(x, y)`` going once round the ring (at least one point).
    """
    ring = polygon.exterior
    length = ring.length
    s0 = ring.project(shapely.Point(start))
    n = max(int(np.floor(length / step + 1e-9)), 1)
    s = (s0 + step * np.arange(n)) % length
    return interpolate_ring(np.asarray(ring.coords), s)


def transect_ends(
    polygons: list[Polygon], width: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The cross-transects of many polygons at once: each one's ends ``A_k``, ``B_k``.

    The same geometry as the transect planners draw one polygon at a time (major
    axis by a total-least-squares fit to the evenly resampled exterior, stations
    along it at most ``width`` apart, the farthest boundary points on each
    perpendicular line), computed for all polygons in a few vectorised passes: a
    mask of thousands of specks costs milliseconds, not one Python round per
    speck. Equal to the one-polygon computation up to floating-point rounding.

    Parameters
    ----------
    polygons : list of shapely.Polygon
        The polygons, pixel coordinates.
    width : float
        Largest spacing between transects, pixels (> 0).

    Returns
    -------
    a, b : numpy.ndarray
        ``(m, 2)`` ends of every transect, in axis order within each polygon (lines
        that miss their polygon are left out).
    first : numpy.ndarray
        ``(len(polygons) + 1,)``: polygon ``i``'s transects are rows ``first[i]:first[i + 1]``.

    Examples
    --------
    >>> from shapely.geometry import box
    >>> a, b, first = transect_ends([box(0, 0, 10, 2), box(20, 0, 21, 1)], width=4.0)
    >>> first.tolist(), a[first[1]].tolist(), b[first[1]].tolist()
    ([0, 3, 4], [20.5, 0.0], [20.5, 1.0])
    """
    n = len(polygons)
    if n == 0:
        return np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(1, np.int64)
    rings = shapely.get_exterior_ring(np.asarray(polygons, dtype=object))
    coords, idx = shapely.get_coordinates(rings, return_index=True)
    counts = np.bincount(idx, minlength=n)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    lengths = shapely.length(rings)
    # segments coords[j] -> coords[j + 1] inside a ring (a ring's last coordinate closes it)
    is_seg = np.ones(len(coords), bool)
    is_seg[starts + counts - 1] = False
    seg_ids = np.flatnonzero(is_seg[:-1])
    seg_a, seg_e = coords[seg_ids], coords[seg_ids + 1] - coords[seg_ids]
    seg_ring = idx[seg_ids]
    seg_len = np.hypot(seg_e[:, 0], seg_e[:, 1])
    nseg = np.bincount(seg_ring, minlength=n)
    seg_first = np.concatenate([[0], np.cumsum(nseg)[:-1]])
    # 1. the ring resampled evenly (as resample_ring with spacing max(length / 400, 0.5))
    spacing = np.maximum(lengths / 400.0, 0.5)
    ns = np.maximum(np.ceil(lengths / spacing).astype(np.int64), 4)
    s_ring = np.repeat(np.arange(n), ns)
    s_first = np.concatenate([[0], np.cumsum(ns)[:-1]])
    s = (np.arange(len(s_ring)) - s_first[s_ring]) * (lengths / ns)[s_ring]
    cum = np.concatenate([[0.0], np.cumsum(seg_len)])
    offset = cum[seg_first]  # each ring's arc length starts here on the global scale
    j = np.searchsorted(cum, offset[s_ring] + s, side="right") - 1
    j = np.clip(j, seg_first[s_ring], seg_first[s_ring] + nseg[s_ring] - 1)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(seg_len[j] > 0, (s - (cum[j] - offset[s_ring])) / seg_len[j], 0.0)
    pts = seg_a[j] + np.clip(t, 0.0, 1.0)[:, None] * seg_e[j]
    # 2. the major axis: principal direction of the resampled points
    centre = np.add.reduceat(pts, s_first, axis=0) / ns[:, None]
    d = pts - centre[s_ring]
    sxx = np.add.reduceat(d[:, 0] * d[:, 0], s_first)
    sxy = np.add.reduceat(d[:, 0] * d[:, 1], s_first)
    syy = np.add.reduceat(d[:, 1] * d[:, 1], s_first)
    cov = (
        np.stack([np.stack([sxx, sxy], -1), np.stack([sxy, syy], -1)], -2) / (ns - 1)[:, None, None]
    )
    w, vec = np.linalg.eigh(cov)
    u = vec[np.arange(n), :, np.argmax(w, axis=1)]
    round_ = np.abs(w[:, 0] - w[:, 1]) <= 1e-8 + 1e-5 * np.abs(w[:, 1])  # np.isclose
    u[round_] = (1.0, 0.0)
    big = np.argmax(np.abs(u), axis=1)
    u[u[np.arange(n), big] < 0] *= -1.0
    u /= np.hypot(u[:, 0], u[:, 1])[:, None]
    v = np.column_stack([-u[:, 1], u[:, 0]])
    # 3. stations along the axis over the ring's extent
    proj = np.einsum("ij,ij->i", coords - centre[idx], u[idx])
    lo, hi = np.minimum.reduceat(proj, starts), np.maximum.reduceat(proj, starts)
    nst = np.maximum(np.ceil((hi - lo) / width - 1e-9).astype(np.int64), 1)
    st_ring = np.repeat(np.arange(n), nst)
    st_first = np.concatenate([[0], np.cumsum(nst)[:-1]])
    k = np.arange(len(st_ring)) - st_first[st_ring]
    off = lo[st_ring] + (k + 0.5) * ((hi - lo) / nst)[st_ring]
    origins = centre[st_ring] + off[:, None] * u[st_ring]
    # 4. each line against its own ring's segments (as chords): first entry, last exit
    per = nseg[st_ring]
    pair_st = np.repeat(np.arange(len(st_ring)), per)
    pair_first = np.concatenate([[0], np.cumsum(per)[:-1]])
    pair_seg = seg_first[st_ring][pair_st] + (np.arange(len(pair_st)) - pair_first[pair_st])
    dv = v[st_ring][pair_st]
    e = seg_e[pair_seg]
    ao = seg_a[pair_seg] - origins[pair_st]
    denom = dv[:, 0] * e[:, 1] - dv[:, 1] * e[:, 0]
    ok = np.abs(denom) > 1e-12
    with np.errstate(divide="ignore", invalid="ignore"):
        tt = (ao[:, 0] * e[:, 1] - ao[:, 1] * e[:, 0]) / denom
        uu = (ao[:, 0] * dv[:, 1] - ao[:, 1] * dv[:, 0]) / denom
    hit = ok & (uu >= -1e-9) & (uu <= 1 + 1e-9)
    t_min = np.minimum.reduceat(np.where(hit, tt, np.inf), pair_first)
    t_max = np.maximum.reduceat(np.where(hit, tt, -np.inf), pair_first)
    keep = np.isfinite(t_min)
    a = origins + t_min[:, None] * v[st_ring]
    b = origins + t_max[:, None] * v[st_ring]
    first = np.concatenate([[0], np.cumsum(np.bincount(st_ring[keep], minlength=n))])
    return a[keep], b[keep], first
