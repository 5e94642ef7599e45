"""Denoise (the paper's Algorithm 2): merge nearby blobs, drop small ones, return polygons.

1. ``getContours``: the mask's polygons (OpenCV ``findContours``, 8-connected
   outer boundaries with their holes);
2. ``erodeAndDilate``: a morphological closing with a 3x3 kernel repeated
   ``iterations`` times (``iterations`` dilations, then as many erosions) —
   blobs closer than about ``2 * iterations`` px merge; those still apart
   afterwards stay separate plumes;
3. ``filterByArea``: drop polygons whose area (pixels inside the outer
   boundary and outside its holes) is below ``min_area`` px, by default
   ``min_area_fraction`` (1 %) of the image area (plumes are large, enclosed
   shapes; see ``docs/results.md`` for how these defaults were chosen);
4. ``reconstructMask``: the mask of the kept polygons (holes stay holes).

Pixels beyond the image border are background (the mask is zero-padded before
the closing), so blobs near the border are not glued onto it, and plumes cut
by the border keep their shape.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
import shapely
from shapely.geometry import Polygon

from dyntarget.errors import InvalidParameterError, InvalidSceneError

DEFAULT_ITERATIONS = 1
DEFAULT_MIN_AREA_FRACTION = 0.01
_KERNEL = np.ones((3, 3), np.uint8)


@dataclass(frozen=True)
class DenoiseResult:
    """The denoised mask and its polygons (pixel coordinates ``(x, y)`` of pixel centres)."""

    mask: np.ndarray
    polygons: list[Polygon]


def check_mask(mask: object, *, name: str = "mask") -> np.ndarray:
    """Validate a 2-D boolean (or 0/1 integer) mask; return it as ``bool``."""
    arr = np.asarray(mask)
    if arr.ndim != 2 or arr.shape[0] < 1 or arr.shape[1] < 1:
        raise InvalidSceneError(
            f"{name}: expected a non-empty 2-D mask (H, W), got shape {arr.shape}"
        )
    if arr.dtype == bool:
        return arr
    if np.issubdtype(arr.dtype, np.integer):
        return arr != 0
    raise InvalidSceneError(f"{name}: expected a boolean or integer mask, got dtype {arr.dtype}")


def mask_to_polygons(mask: np.ndarray) -> list[Polygon]:
    """Polygons of a mask's 8-connected components, with holes, largest first.

    Vertices are pixel centres ``(column, row)``. A component one or two pixels
    wide (a point, a line, a thin ring: its pixel-centre polygon covers less
    than half its pixels) becomes the union of its pixels' unit squares, so
    every polygon is valid, non-empty and faithful to the mask.
    """
    mask = check_mask(mask)
    if not mask.any():
        return []
    contours, hierarchy = cv2.findContours(
        mask.astype(np.uint8), cv2.RETR_CCOMP, cv2.CHAIN_APPROX_NONE
    )
    hierarchy = hierarchy[0]
    _, component = cv2.connectedComponents(mask.astype(np.uint8), connectivity=8)
    pixel_counts = np.bincount(component.ravel())
    polygons = []
    for i, contour in enumerate(contours):
        if hierarchy[i][3] != -1:  # a hole; handled with its parent
            continue
        shell = _ring(contour)
        holes = []
        for child in _children(hierarchy, i):
            ring = contours[child][:, 0, :]
            if len(np.unique(ring, axis=0)) >= 3:
                holes.append(ring.astype(float))
        if isinstance(shell, Polygon):
            poly = Polygon(shell.exterior.coords, holes)
            if not poly.is_valid:
                poly = poly.buffer(0)
        else:
            poly = shell
        x0, y0 = contour[0, 0]
        label = component[y0, x0]
        if poly.is_empty or poly.area < THIN_AREA_RATIO * pixel_counts[label]:
            # a structure one or two pixels wide (a thin ring, a line): the pixel-centre
            # contour has (almost) no area there; its pixels' unit squares describe it exactly
            rows, cols = np.nonzero(component == label)
            poly = _pixel_union(np.column_stack([cols, rows]))
        polygons.extend(_component_pieces(poly))
    polygons.sort(key=lambda p: (-p.area, p.centroid.x, p.centroid.y))
    return polygons


SLIVER_FRACTION = 0.01
THIN_AREA_RATIO = 0.5
"""A component whose contour polygon covers less than this share of its pixels is described by its pixels."""


def _component_pieces(poly) -> list[Polygon]:
    """The polygon(s) of one connected component.

    A pixel-centre contour runs out and back along one-pixel necks; repairing it
    (``buffer(0)``) splits the component there into its body and slivers of a
    pixel or so. The largest piece is kept, and any other piece of at least
    ``SLIVER_FRACTION`` (1 %) of it and at least one pixel: real lobes joined by
    a thin neck stay, slivers do not become separate plumes.
    """
    pieces = list(poly.geoms) if poly.geom_type == "MultiPolygon" else [poly]
    pieces = [p for p in pieces if not p.is_empty]
    if len(pieces) <= 1:
        return pieces
    largest = max(p.area for p in pieces)
    return [p for p in pieces if p.area == largest or p.area >= max(1.0, SLIVER_FRACTION * largest)]


def _ring(contour: np.ndarray) -> Polygon:
    pts = contour[:, 0, :].astype(float)
    poly = Polygon(pts) if len(pts) >= 3 else None
    if poly is not None and poly.area > 0:
        return poly
    # a point or a one-pixel-wide line: the union of its pixels' unit squares
    return _pixel_union(pts)


def _pixel_union(pts: np.ndarray) -> Polygon:
    """The union of the unit squares of pixels ``(x, y)``."""
    squares = [
        shapely.box(x - 0.5, y - 0.5, x + 0.5, y + 0.5)
        for x, y in np.unique(pts.astype(float), axis=0)
    ]
    return shapely.union_all(squares)


def _children(hierarchy: np.ndarray, i: int) -> list[int]:
    out, child = [], hierarchy[i][2]
    while child != -1:
        out.append(child)
        child = hierarchy[child][0]
    return out


def close(mask: np.ndarray, iterations: int) -> np.ndarray:
    """Morphological closing with a 3x3 kernel, ``iterations`` times, outside = background.

    The mask is padded with ``iterations + 1`` background pixels first, so a
    blob near the border is not glued onto it, and a blob touching the border
    keeps its shape (the closing of the set in an unbounded background).
    """
    pad = iterations + 1
    padded = cv2.copyMakeBorder(
        mask.astype(np.uint8), pad, pad, pad, pad, cv2.BORDER_CONSTANT, value=0
    )
    closed = cv2.morphologyEx(padded, cv2.MORPH_CLOSE, _KERNEL, iterations=iterations)
    return closed[pad:-pad, pad:-pad]


def denoise(
    mask: np.ndarray,
    *,
    iterations: int = DEFAULT_ITERATIONS,
    min_area: float | None = None,
    min_area_fraction: float = DEFAULT_MIN_AREA_FRACTION,
) -> DenoiseResult:
    """Denoise a plume mask (Algorithm 2); see the module docstring.

    Parameters
    ----------
    mask : bool (H, W)
    iterations : number of 3x3 closing iterations (0 = no merging).
    min_area : smallest kept polygon in pixels; overrides ``min_area_fraction``.
    min_area_fraction : smallest kept polygon as a fraction of the image area.

    Examples
    --------
    >>> m = np.zeros((20, 20), bool)
    >>> m[2:10, 2:6] = m[2:10, 7:11] = True   # two blobs one pixel apart
    >>> m[15, 15] = True                      # a speck
    >>> r = denoise(m, iterations=1, min_area=4)
    >>> len(r.polygons), int(r.mask.sum())
    (1, 72)
    """
    mask = check_mask(mask)
    if (
        isinstance(iterations, bool)
        or not isinstance(iterations, int | np.integer)
        or iterations < 0
    ):
        raise InvalidParameterError(f"iterations: expected an integer >= 0, got {iterations!r}")
    if not 0.0 <= float(min_area_fraction) <= 1.0:
        raise InvalidParameterError(
            f"min_area_fraction: expected a fraction in 0..1, got {min_area_fraction!r}"
        )
    if min_area is None:
        min_area = float(min_area_fraction) * mask.size
    elif not np.isfinite(min_area) or min_area < 0:
        raise InvalidParameterError(f"min_area: expected a number of pixels >= 0, got {min_area!r}")
    m8 = mask.astype(np.uint8)
    if iterations > 0 and m8.any():
        m8 = close(m8, int(iterations))
    n, labels, stats, _ = cv2.connectedComponentsWithStats(m8, connectivity=8)
    keep = np.zeros(n, bool)
    keep[1:] = stats[1:, cv2.CC_STAT_AREA] >= min_area
    out = keep[labels]
    return DenoiseResult(mask=out, polygons=mask_to_polygons(out))
