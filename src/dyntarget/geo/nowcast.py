"""GEO detection (a brightness threshold on coarse pixels) and pysteps nowcasting."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from dyntarget.errors import InvalidParameterError

DETECT_THRESHOLD = 0.03
"""Brightness above the background (reflectance, mean of the bands) that counts as plume."""


def detect(
    image: np.ndarray, threshold: float = DETECT_THRESHOLD, background: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Plume candidates on a GEO brightness image: brighter than the background by ``threshold``.

    Parameters
    ----------
    image : numpy.ndarray
        ``(H, W)`` brightness (reflectance) on the GEO grid.
    threshold : float
        Brightness above the background that counts.
    background : numpy.ndarray or None
        The clear-sky brightness of the same cells (a composite of cloud- and
        plume-free days); ``None``: the image's median.

    Returns
    -------
    mask : numpy.ndarray
        Boolean ``(H, W)`` detections.
    anomaly : numpy.ndarray
        ``(H, W)`` brightness above the background, clipped at 0.

    Examples
    --------
    >>> img = np.full((4, 5), 0.1); img[1, 2] = 0.3
    >>> m, a = detect(img); int(m.sum()), round(float(a[1, 2]), 3)
    (1, 0.2)
    """
    img = np.asarray(image, np.float64)
    if img.ndim != 2 or img.size == 0:
        raise InvalidParameterError(f"image: expected a 2-D brightness image, got {img.shape}")
    if not (math.isfinite(threshold) and threshold > 0):
        raise InvalidParameterError(f"threshold: expected > 0, got {threshold!r}")
    if background is None:
        ref: Any = float(np.nanmedian(img))
    else:
        ref = np.asarray(background, np.float64)
        if ref.shape != img.shape:
            raise InvalidParameterError(
                f"background: shape {ref.shape} does not match the image's {img.shape}"
            )
    anomaly = np.clip(img - ref, 0.0, None)
    return anomaly > threshold, anomaly


def unmix(image: np.ndarray, background: np.ndarray, members: np.ndarray) -> np.ndarray:
    """Per-cell cover fractions of end-member spectra over a known background (non-negative).

    Each cell's spectrum is taken as the linear mixture
    ``background + sum_k f_k (members[k] - background)`` (a layer of cover ``f_k``
    and reflectance ``members[k]`` over the ground), and the fractions ``f >= 0``
    are found by non-negative least squares (:func:`scipy.optimize.nnls`), cell
    by cell. The fraction of plume end-members is what tells a plume from a
    meteorological cloud of the same brightness.

    Parameters
    ----------
    image : numpy.ndarray
        ``(B, H, W)`` reflectance on the GEO grid.
    background : numpy.ndarray
        ``(B, H, W)`` clear-sky reflectance of the same cells.
    members : numpy.ndarray
        ``(K, B)`` end-member reflectance spectra (``K <= B``).

    Returns
    -------
    numpy.ndarray
        ``(K, H, W)`` fractions, ``>= 0``.

    Examples
    --------
    >>> bg = np.full((4, 1, 2), 0.1)
    >>> members = np.array([[0.8, 0.8, 0.8, 0.8], [0.3, 0.26, 0.22, 0.27]])
    >>> img = bg.copy(); img[:, 0, 0] += 0.5 * (members[0] - 0.1)  # half a cloud
    >>> img[:, 0, 1] += 0.2 * (members[1] - 0.1)  # a fifth of an ash plume
    >>> np.round(unmix(img, bg, members)[:, 0], 3).tolist()
    [[0.5, 0.0], [0.0, 0.2]]
    """
    from scipy.optimize import nnls

    img = np.asarray(image, np.float64)
    ref = np.asarray(background, np.float64)
    m = np.asarray(members, np.float64)
    if img.ndim != 3 or ref.shape != img.shape:
        raise InvalidParameterError(
            f"unmix: expected (bands, H, W) image and background of one shape, "
            f"got {img.shape} and {ref.shape}"
        )
    if m.ndim != 2 or m.shape[1] != img.shape[0] or m.shape[0] > m.shape[1]:
        raise InvalidParameterError(
            f"unmix: expected (K, {img.shape[0]}) end-members with K <= bands, got {m.shape}"
        )
    b, h, w = img.shape
    d = (img - ref).reshape(b, -1).T  # (cells, bands)
    g = ref.reshape(b, -1).T
    out = np.zeros((h * w, m.shape[0]))
    for i in range(h * w):
        out[i] = nnls((m - g[i]).T, d[i])[0]
    return out.T.reshape(m.shape[0], h, w)


def nowcast(
    fields: list[np.ndarray],
    interval_s: float,
    leads_s: list[float],
    motion: Callable[[np.ndarray], np.ndarray],
) -> tuple[np.ndarray, np.ndarray]:
    """Carry the last GEO field to future times: a motion field + pysteps' semi-Lagrangian.

    As in pysteps, the motion is an input: ``motion(stack)`` of the ``(T, H, W)``
    fields gives the ``(2, H, W)`` field in pixels per interval; the pipeline passes
    the predict stage's Lucas-Kanade (:func:`dyntarget.predict.lucas_kanade`).

    Parameters
    ----------
    fields : list of numpy.ndarray
        The last images' fields (e.g. :func:`detect`'s anomaly), oldest first,
        ``interval_s`` apart; with one field there is no motion (persistence).
    interval_s : float
        Seconds between consecutive fields.
    leads_s : list of float
        Seconds after the last field to extrapolate to (>= 0).
    motion : callable
        ``motion(stack) -> (2, H, W)`` pixels per interval (``u``, ``v``), finite.

    Returns
    -------
    out : numpy.ndarray
        ``(len(leads_s), H, W)`` extrapolated fields (0 where nothing flows in).
    velocity : numpy.ndarray
        ``(2, H, W)`` motion, GEO pixels per second (x, y).

    Examples
    --------
    >>> y, x = np.mgrid[0:32, 0:64]
    >>> blob = lambda c: np.exp(-((x - c) ** 2 + (y - 16) ** 2) / 8.0)
    >>> from functools import partial
    >>> from dyntarget.predict import lucas_kanade
    >>> lk = partial(lucas_kanade, needs="pysteps")
    >>> out, v = nowcast([blob(20), blob(22), blob(24)], 600.0, [600.0], lk)
    >>> int(np.argmax(out[0][16]))
    26
    """
    if not fields:
        raise InvalidParameterError("nowcast: no GEO field to extrapolate")
    if not (math.isfinite(interval_s) and interval_s > 0):
        raise InvalidParameterError(f"interval_s: expected seconds > 0, got {interval_s!r}")
    last = np.asarray(fields[-1], np.float64)
    leads = np.asarray(leads_s, np.float64)
    if np.any(~np.isfinite(leads)) or np.any(leads < 0):
        raise InvalidParameterError(f"leads_s: expected seconds >= 0, got {leads_s!r}")
    if len(fields) < 2 or not np.any(last > 0):
        return np.repeat(last[None], len(leads), axis=0), np.zeros((2, *last.shape))
    import warnings

    try:
        import contextlib
        import io

        with contextlib.redirect_stdout(io.StringIO()), warnings.catch_warnings():
            warnings.simplefilter("ignore")  # pysteps announces its config file, warns on import
            from pysteps import extrapolation
    except ImportError:
        raise InvalidParameterError(
            "nowcasting GEO images needs pysteps: pip install 'dyntarget[geo]'"
        ) from None
    v = motion(np.stack([np.asarray(f, np.float64) for f in fields]))  # px per interval
    out = np.zeros((len(leads), *last.shape))
    steps = leads / interval_s
    nz = steps > 1e-9
    out[~nz] = last
    if nz.any():
        ext = extrapolation.get_method("semilagrangian")
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)
            res = ext(last, v, list(steps[nz]), outval=0.0)
        out[nz] = np.nan_to_num(np.asarray(res, np.float64))
    return out, v / interval_s
