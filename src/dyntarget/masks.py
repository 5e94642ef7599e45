"""Masks: validation of plume masks and the mask -> polygons conversion (core).

Polygons are in pixel coordinates ``(x, y) = (column, row)`` of pixel centres.
"""

from __future__ import annotations

import cv2
import numpy as np
import shapely
from shapely.geometry import Polygon

from dyntarget.errors import InvalidSceneError


def check_mask(mask: object, *, name: str = "mask") -> np.ndarray:
    """Validate a 2-D boolean (or integer, non-zero = plume) mask; return it as ``bool``.

    Parameters
    ----------
    mask : array_like
        ``(H, W)`` bool or integer mask.
    name : str
        The argument's name in error messages.

    Returns
    -------
    numpy.ndarray
        ``(H, W)`` bool. A wrong shape or dtype raises
        :class:`~dyntarget.errors.InvalidSceneError`.

    Examples
    --------
    >>> check_mask(np.array([[0, 2], [1, 0]])).tolist()
    [[False, True], [True, False]]
    """
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

    Parameters
    ----------
    mask : array_like
        ``(H, W)`` bool mask.

    Returns
    -------
    list of shapely.geometry.Polygon
        In pixel-centre coordinates, largest first.

    Examples
    --------
    >>> m = np.zeros((10, 10), bool); m[2:5, 2:8] = True; m[8, 8] = True
    >>> [round(p.area, 1) for p in mask_to_polygons(m)]
    [10.0, 1.0]
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
    # one-pixel components (specks): their unit squares, all at once (what _pixel_union
    # gives one by one: the same polygons, thousands of specks in milliseconds)
    single = pixel_counts == 1
    single[0] = False
    rows, cols = np.nonzero(single[component])
    polygons = list(shapely.box(cols - 0.5, rows - 0.5, cols + 0.5, rows + 0.5))
    for i, contour in enumerate(contours):
        if hierarchy[i][3] != -1:  # a hole; handled with its parent
            continue
        if len(contour) == 1 and single[component[contour[0, 0, 1], contour[0, 0, 0]]]:
            continue  # a speck, drawn above
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
