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

Pixels beyond the image border count as background for the closing's
dilation and as foreground for its erosion (OpenCV's defaults), so plumes cut
by the border are not eroded away.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from shapely.geometry import LineString, MultiPoint, Point, Polygon

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

    Vertices are pixel centres ``(column, row)``. A component only one pixel
    wide (a point or a line of pixels) becomes the square-buffered point or
    line (half a pixel each side), so every polygon is valid and non-empty.
    """
    mask = check_mask(mask)
    if not mask.any():
        return []
    contours, hierarchy = cv2.findContours(
        mask.astype(np.uint8), cv2.RETR_CCOMP, cv2.CHAIN_APPROX_NONE
    )
    hierarchy = hierarchy[0]
    polygons = []
    for i, contour in enumerate(contours):
        if hierarchy[i][3] != -1:  # a hole; handled with its parent
            continue
        shell = _ring(contour)
        holes = []
        child = hierarchy[i][2]
        while child != -1:
            ring = contours[child][:, 0, :]
            if len(np.unique(ring, axis=0)) >= 3:
                holes.append(ring.astype(float))
            child = hierarchy[child][0]
        if isinstance(shell, Polygon):
            poly = Polygon(shell.exterior.coords, holes)
            if not poly.is_valid:
                poly = poly.buffer(0)
        else:
            poly = shell
        if poly.geom_type == "MultiPolygon":
            polygons.extend(poly.geoms)
        else:
            polygons.append(poly)
    polygons.sort(key=lambda p: (-p.area, p.centroid.x, p.centroid.y))
    return polygons


def _ring(contour: np.ndarray):
    pts = contour[:, 0, :].astype(float)
    unique = np.unique(pts, axis=0)
    if len(unique) == 1:
        return Point(unique[0]).buffer(0.5, cap_style="square")
    poly = Polygon(pts) if len(unique) >= 3 else None
    if poly is None or poly.area == 0:
        # a line of pixels: cover it with its half-pixel square buffer
        return (
            LineString(pts).buffer(0.5, cap_style="square") if len(unique) > 1 else MultiPoint(pts)
        )
    return poly


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
        m8 = cv2.morphologyEx(m8, cv2.MORPH_CLOSE, _KERNEL, iterations=int(iterations))
    n, labels, stats, _ = cv2.connectedComponentsWithStats(m8, connectivity=8)
    keep = np.zeros(n, bool)
    keep[1:] = stats[1:, cv2.CC_STAT_AREA] >= min_area
    out = keep[labels]
    return DenoiseResult(mask=out, polygons=mask_to_polygons(out))
