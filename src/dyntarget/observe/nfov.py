"""NFOV observation simulator and the paper's utility metrics (Table 2 columns).

Utility maps are computed on the **high-resolution** scene (the truth the
NFOV sensor would see):

* intensity: the plume label overlaid on the blue band (``label * blue``),
  divided by its maximum so it spans 0..1 per scene;
* gradient: the Sobel gradient magnitude of the intensity with a 5x5 kernel,
  divided by its maximum (0..1 per scene) — high at the plume's diffuse edges
  and inner structure.

A pointing at WFOV pixel ``(x, y)`` (rounded to the nearest pixel centre)
observes the high-resolution footprint under ``footprint x footprint`` WFOV
pixels centred there (default 1: exactly the ``factor x factor`` block under
one WFOV pixel). Pointings outside the image observe nothing and are
dropped, and so are pointings on nodata; several pointings at the same WFOV pixel count once.

Metrics per trajectory: pixels observed (distinct pointings), ratio plume
(mean plume fraction of the observed footprints), intensity and gradient
(mean utility over the observed footprints). Empty trajectories score 0.
"""

from __future__ import annotations

import math
import weakref
from collections.abc import Callable
from dataclasses import asdict, dataclass

import cv2
import numpy as np

from dyntarget.errors import InvalidParameterError, InvalidSceneError
from dyntarget.scene import Scene, block_mean, check_factor
from dyntarget.trajectory import Trajectory
from dyntarget.utility import UtilityMaps


@dataclass(frozen=True)
class ObservationMetrics:
    """What the NFOV sensor observed along one trajectory.

    Parameters
    ----------
    pixels_observed : int
        Distinct WFOV pixels observed (pointings inside the image, off nodata).
    ratio_plume : float
        Mean plume fraction of the observed footprints, 0..1.
    intensity : float
        Mean intensity utility over the observed footprints, 0..1.
    gradient : float
        Mean gradient utility over the observed footprints, 0..1.
    """

    pixels_observed: int
    ratio_plume: float
    intensity: float
    gradient: float

    def as_dict(self) -> dict[str, float]:
        """The metrics as a plain dict.

        Returns
        -------
        dict of str to float
            ``pixels_observed``, ``ratio_plume``, ``intensity`` and ``gradient``.
        """
        return asdict(self)


def observed_pixels(trajectory: Trajectory, wfov_shape: tuple[int, int]) -> np.ndarray:
    """Distinct WFOV pixels ``(row, col)`` hit by the pointings, in first-visit order.

    Parameters
    ----------
    trajectory : dyntarget.trajectory.Trajectory
        The pointings, in WFOV pixels.
    wfov_shape : tuple of int
        The WFOV grid's ``(H, W)``; pointings outside it are dropped.

    Returns
    -------
    numpy.ndarray
        ``(k, 2)`` int64 ``(row, col)`` of the pixels under the rounded pointings.
    """
    if len(trajectory) == 0:
        return np.zeros((0, 2), np.int64)
    cols = np.floor(trajectory.points[:, 0] + 0.5).astype(np.int64)
    rows = np.floor(trajectory.points[:, 1] + 0.5).astype(np.int64)
    h, w = wfov_shape
    inside = (rows >= 0) & (rows < h) & (cols >= 0) & (cols < w)
    rc = np.column_stack([rows[inside], cols[inside]])
    _, first = np.unique(rc[:, 0] * w + rc[:, 1], return_index=True)
    pixels: np.ndarray = rc[np.sort(first)]
    return pixels


def _check_footprint(footprint: object) -> int:
    if (
        isinstance(footprint, bool)
        or not isinstance(footprint, int)
        or footprint < 1
        or footprint % 2 == 0
    ):
        raise InvalidParameterError(
            f"footprint: expected an odd positive number of WFOV pixels, got {footprint!r}"
        )
    return footprint


def _per_wfov(
    maps: UtilityMaps, factor: int, footprint: int
) -> tuple[np.ndarray, np.ndarray | None]:
    """``(3, H/f, W/f)`` mean label/intensity/gradient under each WFOV pointing; valid WFOV mask."""
    stack = np.stack([maps.label.astype(np.float32), maps.intensity, maps.gradient])
    per_wfov = block_mean(stack, factor)  # (3, H/f, W/f): mean over each WFOV pixel's footprint
    if footprint > 1:
        per_wfov = np.stack(
            [
                cv2.blur(ch, (footprint, footprint), borderType=cv2.BORDER_CONSTANT)
                for ch in per_wfov
            ]
        )
        # at the image edge, average only over footprint pixels that exist
        ones = cv2.blur(
            np.ones(per_wfov.shape[1:], np.float32),
            (footprint, footprint),
            borderType=cv2.BORDER_CONSTANT,
        )
        per_wfov = per_wfov / ones
    valid_wfov = None
    if maps.valid is not None:
        valid_wfov = block_mean(maps.valid[None].astype(np.float32), factor)[0] == 1.0
    return per_wfov, valid_wfov


def observe(
    trajectory: Trajectory,
    truth: Scene | UtilityMaps,
    *,
    factor: int,
    footprint: int = 1,
) -> ObservationMetrics:
    """Score a trajectory planned on the WFOV grid against the high-resolution truth.

    ``factor`` is the high-res -> WFOV downsampling factor the trajectory was
    planned at; ``footprint`` the NFOV footprint in WFOV pixels (odd, >= 1).

    Parameters
    ----------
    trajectory : dyntarget.trajectory.Trajectory
        The pointings, in WFOV pixels.
    truth : dyntarget.scene.Scene or UtilityMaps
        The labelled high-resolution scene, or its utility maps.
    factor : int
        High-resolution pixels per WFOV pixel along each axis.
    footprint : int
        NFOV footprint side in WFOV pixels (odd, at least 1).

    Returns
    -------
    ObservationMetrics
        The trajectory's scores (all 0 when it observes nothing).
    """
    maps = truth if isinstance(truth, UtilityMaps) else UtilityMaps.from_scene(truth)
    factor = check_factor(factor, maps.label.shape)
    footprint = _check_footprint(footprint)
    per_wfov, valid_wfov = _per_wfov(maps, factor, footprint)
    rc = observed_pixels(trajectory, per_wfov.shape[1:])
    if valid_wfov is not None and len(rc):  # nodata is never observed
        rc = rc[valid_wfov[rc[:, 0], rc[:, 1]]]
    if len(rc) == 0:
        return ObservationMetrics(0, 0.0, 0.0, 0.0)
    vals = per_wfov[:, rc[:, 0], rc[:, 1]].astype(np.float64)
    return ObservationMetrics(
        pixels_observed=len(rc),
        ratio_plume=float(vals[0].mean()),
        intensity=float(vals[1].mean()),
        gradient=float(vals[2].mean()),
    )


_PER_WFOV_CACHE: weakref.WeakKeyDictionary[
    Scene, dict[tuple[int, int], tuple[np.ndarray, np.ndarray | None]]
] = weakref.WeakKeyDictionary()


def _per_wfov_of(
    truth: Scene | UtilityMaps, factor: int, footprint: int
) -> tuple[np.ndarray, np.ndarray | None]:
    """:func:`_per_wfov` of a truth object, remembered while the object lives."""
    if isinstance(truth, UtilityMaps):  # not hashable: computed each time
        check_factor(factor, truth.label.shape)
        return _per_wfov(truth, factor, footprint)
    if not isinstance(truth, Scene):
        raise InvalidParameterError(
            f"truth provider: expected it to return a Scene or UtilityMaps, got {type(truth).__name__}"
        )
    per = _PER_WFOV_CACHE.setdefault(truth, {})
    key = (factor, footprint)
    if key not in per:
        maps = UtilityMaps.from_scene(truth)
        check_factor(factor, maps.label.shape)
        per[key] = _per_wfov(maps, factor, footprint)
    return per[key]


def observe_at(
    trajectory: Trajectory,
    truth: Callable[[float], Scene | UtilityMaps],
    *,
    factor: int,
    footprint: int = 1,
    latency_s: float = 0.0,
) -> ObservationMetrics:
    """Score every pointing against the truth *at its own time*.

    Parameters
    ----------
    trajectory : Trajectory
        Pointings on the WFOV grid; ``trajectory.times`` (seconds after the
        look-ahead acquisition, as set by the kinematic schedule) give when each
        is taken; an untimed trajectory takes every pointing at ``latency_s``.
    truth : callable
        Truth provider ``t -> Scene`` (labelled, high resolution) or ``t -> UtilityMaps``,
        e.g. :meth:`dyntarget.sequence.FrameSequence.truth_at`.
    factor, footprint : int
        As for :func:`observe`.
    latency_s : float
        Added to every pointing's time (onboard latency not already in the schedule).

    Returns
    -------
    ObservationMetrics
        As :func:`observe`; a WFOV pixel pointed at more than once counts once,
        at its first visit. With one truth for every time this equals :func:`observe`.

    Examples
    --------
    >>> lab = np.zeros((8, 8), bool); lab[:4, :4] = True
    >>> moved = np.zeros((8, 8), bool); moved[4:, 4:] = True
    >>> img = np.full((4, 8, 8), 0.5, np.float32)
    >>> scenes = {0.0: Scene(img, label=lab), 60.0: Scene(img, label=moved)}
    >>> traj = Trajectory(np.array([[0.0, 0.0]]), np.zeros(1), "t", times=np.zeros(1))
    >>> observe_at(traj, scenes.__getitem__, factor=4).ratio_plume
    1.0
    >>> observe_at(traj, scenes.__getitem__, factor=4, latency_s=60.0).ratio_plume
    0.0
    """
    if not (isinstance(latency_s, int | float) and math.isfinite(latency_s)):
        raise InvalidParameterError(f"latency_s: expected finite seconds, got {latency_s!r}")
    if not callable(truth):
        raise InvalidParameterError("truth: expected a callable t -> Scene (a truth provider)")
    footprint = _check_footprint(footprint)
    n = len(trajectory)
    if n == 0:
        return ObservationMetrics(0, 0.0, 0.0, 0.0)
    times = (
        np.zeros(n) if trajectory.times is None else np.asarray(trajectory.times, np.float64)
    ) + float(latency_s)
    first = truth(float(times[0]))
    per0, _ = _per_wfov_of(first, factor, footprint)
    h, w = per0.shape[1:]
    cols = np.floor(trajectory.points[:, 0] + 0.5).astype(np.int64)
    rows = np.floor(trajectory.points[:, 1] + 0.5).astype(np.int64)
    inside = np.flatnonzero((rows >= 0) & (rows < h) & (cols >= 0) & (cols < w))
    _, first_visit = np.unique(rows[inside] * w + cols[inside], return_index=True)
    idx = inside[np.sort(first_visit)]  # pointings that count, in first-visit order
    vals = np.zeros((3, len(idx)), np.float64)
    keep = np.ones(len(idx), bool)
    for t in np.unique(times[idx]):
        sel = np.flatnonzero(times[idx] == t)
        per, valid = _per_wfov_of(truth(float(t)), factor, footprint)
        if per.shape[1:] != (h, w):
            raise InvalidSceneError(
                f"truth at t={t:g} s: WFOV grid {per.shape[1:]} differs from {(h, w)} at t={times[0]:g} s"
            )
        r, c = rows[idx[sel]], cols[idx[sel]]
        vals[:, sel] = per[:, r, c]
        if valid is not None:  # nodata is never observed
            keep[sel] = valid[r, c]
    vals = vals[:, keep]
    if vals.shape[1] == 0:
        return ObservationMetrics(0, 0.0, 0.0, 0.0)
    return ObservationMetrics(
        pixels_observed=int(vals.shape[1]),
        ratio_plume=float(vals[0].mean()),
        intensity=float(vals[1].mean()),
        gradient=float(vals[2].mean()),
    )


def pointing_truth(
    trajectory: Trajectory, image: np.ndarray, label: np.ndarray, *, factor: int = 1
) -> dict[str, np.ndarray]:
    """What each pointing observed of the truth: plume fraction, intensity, gradient.

    The values of the utility maps (:class:`UtilityMaps`) averaged over the
    ``factor x factor`` high-resolution block under each pointing's WFOV pixel
    (NaN for a pointing outside the image).

    Parameters
    ----------
    trajectory : Trajectory
        Pointings in WFOV pixels.
    image : array (4, H, W)
        The high-resolution image (``H, W`` = WFOV shape times ``factor``).
    label : bool array (H, W)
        The true plume mask at that resolution.
    factor : int
        High-resolution pixels per WFOV pixel.

    Returns
    -------
    dict
        ``{"plume": ..., "intensity": ..., "gradient": ...}``, one float per pointing.

    Examples
    --------
    >>> from dyntarget.trajectory import Trajectory
    >>> img = np.full((4, 4, 4), 0.5, np.float32)
    >>> lab = np.zeros((4, 4), bool); lab[:, :2] = True
    >>> t = Trajectory(np.array([[0.0, 0.0], [3.0, 0.0], [9.0, 0.0]]), np.zeros(3, int), "d")
    >>> pointing_truth(t, img, lab)["plume"].tolist()
    [1.0, 0.0, nan]
    """
    maps = UtilityMaps.from_scene(Scene(image, label=label))
    stack = np.stack([maps.label.astype(np.float32), maps.intensity, maps.gradient])
    per_wfov = block_mean(stack, factor)
    h, w = per_wfov.shape[1:]
    pts = np.asarray(trajectory.points, np.float64).reshape(-1, 2)
    cols = np.floor(pts[:, 0] + 0.5).astype(np.int64)
    rows = np.floor(pts[:, 1] + 0.5).astype(np.int64)
    inside = (rows >= 0) & (rows < h) & (cols >= 0) & (cols < w)
    out = np.full((3, len(pts)), np.nan)
    out[:, inside] = per_wfov[:, rows[inside], cols[inside]]
    return {"plume": out[0], "intensity": out[1], "gradient": out[2]}
