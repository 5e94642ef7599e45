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
from shapely.geometry import Polygon

from dyntarget import defaults
from dyntarget.errors import InvalidParameterError
from dyntarget.masks import check_mask, mask_to_polygons

DEFAULT_ITERATIONS = defaults.DENOISE_ITERATIONS
DEFAULT_MIN_AREA_FRACTION = defaults.MIN_AREA_FRACTION
_KERNEL = np.ones((3, 3), np.uint8)


@dataclass(frozen=True)
class DenoiseResult:
    """The denoised mask and its polygons (pixel coordinates ``(x, y)`` of pixel centres).

    Parameters
    ----------
    mask : numpy.ndarray
        Boolean ``(H, W)`` denoised mask.
    polygons : list of shapely.Polygon
        Its polygons, one per kept connected component.
    """

    mask: np.ndarray
    polygons: list[Polygon]


def close(mask: np.ndarray, iterations: int) -> np.ndarray:
    """Morphological closing with a 3x3 kernel, ``iterations`` times, outside = background.

    The mask is padded with ``iterations + 1`` background pixels first, so a
    blob near the border is not glued onto it, and a blob touching the border
    keeps its shape (the closing of the set in an unbounded background).

    Parameters
    ----------
    mask : numpy.ndarray
        ``(H, W)`` mask, boolean or 0/1 integers.
    iterations : int
        Number of closing iterations (at least 1).

    Returns
    -------
    numpy.ndarray
        ``(H, W)`` uint8 closed mask, 0 or 1.
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

    Returns
    -------
    DenoiseResult
        The mask with the small components removed and their polygons.

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
