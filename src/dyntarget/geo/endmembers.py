"""End-members estimated from the GEO images themselves (N-FINDR), not the simulator's spectra.

:func:`estimate_members` finds the meteorological-cloud, ash and steam spectra that
:func:`dyntarget.geo.unmix` needs in the GEO images of the pass, so that the unmixing
does not borrow the simulator's own end-members (``GeoImager.members``):

1. **Candidates.** The cells (of every image given) brighter than the clear-sky
   background by more than ``min_anomaly`` (band mean): cloud and plume cells.
2. **Background vertex.** The per-band median of the clear-sky background (a robust
   statistic of the clear cells), fixed as one vertex of the simplex.
3. **Vertices.** N-FINDR (Winter 1999): the three candidate spectra that, with the
   background vertex, span the simplex of largest volume (``sqrt(det(E^T E))``, ``E`` the
   edges from the background vertex), started by successive orthogonal projections
   (each next vertex the candidate farthest from the span of the ones chosen) and
   improved by swapping one vertex at a time while the volume grows.
4. **Classes, by spectral shape (not by the simulator's values).** Cloud: bright and
   flat (large droplets); steam: as bright in the visible, the NIR a quarter lower (small
   droplets and sulfate scatter less in the NIR); ash: dark, slightly brown. Written as
   round-number reference spectra (:data:`SHAPES`), whose edges from the background are
   matched one to one to the vertices' edges (:func:`classify`). They only *name* the
   vertices: the end-members returned are the vertices, the spectra found in the images.

Assumption (that of N-FINDR): the images hold nearly pure cells of each material; where
they do not (a plume narrower than a cell), the vertices are the purest mixtures found,
darker than the true spectra, and the fractions come out larger than the true cover
(the plume field is more sensitive; see ``docs/results.md``). When fewer than three
candidates exist, :func:`estimate_members` returns the vertices it has (possibly none).
"""

from __future__ import annotations

import numpy as np

from dyntarget.errors import InvalidParameterError

MIN_ANOMALY = 0.03
"""Band-mean brightness above the background of a candidate cell, reflectance."""
MAX_CANDIDATES = 4000
"""Most candidate cells kept (the brightest), to bound the N-FINDR sweeps."""
SWEEPS = 4
"""Most N-FINDR swap sweeps over the vertices."""
CLASSES = ("cloud", "ash", "steam")
"""Order of the end-members returned (that of :func:`dyntarget.geo.unmix`'s callers)."""


def _volume(edges: np.ndarray) -> np.ndarray:
    """``sqrt(det(E^T E))`` of ``(..., B, K)`` edge stacks (the simplex volume times K!)."""
    gram = np.einsum("...bi,...bj->...ij", edges, edges)
    out: np.ndarray = np.sqrt(np.clip(np.linalg.det(gram), 0.0, None))
    return out


def _unit(e: np.ndarray) -> np.ndarray:
    """Rows of ``e`` scaled to unit length."""
    out: np.ndarray = e / np.maximum(np.linalg.norm(e, axis=-1, keepdims=True), 1e-12)
    return out


def nfindr(spectra: np.ndarray, origin: np.ndarray, k: int = 3) -> np.ndarray:
    """Indices of the ``k`` spectra spanning with ``origin`` the simplex of largest volume.

    Parameters
    ----------
    spectra : numpy.ndarray
        ``(N, B)`` candidate spectra, ``N >= k``, ``k < B + 1``.
    origin : numpy.ndarray
        ``(B,)`` the fixed vertex (the background).
    k : int
        Vertices to choose.

    Returns
    -------
    numpy.ndarray
        ``(k,)`` indices into ``spectra`` (in the order they were first chosen).

    Examples
    --------
    >>> bg = np.zeros(3)
    >>> pts = np.array([[1, 0, 0], [0.5, 0.5, 0], [0, 1, 0], [0.2, 0.2, 0], [0, 0, 1]], float)
    >>> sorted(nfindr(pts, bg, 3).tolist())
    [0, 2, 4]
    """
    x = np.asarray(spectra, np.float64) - np.asarray(origin, np.float64)[None]
    n, b = x.shape
    if not 1 <= k <= min(n, b):
        raise InvalidParameterError(f"nfindr: cannot choose {k} of {n} spectra in {b} bands")
    chosen: list[int] = []
    for _ in range(k):  # successive orthogonal projections (the start)
        if chosen:
            q, _ = np.linalg.qr(x[chosen].T)
            resid = x - (x @ q) @ q.T
        else:
            resid = x
        norms = np.einsum("ij,ij->i", resid, resid)
        norms[chosen] = -1.0
        chosen.append(int(np.argmax(norms)))
    best = float(_volume(x[chosen].T))
    for _ in range(SWEEPS):  # N-FINDR swaps
        improved = False
        for j in range(k):
            edges = np.repeat(x[chosen].T[None], n, axis=0)  # (n, B, k)
            edges[:, :, j] = x
            vol = _volume(edges)
            i = int(np.argmax(vol))
            if vol[i] > best * (1.0 + 1e-9) and i not in chosen:
                chosen[j], best, improved = i, float(vol[i]), True
        if not improved:
            break
    return np.asarray(chosen, np.int64)


SHAPES = {
    "cloud": (0.8, 0.8, 0.8, 0.8),
    "ash": (0.27, 0.25, 0.23, 0.25),
    "steam": (0.75, 0.75, 0.75, 0.56),
}
"""The shape rule as round-number reference spectra (blue, green, red, NIR): cloud bright
and flat (large droplets); steam as bright in the visible with the NIR a quarter lower
(small droplets, sulfate); ash dark and slightly brown (falling from blue to red, the NIR
as green). Used only to *name* the vertices found, never as end-members."""


def classify(vertices: np.ndarray, origin: np.ndarray) -> dict[str, int]:
    """Which vertex is cloud, ash and steam: the edges from the background matched to :data:`SHAPES`.

    Each vertex ``v`` found by N-FINDR is, at best, a pure material, else a mixture
    ``(1 - F) origin + F m`` of it with the ground; either way its edge ``v - origin`` points
    along ``m - origin``. The edges are matched one to one to the edges of the shape rule's
    reference spectra (:data:`SHAPES`) from the same background by the largest total cosine
    similarity (:func:`scipy.optimize.linear_sum_assignment`).

    Parameters
    ----------
    vertices : numpy.ndarray
        ``(K, 4)`` spectra, ``K <= 3`` (bands blue, green, red, NIR).
    origin : numpy.ndarray
        ``(4,)`` the background vertex.

    Returns
    -------
    dict
        Class name -> row of ``vertices`` (classes left without a vertex left out).

    Examples
    --------
    >>> v = np.array([[0.8, 0.8, 0.8, 0.8], [0.3, 0.26, 0.22, 0.27], [0.7, 0.75, 0.8, 0.55]])
    >>> classify(v, np.full(4, 0.1))
    {'cloud': 0, 'ash': 1, 'steam': 2}
    """
    from scipy.optimize import linear_sum_assignment

    v = np.asarray(vertices, np.float64)
    o = np.asarray(origin, np.float64)
    if v.ndim != 2 or v.shape[1] != 4 or v.shape[0] > 3 or o.shape != (4,):
        raise InvalidParameterError(f"classify: expected (K <= 3, 4) spectra, got {v.shape}")
    if len(v) == 0:
        return {}
    edges = _unit(v - o[None])
    refs = _unit(np.array([SHAPES[c] for c in CLASSES]) - o[None])
    rows, cols = linear_sum_assignment(-(edges @ refs.T))
    return {CLASSES[c]: int(r) for r, c in sorted(zip(rows, cols, strict=True), key=lambda p: p[1])}


def estimate_members(
    images: list[np.ndarray],
    background: np.ndarray,
    *,
    min_anomaly: float = MIN_ANOMALY,
) -> tuple[np.ndarray, list[str], dict[str, object]]:
    """Cloud, ash and steam end-members found in GEO images (see the module docstring).

    Parameters
    ----------
    images : list of numpy.ndarray
        ``(4, H, W)`` GEO reflectance images (the ones the blueprint uses).
    background : numpy.ndarray
        ``(4, H, W)`` clear-sky reflectance of the same cells.
    min_anomaly : float
        Band-mean brightness above the background of a candidate cell.

    Returns
    -------
    members : numpy.ndarray
        ``(K, 4)`` spectra, ``K <= 3``, in :data:`CLASSES` order, classes not found left out.
    names : list of str
        The class of each row of ``members``.
    info : dict
        ``candidates`` (cells used) and ``members`` (class -> spectrum, rounded), for the
        pass's ``summary.json``.

    Examples
    --------
    >>> bg = np.full((4, 4, 4), 0.1)
    >>> truth = {"cloud": [0.8, 0.81, 0.83, 0.79], "ash": [0.3, 0.26, 0.22, 0.27],
    ...          "steam": [0.74, 0.76, 0.8, 0.58]}
    >>> img = bg.copy()
    >>> img[:, 0, 0], img[:, 1, 1], img[:, 2, 2] = truth["cloud"], truth["ash"], truth["steam"]
    >>> m, names, _ = estimate_members([img], bg)
    >>> names, bool(np.allclose(m, [truth[n] for n in names]))
    (['cloud', 'ash', 'steam'], True)
    """
    bg = np.asarray(background, np.float64)
    if bg.ndim != 3 or bg.shape[0] != 4:
        raise InvalidParameterError(f"background: expected (4, H, W), got {bg.shape}")
    if not images:
        raise InvalidParameterError("estimate_members: no GEO image")
    cells = []
    for im in images:
        im = np.asarray(im, np.float64)
        if im.shape != bg.shape:
            raise InvalidParameterError(
                f"image: shape {im.shape} does not match the background's {bg.shape}"
            )
        x = im.reshape(4, -1).T
        a = (im - bg).mean(axis=0).ravel()
        keep = np.flatnonzero(a > min_anomaly)
        cells.append((x[keep], a[keep]))
    x = np.concatenate([c[0] for c in cells])
    a = np.concatenate([c[1] for c in cells])
    if len(x) > MAX_CANDIDATES:  # the brightest (ties broken by position: deterministic)
        top = np.argsort(-a, kind="stable")[:MAX_CANDIDATES]
        x = x[np.sort(top)]
    origin = np.median(bg.reshape(4, -1), axis=1)
    k = min(3, len(x))
    if k == 0:
        return np.zeros((0, 4)), [], {"candidates": 0, "members": {}}
    verts = x[nfindr(x, origin, k)]
    cls = classify(verts, origin)
    names = [c for c in CLASSES if c in cls]
    members = np.array([verts[cls[c]] for c in names], np.float64).reshape(-1, 4)
    info = {
        "candidates": len(x),
        "members": {c: [round(float(v), 4) for v in verts[cls[c]]] for c in names},
    }
    return members, names, info
