"""Plume motion from two looks (dense optical flow) or from a wind prior (one look).

Method of :func:`estimate_motion` (documented in ``docs/onboard.md``, "Predictive
targeting"; measured on real evolving fields by ``benchmarks/motion_real.py``):

1. Both frames are reduced to one *brightness* band, the mean of R, G, B and
   NIR, over the plumes' bounding box plus a margin (:data:`CROP_MARGIN`, at
   least :data:`MIN_CROP` px). Both are scaled to 8 bits with the *same* range
   (1 % of the two frames together to the larger of their 99 % and the plumes'
   own 99.5 %, so a few bright cells in a dark frame keep their texture) and
   downsampled by a whole factor to at most :data:`FLOW_MAX_PX` a side
   (:data:`FLOW_MAX_PX_MOVING` once the background is found moving).
2. OpenCV's Farneback optical flow (default; ``flow="dis"``: DIS; ``flow="lk"``:
   pysteps' Lucas-Kanade, the ``nowcast`` extra) gives a dense flow previous ->
   current and current -> previous; a pixel is consistent when the round trip
   returns within 1 px (or 10 % of its displacement), textured when the smaller
   structure-tensor eigenvalue exceeds :data:`MIN_EIGEN` (Shi-Tomasi).
3. The background: the histogram mode of the flow over textured, consistent
   pixels away from the plumes (farther than the plumes' own displacement), or
   phase correlation where there are too few. ``ground="fixed"`` removes it as
   misregistration; ``"moving"`` keeps it (weather, radar: the background is
   the same moving field and votes too); ``"auto"`` (default) calls it moving
   when it exceeds :data:`MAX_MISREGISTRATION_PX`, is not one rigid shift, or
   moves as the plumes do, and writes its decision in ``Motion.ground`` and the notes.
4. The consistent, textured pixels of the previous mask's interior vote. If fewer
   than :data:`CALM_FRACTION` move by more than :data:`STILL_PX`, the air is calm;
   otherwise ``Motion.velocity`` is the *mode* of the moving votes (smoothed 2-D
   histogram peak: over semi-transparent edges the flow mixes in the still ground,
   which pulls a median towards zero).
5. The dense field (``Motion.dense``, :class:`MotionField`): a base motion (a robust
   affine fit when it clearly explains the votes better than the mode: rotation,
   shear; else the mode) plus the votes' local departures from it when they exceed
   the flow's noise (:data:`RESIDUAL_MIN_PX`), averaged by Gaussian normalised
   convolution (:data:`FIELD_SIGMA`). :mod:`dyntarget.predict.advect` carries each
   detached plume along it (semi-Lagrangian).
6. Regimes per plume: each current plume is carried back by its own displacement
   and compared with the previous mask inside that footprint; an upwind edge that
   stayed makes it *attached* (vent held), otherwise *detached*. Over a background
   ``"auto"`` found moving no vent is sought (growth upwind is not a vent).
7. Confidence in [0, 1]: the share of plume pixels with trackable texture
   (saturating at :data:`TEXTURE_SATURATION`), times the agreement of the votes
   with the dense field (1 - median residual / median displacement: rotation and
   shear are not disagreement), times a count term (saturating at 200 full-grid
   px of votes). Below :data:`LOW_CONFIDENCE` the estimate is not used: the Motion
   is calm with ``fallback="persistence"`` (the mask is not moved, never worse
   than not predicting) and its notes say so and why.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import cv2
import numpy as np
from affine import Affine

from dyntarget.errors import InvalidParameterError, InvalidSceneError

REGIMES = ("calm", "detached", "attached", "mixed")
STILL_PX = 0.5
"""A vote moving by less than this many pixels between the looks counts as still."""
CALM_FRACTION = 0.25
"""Fewer moving votes than this share of all votes: calm air (no motion)."""
MAX_LEAD_INTERVALS = 30
"""Longest lead two looks support, in intervals between the looks: the motion is
extrapolated, and growth, decay and turning are not modelled (``plan --lead-s`` says so)."""
LOW_CONFIDENCE = 0.3
"""Below this confidence the flow is not trusted (``Motion.reliable`` is False)."""
MIN_EIGEN = 25.0
"""A pixel carries trackable texture when the smaller eigenvalue of its 5 x 5 structure
tensor (``cv2.cornerMinEigenVal``, 3 x 3 Sobel) on the 8-bit brightness exceeds this; a
flat plume interior with 0.4 % reflectance noise stays near 1, an edge alone near 10."""
CROP_MARGIN = 24
"""Pixels around the plumes' bounding box over which the flow is computed."""
MIN_CROP = 256
"""Smallest side of that box (or the image): OpenCV builds fewer pyramid levels on small
images, and Farneback then loses displacements of a few pixels (measured: a 6 px drift
read as -1.4 px on a 119 x 141 px crop, right on 140 x 160 px)."""
MIN_REGISTRATION_RESPONSE = 0.05
"""Weakest phase-correlation peak trusted for the ground's shift."""
MIN_COMPONENT_PX = 10
"""Plumes smaller than this (px) are not given a regime of their own (they move with the flow)."""
ATTACHED_UPWIND = 0.5
"""Upwind edge moving less than this share of the flow displacement: attached plume."""


GROUNDS = ("auto", "fixed", "moving")
MOTION_FIELDS = ("dense", "uniform")
FLOW_MAX_PX = 256
"""The flow is computed on the plumes' window downsampled (area mean, by a whole factor) to
at most this many pixels a side; the displacements are scaled back. Cost then stays near
constant with the image size; the velocity resolution stays well under a pixel of the
full grid for displacements of a few pixels (``benchmarks/motion_real.py``)."""
FLOW_MAX_PX_MOVING = 384
"""Over a background found (or given) moving, the flow grid is refined to at most this many
pixels a side (a second flow for ``ground="auto"``): the weather's many cells move each their
own way at scales the :data:`FLOW_MAX_PX` grid averages out. Chosen on the first five frame
pairs of the FMI radar day (a 1024 px window: 1/3 grid against 1/4 and 1/2; IoU at 15 min
0.98 of pysteps LK's against 0.91 and 0.97) and checked on its 28 other pairs
(``benchmarks/motion_real.py``); over a fixed ground the grid stays at :data:`FLOW_MAX_PX`."""
MAX_MISREGISTRATION_PX = 4.0
"""``ground="auto"``: a background moving by more than this between the looks (full-grid px)
is not a misregistration of a fixed ground but the scene moving (weather, clouds)."""
FIELD_SIGMA = 6.0
"""Gaussian (cells of the flow grid) over which the votes are averaged into the dense field."""
FIELD_PRIOR = 0.05
"""Weight (share of a fully voted neighbourhood) of the scene's mode in the dense field:
far from any vote the field tends to the mode."""
TEXTURE_SATURATION = 0.15
"""Share of plume pixels carrying trackable texture at which the texture term reaches 1."""


@dataclass(frozen=True, eq=False)
class MotionField:
    """A spatially varying velocity: ``(vx, vy)`` px/s on a coarse grid over the plumes' window.

    Parameters
    ----------
    velocity : numpy.ndarray
        ``float32 (h, w, 2)`` px/s of the full grid, one cell per ``scale`` x ``scale`` px.
    origin : tuple of int
        ``(x0, y0)``: the full-grid pixel of cell (0, 0)'s top-left corner.
    scale : int
        Full-grid pixels per cell.
    shape : tuple of int
        ``(H, W)`` of the full grid.

    Examples
    --------
    >>> f = MotionField(np.ones((2, 2, 2), np.float32), (0, 0), 4, (8, 8))
    >>> f.full().shape, float(f.full()[5, 5, 0])
    ((8, 8, 2), 1.0)
    >>> f.sample(np.zeros(0), np.zeros(0)).shape  # no position: no velocity
    (0, 2)
    """

    velocity: np.ndarray
    origin: tuple[int, int]
    scale: int
    shape: tuple[int, int]

    def sample(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Velocity (px/s) at full-grid positions ``x``, ``y`` (bilinear; the window's edge beyond).

        Parameters
        ----------
        x, y : numpy.ndarray
            Positions, full-grid pixels (any shape).

        Returns
        -------
        numpy.ndarray
            ``float32 (..., 2)``.
        """
        if np.size(x) == 0:  # nothing to sample (OpenCV refuses an empty map)
            return np.zeros((*np.shape(x), 2), np.float32)
        s = float(self.scale)
        cx = ((np.asarray(x, np.float32) - self.origin[0] - (s - 1) / 2) / s).astype(np.float32)
        cy = ((np.asarray(y, np.float32) - self.origin[1] - (s - 1) / 2) / s).astype(np.float32)
        flat = cx.ndim != 2
        if flat:
            cx, cy = cx.reshape(1, -1), cy.reshape(1, -1)
        out = cv2.remap(self.velocity, cx, cy, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        out = out.reshape(*cx.shape, 2)
        return out.reshape(*np.shape(x), 2) if flat else out

    def full(self) -> np.ndarray:
        """The velocity at every pixel of the full grid, ``float32 (H, W, 2)`` px/s.

        Returns
        -------
        numpy.ndarray
            ``float32 (H, W, 2)``.
        """
        h, w = self.shape
        gy, gx = np.mgrid[0:h, 0:w].astype(np.float32)
        return self.sample(gx, gy)


@dataclass(frozen=True)
class Motion:
    """How the plume moves, in pixels of the current frame's grid.

    Parameters
    ----------
    velocity : tuple of float
        ``(vx, vy)`` in pixels per second, x = column (east in a north-up
        image), y = row (south in a north-up image); relative to the ground.
    regime : {"calm", "detached", "attached", "mixed"}
        ``"detached"`` moves as a whole, ``"attached"`` has its vent end fixed
        and stretches downwind, ``"mixed"`` has both kinds of plume in the scene
        (see ``attached``).
    confidence : float
        0 (no information) to 1; see :data:`LOW_CONFIDENCE`.
    source : str
        ``"two-looks"`` or ``"wind-prior"``.
    method : str
        How the velocity was obtained (e.g. ``"Farneback flow, dense field (1/2 grid)"``).
    vent : tuple of float or None
        ``(x, y)`` of the attached plume's upwind end in the current frame, else ``None``.
    ground_shift : tuple of float
        ``(dx, dy)`` pixels the ground moved between the looks (misregistration).
    upwind_shift, downwind_shift : float or None
        Displacement (px) of the masks' upwind and downwind edges along the flow
        direction between the looks (two looks only).
    interval_s : float or None
        Seconds between the looks (two looks only).
    notes : tuple of str
        Anything the estimate wants the user to know.
    attached : tuple of tuple of float
        ``(vent x, vent y, front speed px/s)`` per attached plume seen by two
        looks; plumes of the mask near none of these vents move as a whole. Empty
        for a wind prior (then ``regime`` applies to every plume and an attached
        plume's front advances at the full speed).
    ground : str
        Two looks: ``"fixed"`` (the background's shift was removed as
        misregistration) or ``"moving"`` (the background moves itself: not removed);
        empty for a wind prior.
    fallback : str
        ``"persistence"`` when the estimate was too unsure to use (then the motion is
        calm: the mask is not moved) and the notes say why; else empty.
    dense : MotionField or None
        The spatially varying velocity (px/s) detached plumes are advected by; ``None``
        for one velocity per scene.
    """

    velocity: tuple[float, float]
    regime: str = "detached"
    confidence: float = 1.0
    source: str = "wind-prior"
    method: str = ""
    vent: tuple[float, float] | None = None
    ground_shift: tuple[float, float] = (0.0, 0.0)
    upwind_shift: float | None = None
    downwind_shift: float | None = None
    interval_s: float | None = None
    notes: tuple[str, ...] = field(default_factory=tuple)
    attached: tuple[tuple[float, float, float], ...] = ()
    ground: str = ""
    fallback: str = ""
    dense: MotionField | None = field(default=None, compare=False, repr=False)

    def __post_init__(self) -> None:
        vx, vy = (float(v) for v in self.velocity)
        if not (math.isfinite(vx) and math.isfinite(vy)):
            raise InvalidParameterError(f"velocity: expected finite px/s, got {self.velocity!r}")
        object.__setattr__(self, "velocity", (vx, vy))
        if self.regime not in REGIMES:
            raise InvalidParameterError(
                f"regime: expected one of {', '.join(REGIMES)}, got {self.regime!r}"
            )
        if not 0.0 <= self.confidence <= 1.0:
            raise InvalidParameterError(
                f"confidence: expected a number in [0, 1], got {self.confidence!r}"
            )

    @property
    def speed(self) -> float:
        """Speed in pixels per second."""
        return math.hypot(*self.velocity)

    @property
    def reliable(self) -> bool:
        """Whether the confidence reaches :data:`LOW_CONFIDENCE`."""
        return self.confidence >= LOW_CONFIDENCE

    def displacement(self, dt_s: float) -> tuple[float, float]:
        """Pixels the plume material moves in ``dt_s`` seconds (0 in calm air).

        Parameters
        ----------
        dt_s : float
            Seconds.

        Returns
        -------
        tuple of float
            ``(dx, dy)``, pixels.
        """
        if self.regime == "calm":
            return 0.0, 0.0
        return self.velocity[0] * dt_s, self.velocity[1] * dt_s

    def summary(self) -> str:
        """One line for logs: regime, velocity, confidence, method.

        Returns
        -------
        str
            The line.
        """
        vx, vy = self.velocity
        s = (
            f"{self.regime} plume, velocity ({vx:+.3f}, {vy:+.3f}) px/s "
            f"({self.speed:.3f} px/s), confidence {self.confidence:.2f} [{self.source}: {self.method}]"
        )
        if self.vent is not None:
            s += f", vent at ({self.vent[0]:.1f}, {self.vent[1]:.1f})"
        return s + "".join(f"; {n}" for n in self.notes)

    def to_dict(self) -> dict:
        """A JSON-ready dictionary of the estimate.

        Returns
        -------
        dict
            Velocity, speed, regime, confidence, reliability, source, method, vent,
            shifts, interval, notes and attached plumes (lengths in px, times in s).
        """
        return {
            "velocity_px_s": list(self.velocity),
            "speed_px_s": self.speed,
            "regime": self.regime,
            "confidence": self.confidence,
            "reliable": self.reliable,
            "source": self.source,
            "method": self.method,
            "vent": None if self.vent is None else list(self.vent),
            "ground_shift_px": list(self.ground_shift),
            "upwind_shift_px": self.upwind_shift,
            "downwind_shift_px": self.downwind_shift,
            "interval_s": self.interval_s,
            "notes": list(self.notes),
            "attached": [list(a) for a in self.attached],
            "ground": self.ground,
            "fallback": self.fallback,
            "dense_field": None
            if self.dense is None
            else {"cells": list(self.dense.velocity.shape[:2]), "px_per_cell": self.dense.scale},
        }


CALM = Motion((0.0, 0.0), regime="calm", confidence=1.0, source="wind-prior", method="calm")
"""No motion at all."""


def _check_mask(mask: object, shape: tuple[int, int], name: str) -> np.ndarray:
    arr = np.asarray(mask)
    if arr.shape != tuple(shape):
        raise InvalidSceneError(f"{name}: shape {arr.shape} does not match the image's {shape}")
    if arr.dtype == bool:
        return arr
    if np.issubdtype(arr.dtype, np.integer):
        return arr != 0
    raise InvalidSceneError(f"{name}: expected a boolean or integer mask, got dtype {arr.dtype}")


def _check_frame(image: object, name: str) -> np.ndarray:
    arr = np.asarray(image)
    if arr.ndim != 3 or arr.shape[0] != 4 or arr.shape[1] < 8 or arr.shape[2] < 8:
        raise InvalidSceneError(
            f"{name}: expected a 4-band image (4, H, W) of at least 8 x 8 px, got shape {arr.shape}"
        )
    if not np.issubdtype(arr.dtype, np.floating):
        raise InvalidSceneError(f"{name}: expected floating-point reflectance, got {arr.dtype}")
    if not np.isfinite(arr).all():
        raise InvalidSceneError(f"{name}: {int((~np.isfinite(arr)).sum())} NaN or infinite values")
    return arr.astype(np.float32, copy=False)


def check_interval(interval_s: object) -> float:
    """Validate the time between two looks (seconds, finite, > 0).

    Parameters
    ----------
    interval_s : object
        The interval, anything ``float()`` accepts.

    Returns
    -------
    float
        The interval, seconds.

    Raises
    ------
    dyntarget.errors.InvalidParameterError
        When it is not a finite number > 0.

    Examples
    --------
    >>> check_interval(5)
    5.0
    """
    try:
        v = float(interval_s)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        v = math.nan
    if not (math.isfinite(v) and v > 0):
        raise InvalidParameterError(f"interval_s: expected seconds > 0, got {interval_s!r}")
    return v


def brightness(image: np.ndarray) -> np.ndarray:
    """The band used for motion: the mean of R, G, B and NIR, ``float32 (H, W)``.

    Parameters
    ----------
    image : numpy.ndarray
        ``(4, H, W)`` image.

    Returns
    -------
    numpy.ndarray
        ``float32 (H, W)`` mean over the bands.

    Examples
    --------
    >>> float(brightness(np.ones((4, 2, 2), np.float32))[0, 0])
    1.0
    """
    return np.asarray(image, np.float32).mean(axis=0)


def _to_u8(a: np.ndarray, lo: float, hi: float) -> np.ndarray:
    scale = 255.0 / max(hi - lo, 1e-6)
    return np.clip((a - lo) * scale, 0, 255).astype(np.uint8)


AFFINE_GAIN_PX = 0.1
"""The affine base must lower the votes' median residual by more than this (full-grid px)."""
RESIDUAL_MIN_PX = 0.75
"""Votes departing from the base motion (mode or affine) by less than this (median, full-grid
px) are the flow's noise: the field is the base alone (a rigid drift stays rigid)."""
MOVING_GROUND_WEIGHT = 1.0
"""Moving ground: weight of a background vote in the dense field (a plume vote weighs 1)."""
MOVING_ALL_VOTES = 200
"""Moving ground: with fewer plume votes (full-grid px) than this the background votes too."""
FARNEBACK_WINDOW = 9
"""Farneback's Gaussian averaging window (px of the flow grid)."""
FLOWS = {"dis": "DIS", "farneback": "Farneback", "lk": "pysteps Lucas-Kanade"}
VOTE_INSET = FARNEBACK_WINDOW // 2
"""Votes come from at least this many pixels (flow grid) inside the plume's edge: half the
flow's window, so the window holds the plume's texture alone (measured on the real 38-Cloud
layer drifting 0.8 px between looks: the 1 px inset read 8 % too fast, 4 px 3.7 %)."""
MIN_INTERIOR_SHARE = 0.2
"""The deep interior is used when it keeps at least this share of the mask's pixels."""


def dense_flow(a: np.ndarray, b: np.ndarray, flow: str = "farneback") -> np.ndarray:
    """Dense optical flow from 8-bit image ``a`` to ``b``, ``float32 (H, W, 2)`` in px.

    Parameters
    ----------
    a, b : numpy.ndarray
        ``uint8 (H, W)`` images, first and second.
    flow : {"farneback", "dis"}
        The OpenCV optical flow method.

    Returns
    -------
    numpy.ndarray
        ``float32 (H, W, 2)`` displacement ``(dx, dy)`` per pixel of ``a``, pixels.

    Raises
    ------
    dyntarget.errors.InvalidParameterError
        For an unknown ``flow``.

    Examples
    --------
    >>> dense_flow(np.zeros((16, 16), np.uint8), np.zeros((16, 16), np.uint8)).shape
    (16, 16, 2)
    """
    if flow == "dis":
        dis = cv2.DISOpticalFlow.create(cv2.DISOPTICAL_FLOW_PRESET_MEDIUM)
        return np.asarray(dis.calc(a, b, None))  # type: ignore[call-overload]  # None: a new field
    if flow == "farneback":  # Gaussian 9 px window, 5 iterations: the most accurate we measured
        return cv2.calcOpticalFlowFarneback(
            a, b, None, 0.5, 4, FARNEBACK_WINDOW, 5, 5, 1.1, cv2.OPTFLOW_FARNEBACK_GAUSSIAN
        )
    raise InvalidParameterError(f"flow: expected one of {', '.join(FLOWS)}, got {flow!r}")


def _span(lo: int, hi: int, n: int) -> tuple[int, int]:
    """``[lo, hi)`` widened by :data:`CROP_MARGIN` and to at least :data:`MIN_CROP` px, within ``[0, n)``."""
    lo, hi = lo - CROP_MARGIN, hi + CROP_MARGIN
    if hi - lo < MIN_CROP:
        grow = MIN_CROP - (hi - lo)
        lo, hi = lo - grow // 2, hi + grow - grow // 2
    if lo < 0:
        lo, hi = 0, hi - lo
    if hi > n:
        lo, hi = max(lo - (hi - n), 0), n
    return lo, hi


def _ground_shift(bp: np.ndarray, bc: np.ndarray, plume: np.ndarray) -> tuple[float, float, bool]:
    """How far the fixed ground moved between the looks: phase correlation (OpenCV) of the
    brightness with the plume's neighbourhood filled by the ground's mean; ``ok`` False
    when the correlation peak is too weak to trust (e.g. a featureless sea)."""
    ground = ~plume
    if ground.sum() < 256:
        return 0.0, 0.0, False
    a, b = bp.copy(), bc.copy()
    a[plume], b[plume] = float(bp[ground].mean()), float(bc[ground].mean())
    window = cv2.createHanningWindow(a.shape[::-1], cv2.CV_32F)
    (dx, dy), response = cv2.phaseCorrelate(a.astype(np.float32), b.astype(np.float32), window)
    if response < MIN_REGISTRATION_RESPONSE:
        return 0.0, 0.0, False
    return _snap_still(dx), _snap_still(dy), True


def _snap_still(v: float) -> float:
    """Sub-tenth-pixel registration offsets are noise: 0."""
    return 0.0 if abs(v) < 0.1 else float(v)


def _mode(x: np.ndarray, y: np.ndarray, bin_px: float = 0.1, sigma_bins: float = 2.0):
    """The densest displacement of the votes (smoothed 2-D histogram peak, refined by the
    mean of the votes within 0.6 px). Over semi-transparent plume parts the flow mixes the
    still ground into the plume's motion; the mode keeps to the plume's own motion where
    a median is pulled towards zero."""
    r = float(max(np.abs(x).max(), np.abs(y).max())) + 1.0
    n = int(2 * r / bin_px) + 1
    hist, xe, ye = np.histogram2d(x, y, bins=n, range=[[-r, r], [-r, r]])
    hist = cv2.GaussianBlur(hist.astype(np.float32), (0, 0), sigma_bins)
    i, j = np.unravel_index(int(np.argmax(hist)), hist.shape)
    px, py = (xe[i] + xe[i + 1]) / 2, (ye[j] + ye[j + 1]) / 2
    near = np.hypot(x - px, y - py) < 3 * bin_px * sigma_bins
    return float(x[near].mean()), float(y[near].mean())


def _edges(mask: np.ndarray, u: np.ndarray) -> tuple[float, float]:
    ys, xs = np.nonzero(mask)
    s = xs * u[0] + ys * u[1]
    return float(np.percentile(s, 1)), float(np.percentile(s, 99))


def _vent(mask: np.ndarray, u: np.ndarray) -> tuple[float, float]:
    """Mean position of the mask pixels within 1.5 px of the upwind edge."""
    ys, xs = np.nonzero(mask)
    s = xs * u[0] + ys * u[1]
    near = s <= np.percentile(s, 1) + 1.5
    return float(xs[near].mean()), float(ys[near].mean())


def _interior(mask: np.ndarray, trackable: np.ndarray, f: int) -> np.ndarray:
    """The mask's pixels whose flow is the plume's own: at least :data:`VOTE_INSET` px (of
    the flow grid) inside its edge, where Farneback's window no longer straddles the edge
    (whose motion is the mask's, rounded to whole pixels, or the still ground's). Thin or
    texture-poor plumes (a deep interior under :data:`MIN_INTERIOR_SHARE` of the mask, or
    with fewer than 200 full-grid px of trackable votes) keep the 1 px inset, then the mask."""
    u8 = mask.astype(np.uint8)
    k = 2 * VOTE_INSET + 1
    deep = cv2.erode(u8, np.ones((k, k), np.uint8)) > 0
    if (
        int(deep.sum()) >= MIN_INTERIOR_SHARE * int(mask.sum())
        and int((deep & trackable).sum()) * f * f >= 200
    ):
        return deep
    inner = cv2.erode(u8, np.ones((3, 3), np.uint8)) > 0
    return inner if inner.any() else mask


def _downsample(a: np.ndarray, f: int) -> np.ndarray:
    if f == 1:
        return a
    h, w = a.shape[0] // f * f, a.shape[1] // f * f
    return cv2.resize(a[:h, :w], (w // f, h // f), interpolation=cv2.INTER_AREA)


def _mask_down(m: np.ndarray, f: int) -> np.ndarray:
    return m if f == 1 else _downsample(m.astype(np.float32), f) >= 0.5


def _normalized(weights: np.ndarray, values: np.ndarray, prior: np.ndarray, sigma: float):
    """Gaussian normalised convolution of the votes, tending to ``prior`` where none is near."""
    k = (0, 0)
    w = cv2.GaussianBlur(weights, k, sigma, borderType=cv2.BORDER_REFLECT)
    out = np.empty((*weights.shape, 2), np.float32)
    for c in range(2):
        num = cv2.GaussianBlur(weights * values[..., c], k, sigma, borderType=cv2.BORDER_REFLECT)
        out[..., c] = (num + FIELD_PRIOR * prior[c]) / (w + FIELD_PRIOR)
    return out


def _robust_field(weights: np.ndarray, rel: np.ndarray, mode: tuple[float, float]) -> np.ndarray:
    """The dense displacement field (cells of the flow grid, full-grid px) from the votes.

    A base motion, then local departures from it. The base is a robust affine fit of
    the votes (least squares on the 60 % closest, four rounds) when it explains them
    clearly better than the one mode (median residual below 0.7 of the mode's, and
    smaller by more than :data:`AFFINE_GAIN_PX`: rotation, shear, convergence), else
    the mode. The departures: the votes' residuals
    from the base, outliers dropped (over twice the median residual and 0.5 px: mixed
    semi-transparent edges), averaged over :data:`FIELD_SIGMA` cells (normalised
    convolution), fading to the base where no vote is near; none when their median is
    under :data:`RESIDUAL_MIN_PX` (noise).
    """
    votes = weights > 0
    h, w = votes.shape
    ys, xs = np.nonzero(votes)
    vx, vy = rel[..., 0][votes].astype(np.float64), rel[..., 1][votes].astype(np.float64)
    cx, cy = w / 2.0, h / 2.0
    step = max(1, len(xs) // 5000)
    X = np.stack([xs[::step] - cx, ys[::step] - cy, np.ones(len(xs[::step]))], axis=1)
    tx, ty = vx[::step], vy[::step]
    res_mode = np.hypot(tx - mode[0], ty - mode[1])
    res = res_mode
    keep = res_mode <= np.percentile(res_mode, 60)
    ax, ay = np.zeros(3), np.zeros(3)
    for _ in range(4):
        if keep.sum() < 10:
            break
        ax = np.linalg.lstsq(X[keep], tx[keep], rcond=None)[0]
        ay = np.linalg.lstsq(X[keep], ty[keep], rcond=None)[0]
        res = np.hypot(tx - X @ ax, ty - X @ ay)
        keep = res <= np.percentile(res, 60)
    gy, gx = np.mgrid[0:h, 0:w].astype(np.float32)
    base = np.empty((h, w, 2), np.float32)
    gain = float(np.median(res_mode) - np.median(res))
    if keep.sum() >= 10 and np.median(res) < 0.7 * np.median(res_mode) and gain > AFFINE_GAIN_PX:
        base[..., 0] = (gx - cx) * ax[0] + (gy - cy) * ax[1] + ax[2]
        base[..., 1] = (gx - cx) * ay[0] + (gy - cy) * ay[1] + ay[2]
    else:
        base[..., 0], base[..., 1] = mode
    resid = rel - base
    rmag = np.hypot(resid[..., 0], resid[..., 1])
    typical = float(np.median(rmag[votes]))
    if typical < RESIDUAL_MIN_PX:
        return base  # the base explains the votes to within the flow's noise: keep it exact
    good = votes & (rmag <= max(0.5, 2.0 * typical))
    return base + _normalized(
        np.where(good, weights, 0.0).astype(np.float32), resid, np.zeros(2, np.float32), FIELD_SIGMA
    )


def lucas_kanade(stack: np.ndarray, *, needs: str) -> np.ndarray:
    """pysteps' Lucas-Kanade motion field of an image sequence (the one wrapper of it).

    Parameters
    ----------
    stack : numpy.ndarray
        ``(T, H, W)`` images, oldest first, ``T >= 2``, in time steps of one interval.
    needs : str
        What to tell the user when pysteps is missing (``dyntarget: error: NEEDS``),
        e.g. ``"flow: 'lk' needs pysteps (pip install 'dyntarget[nowcast]')"``.

    Returns
    -------
    numpy.ndarray
        ``(2, H, W)`` float64 ``(u, v)`` pixels per interval (``u`` along columns, ``v``
        along rows), 0 where pysteps found none.

    Raises
    ------
    dyntarget.errors.InvalidParameterError
        When pysteps is not installed.

    Examples
    --------
    >>> y, x = np.mgrid[0:32, 0:64]
    >>> blob = lambda c: np.exp(-((x - c) ** 2 + (y - 16) ** 2) / 8.0)
    >>> v = lucas_kanade(np.stack([blob(20), blob(22)]), needs="pysteps")  # a blob 2 px east
    >>> round(float(v[0, 16, 21]))
    2
    """
    import contextlib
    import io
    import warnings

    try:
        with contextlib.redirect_stdout(io.StringIO()), warnings.catch_warnings():
            warnings.simplefilter("ignore")  # pysteps announces its config file, warns on import
            from pysteps import motion
    except ImportError:
        raise InvalidParameterError(needs) from None
    with warnings.catch_warnings():  # statistics of empty feature sets, and a UserWarning
        warnings.simplefilter("ignore")  # when its outlier detection finds too few vectors
        v = motion.get_method("LK")(stack, verbose=False)
    return np.nan_to_num(np.asarray(v, np.float64))


def _pysteps_lk(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    stack = np.stack([a, b]).astype(np.float64) / 255.0
    v = lucas_kanade(stack, needs="flow: 'lk' needs pysteps (pip install 'dyntarget[nowcast]')")
    return np.moveaxis(v, 0, -1).astype(np.float32)


def estimate_motion(
    previous: np.ndarray,
    current: np.ndarray,
    interval_s: float,
    *,
    previous_mask: np.ndarray,
    current_mask: np.ndarray,
    flow: str = "farneback",
    ground: str = "auto",
    field: str = "dense",
) -> Motion:
    """Estimate the plumes' motion between two looks on the same grid.

    Parameters
    ----------
    previous, current : float32 (4, H, W)
        The earlier and the later look-ahead frame (R, G, B, NIR).
    interval_s : float
        Seconds from ``previous`` to ``current`` (> 0).
    previous_mask, current_mask : bool (H, W)
        The plume in each frame (hand label or classifier output).
    flow : str
        Dense optical flow: ``"farneback"`` (OpenCV Farneback, default), ``"dis"``
        (OpenCV DIS) or ``"lk"`` (pysteps' Lucas-Kanade, interpolated to a dense
        field; needs the ``nowcast`` extra); ``benchmarks/motion_methods.py`` and
        ``benchmarks/motion_real.py`` compare them.
    ground : {"auto", "fixed", "moving"}
        ``"fixed"``: the background outside the plumes is the ground; its apparent
        shift is misregistration and is removed from the plumes' motion.
        ``"moving"``: the background moves itself (weather, radar, a plume over
        moving cloud); nothing is removed. ``"auto"`` (default) decides from the
        frames (moving when the background's shift exceeds
        :data:`MAX_MISREGISTRATION_PX` or is not one rigid shift) and says so in
        ``Motion.ground`` and the notes. A moving background's flow runs on the finer
        :data:`FLOW_MAX_PX_MOVING` grid.
    field : {"dense", "uniform"}
        ``"dense"`` (default): each plume pixel moves by the dense motion field
        (``Motion.dense``), ``"uniform"``: every detached plume moves by the one
        ``velocity``.

    Returns
    -------
    Motion
        Velocity (the mode of the plume's flow votes) relative to the ground in
        px/s of the current grid, the dense field, the regime seen, the vents
        (attached plumes), edge displacements and a confidence. Below
        :data:`LOW_CONFIDENCE` the motion is not used: the result is calm with
        ``fallback="persistence"`` (the mask is not moved) and the notes say why.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> import cv2
    >>> tex = cv2.GaussianBlur(rng.random((96, 96)).astype(np.float32), (0, 0), 2)
    >>> ground = np.repeat(0.1 + 0.1 * tex[None], 4, 0)
    >>> def frame(x0):
    ...     img, m = ground.copy(), np.zeros((96, 96), bool)
    ...     m[30:60, x0:x0 + 30] = True
    ...     img[:, m] = 0.6 + 0.6 * np.roll(tex, x0 - 20, axis=1)[m]
    ...     return img, m
    >>> (a, ma), (b, mb) = frame(20), frame(24)
    >>> m = estimate_motion(a, b, 2.0, previous_mask=ma, current_mask=mb)
    >>> m.regime, round(m.velocity[0], 1), abs(round(m.velocity[1], 1)), m.ground
    ('detached', 2.0, 0.0, 'fixed')
    """
    prev = _check_frame(previous, "previous")
    cur = _check_frame(current, "current")
    if prev.shape != cur.shape:
        raise InvalidSceneError(
            f"previous: shape {prev.shape} does not match the current frame's {cur.shape}"
        )
    dt = check_interval(interval_s)
    if flow not in FLOWS:
        raise InvalidParameterError(f"flow: expected one of {', '.join(FLOWS)}, got {flow!r}")
    if ground not in GROUNDS:
        raise InvalidParameterError(f"ground: expected one of {', '.join(GROUNDS)}, got {ground!r}")
    if field not in MOTION_FIELDS:
        raise InvalidParameterError(
            f"field: expected one of {', '.join(MOTION_FIELDS)}, got {field!r}"
        )
    shape = cur.shape[1:]
    h, w = shape
    pm = _check_mask(previous_mask, shape, "previous_mask")
    cm = _check_mask(current_mask, shape, "current_mask")
    if not pm.any() or not cm.any():
        return Motion(
            (0.0, 0.0),
            regime="calm",
            confidence=0.0,
            source="two-looks",
            method="no plume in one of the looks",
            interval_s=dt,
            notes=("no plume in the previous or current mask: no motion estimated",),
        )

    wf, (gdx, gdy), decided, notes, ground_votes = _flow_and_ground(prev, cur, pm, cm, flow, ground)
    rel = wf.fwd_px - np.array([gdx, gdy], np.float32)
    votes = wf.votes
    if decided == "moving" and int(votes.sum()) * wf.f * wf.f < MOVING_ALL_VOTES:
        votes = votes | ground_votes  # few plume votes: the moving background is the same weather
    weights = votes.astype(np.float32)
    if decided == "moving":
        # the background is the same weather: every trackable pixel around votes too
        weights[wf.trackable & ~votes] = MOVING_GROUND_WEIGHT
    n_votes = int(votes.sum())
    texture_share = n_votes / max(int(wf.inner.sum()), 1)
    (mx, my), agreement, calm, vfield = _vote(rel, votes, weights)
    dense = None
    if vfield is not None and field == "dense":
        dense = MotionField(vfield / np.float32(dt), (wf.x0, wf.y0), wf.f, (h, w))
    f, pm_c, cm_c, x0, y0 = wf.f, wf.pm_c, wf.cm_c, wf.x0, wf.y0
    vx, vy = mx / dt, my / dt
    confidence = (
        min(1.0, texture_share / TEXTURE_SATURATION)
        * agreement
        * min(1.0, n_votes * f * f / 200.0)  # a coarse vote stands for f x f pixels
    )
    confidence = float(np.clip(confidence, 0.0, 1.0))
    method = f"{FLOWS[flow]} flow" + (f", dense field (1/{f} grid)" if dense is not None else "")
    if confidence < LOW_CONFIDENCE:
        # the flow is not trusted: not moving the mask is never worse than a wrong move
        notes.append(
            f"LOW CONFIDENCE {confidence:.2f} < {LOW_CONFIDENCE}: fallback to persistence "
            f"(the mask is not moved; flow said ({vx:+.3f}, {vy:+.3f}) px/s, "
            f"{100 * texture_share:.0f} % of the plume textured, {n_votes} votes)"
        )
        return Motion(
            (0.0, 0.0), regime="calm", confidence=confidence, source="two-looks",
            method=f"persistence ({FLOWS[flow]} flow unreliable)", ground_shift=(gdx, gdy),
            interval_s=dt, notes=tuple(notes), ground=decided, fallback="persistence",
        )  # fmt: skip

    if calm:
        return Motion(
            (0.0, 0.0), regime="calm", confidence=confidence, source="two-looks",
            method=method, ground_shift=(gdx, gdy), upwind_shift=0.0, downwind_shift=0.0,
            interval_s=dt, notes=tuple(notes), ground=decided,
        )  # fmt: skip
    u = np.array([vx, vy]) / math.hypot(vx, vy)
    up0, down0 = _edges(pm_c, u)  # on the window: the shifts are differences
    up1, down1 = _edges(cm_c, u)
    along = math.hypot(vx, vy) * dt
    up_shift, down_shift = up1 - up0, down1 - down0
    if along < 1.0:
        notes.append(f"the plume moved only {along:.2f} px between the looks: regime uncertain")
    if ground == "auto" and decided == "moving":
        # a vent is held by the ground: over a background found moving (weather) a plume's
        # still upwind end is growth, not a vent; every plume is carried (ground="moving"
        # given explicitly keeps the regimes: a plume over moving cloud)
        parts: list = [None]
    else:
        parts = _component_regimes(pm_c, cm_c, (vx * dt, vy * dt), dense, dt, (x0, y0), (h, w))
    attached = tuple(a for a in parts if a is not None)
    n_detached = sum(a is None for a in parts)
    if attached and n_detached:
        regime = "mixed"
    elif attached:
        regime = "attached"
    else:
        regime = "detached"
    return Motion(
        (vx, vy),
        regime=regime,
        confidence=confidence,
        source="two-looks",
        method=method,
        vent=attached[0][:2] if attached else None,
        ground_shift=(gdx, gdy),
        upwind_shift=up_shift,
        downwind_shift=down_shift,
        interval_s=dt,
        notes=tuple(notes),
        attached=attached,
        ground=decided,
        dense=dense,
    )


@dataclass(frozen=True, eq=False)
class _WindowFlow:
    """The dense flow over the plumes' window (plus a margin), on the flow grid."""

    x0: int
    y0: int
    x1: int
    y1: int
    f: int
    """Full-grid pixels per flow-grid cell."""
    pm_c: np.ndarray
    """The masks on the window, full resolution."""
    cm_c: np.ndarray
    pmf: np.ndarray
    """The masks on the flow grid."""
    cmf: np.ndarray
    fwd_px: np.ndarray
    """Flow previous -> current, full-grid pixels, per flow-grid cell."""
    textured: np.ndarray
    trackable: np.ndarray
    """Textured and forward-backward consistent cells."""
    inner: np.ndarray
    """The previous mask's interior (:func:`_interior`)."""

    @property
    def votes(self) -> np.ndarray:
        """The plume's own votes: trackable cells of the interior."""
        return self.inner & self.trackable

    def mode(self, where: np.ndarray) -> tuple[float, float]:
        """The densest displacement (:func:`_mode`) of the cells ``where``."""
        return _mode(self.fwd_px[..., 0][where], self.fwd_px[..., 1][where])


def _window_flow(prev, cur, pm, cm, flow: str, max_px: int = FLOW_MAX_PX) -> _WindowFlow:
    """Steps 1-2 of :func:`estimate_motion`: the window, the shared 8-bit scale, the
    downsampling (to at most ``max_px`` a side), the flow both ways and which cells can
    be trusted."""
    ys, xs = np.nonzero(pm | cm)
    h, w = pm.shape
    y0, y1 = _span(int(ys.min()), int(ys.max()) + 1, h)
    x0, x1 = _span(int(xs.min()), int(xs.max()) + 1, w)
    bp, bc = brightness(prev[:, y0:y1, x0:x1]), brightness(cur[:, y0:y1, x0:x1])
    sample = np.concatenate([bp.ravel()[::7], bc.ravel()[::7]])
    lo, hi = np.percentile(sample, [1, 99])
    # the plumes keep their texture when they are brighter than 99 % of the scene (a
    # few bright cells in a dark radar frame): the scale reaches the plumes' own top
    pm_c, cm_c = pm[y0:y1, x0:x1], cm[y0:y1, x0:x1]
    hi = max(hi, float(np.percentile(np.concatenate([bp[pm_c], bc[cm_c]]), 99.5)))
    f = max(1, math.ceil(max(y1 - y0, x1 - x0) / max_px))
    pmf, cmf = _mask_down(pm_c, f), _mask_down(cm_c, f)
    if f > 1 and (pmf.sum() < 50 or cmf.sum() < 50):
        f, pmf, cmf = 1, pm_c, cm_c  # plumes too small to see on the coarse grid
    p8 = _to_u8(_downsample(bp, f), lo, hi)
    c8 = _to_u8(_downsample(bc, f), lo, hi)
    if flow == "lk":
        fwd = _pysteps_lk(p8, c8)
        consistent = np.ones(p8.shape, bool)
    else:
        fwd, bwd = dense_flow(p8, c8, flow), dense_flow(c8, p8, flow)
        gy, gx = np.mgrid[0 : p8.shape[0], 0 : p8.shape[1]].astype(np.float32)
        back_at = cv2.remap(
            bwd, gx + fwd[..., 0], gy + fwd[..., 1], cv2.INTER_LINEAR,
            borderMode=cv2.BORDER_REPLICATE,
        )  # fmt: skip
        fb_err = np.hypot(fwd[..., 0] + back_at[..., 0], fwd[..., 1] + back_at[..., 1])
        consistent = fb_err < np.maximum(1.0, 0.1 * np.hypot(fwd[..., 0], fwd[..., 1]))
    # texture that pins the flow down in both directions (not just an edge): the smaller
    # eigenvalue of the local structure tensor (Shi-Tomasi), in 8-bit units of the scaled band
    textured = cv2.cornerMinEigenVal(p8.astype(np.float32), 5, ksize=3) > MIN_EIGEN
    return _WindowFlow(
        x0, y0, x1, y1, f, pm_c, cm_c, pmf, cmf, fwd * f, textured,
        textured & consistent, _interior(pmf, textured & consistent, f),
    )  # fmt: skip


def _flow_and_ground(prev, cur, pm, cm, flow: str, ground: str):
    """Steps 1-3: ``(window flow, ground shift removed, "fixed" or "moving", notes, the
    background's votes)``. A background found moving gets its flow again on the finer
    :data:`FLOW_MAX_PX_MOVING` grid (given ``"moving"``, that grid from the start)."""
    wf = _window_flow(
        prev, cur, pm, cm, flow, FLOW_MAX_PX_MOVING if ground == "moving" else FLOW_MAX_PX
    )
    # the plumes' raw displacement (ground not removed) sets how far from the masks the
    # background is safe from the plumes' own flow (occluded and uncovered ground)
    raw = wf.mode(wf.votes) if wf.votes.any() else (0.0, 0.0)
    gdx, gdy, ground_ok, rigid, ground_votes = _background(wf, prev, cur, raw)
    decided, notes = _decide_ground(ground, (gdx, gdy), ground_ok, rigid, raw)
    if decided == "fixed":
        return wf, (gdx, gdy), decided, notes, ground_votes
    side = max(wf.x1 - wf.x0, wf.y1 - wf.y0)
    if ground == "auto" and math.ceil(side / FLOW_MAX_PX_MOVING) < wf.f:
        # the weather's own cells: the flow again on a finer grid
        wf = _window_flow(prev, cur, pm, cm, flow, FLOW_MAX_PX_MOVING)
        raw = wf.mode(wf.votes) if wf.votes.any() else (0.0, 0.0)
        ground_votes = _background(wf, prev, cur, raw)[4]
    return wf, (0.0, 0.0), decided, notes, ground_votes


def _background(wf: _WindowFlow, prev, cur, raw) -> tuple[float, float, bool, bool, np.ndarray]:
    """Step 3's measurement: the background's apparent shift ``(dx, dy)`` px, whether it
    could be measured, whether it is one rigid shift, and the background's votes.

    Over trackable ground farther from the plumes than they moved (the histogram mode);
    where the margin has too little, phase correlation of the whole frames."""
    r = 4 + math.ceil(math.hypot(*raw) / wf.f)
    kernel = np.ones((2 * r + 1,) * 2, np.uint8)
    near_plume = cv2.dilate((wf.pmf | wf.cmf).astype(np.uint8), kernel) > 0
    ground_votes = ~near_plume & wf.trackable
    if ground_votes.sum() >= 50:
        gdx, gdy = (_snap_still(v) for v in wf.mode(ground_votes))
        gx_all, gy_all = wf.fwd_px[..., 0][ground_votes], wf.fwd_px[..., 1][ground_votes]
        near_g = np.hypot(gx_all - gdx, gy_all - gdy) <= max(1.0, 0.2 * math.hypot(gdx, gdy))
        return gdx, gdy, True, float(near_g.mean()) >= 0.5, ground_votes
    near_full = np.zeros(prev.shape[1:], bool)
    size = (wf.x1 - wf.x0, wf.y1 - wf.y0)
    near_full[wf.y0 : wf.y1, wf.x0 : wf.x1] = (
        cv2.resize(near_plume.astype(np.uint8), size, interpolation=cv2.INTER_NEAREST) > 0
    )
    gdx, gdy, ok = _ground_shift(brightness(prev), brightness(cur), near_full)
    return gdx, gdy, ok, True, ground_votes


def _decide_ground(ground: str, shift, ground_ok: bool, rigid: bool, raw) -> tuple[str, list[str]]:
    """Step 3's decision: ``"fixed"`` or ``"moving"`` (``ground="auto"``: from the
    background's shift ``shift``), and the notes that say what was decided and why."""
    gdx, gdy = shift
    g_mag = math.hypot(gdx, gdy)
    if ground == "fixed":
        if not ground_ok:
            return ground, [
                "ground registration failed (no texture outside the plume): assumed aligned"
            ]
        if g_mag > STILL_PX:
            return ground, [
                f"ground moved by ({gdx:+.2f}, {gdy:+.2f}) px between the looks (removed)"
            ]
        return ground, []
    if ground == "moving":
        return ground, [
            f"ground moving: the background's shift ({gdx:+.2f}, {gdy:+.2f}) px is not removed"
        ]
    like_plume = g_mag > 2.0 and math.hypot(raw[0] - gdx, raw[1] - gdy) < 0.25 * g_mag
    decided = (
        "moving"
        if ground_ok and (g_mag > MAX_MISREGISTRATION_PX or not rigid or like_plume)
        else "fixed"
    )
    if not (g_mag > STILL_PX or decided == "moving"):
        return decided, ["ground auto -> fixed: the background is still"]
    why = (
        f"more than {MAX_MISREGISTRATION_PX:g} px"
        if g_mag > MAX_MISREGISTRATION_PX
        else "not one rigid shift"
        if not rigid
        else "as the plumes do"
    )
    return decided, [
        f"ground auto -> {decided}: the background moved by ({gdx:+.2f}, {gdy:+.2f}) px"
        + (f", {why}: not removed" if decided == "moving" else ": misregistration removed")
    ]


def _vote(rel: np.ndarray, votes: np.ndarray, weights: np.ndarray):
    """Steps 4-5: ``((mx, my), agreement, calm, field)`` from the votes' displacements
    ``rel`` (full-grid px between the looks, ground removed): the mode of the moving
    votes, how well the votes follow the dense field, whether the air is calm, and the
    dense displacement field (``None`` when calm or without votes)."""
    n_votes = int(votes.sum())
    if n_votes == 0:
        return (0.0, 0.0), 0.0, False, None
    rel_x, rel_y = rel[..., 0][votes], rel[..., 1][votes]
    mag = np.hypot(rel_x, rel_y)
    moving = mag > STILL_PX
    n_moving = int(moving.sum())
    if n_moving < CALM_FRACTION * n_votes:
        return (0.0, 0.0), 1.0 - n_moving / n_votes, True, None
    mx, my = _mode(rel_x[moving], rel_y[moving])
    # the dense field: the votes averaged over FIELD_SIGMA cells, tending to the mode far
    # from any vote; agreement: how well the votes follow it (rotation and shear are not
    # disagreement), relative to the displacement
    vfield = _robust_field(weights, rel, (mx, my))
    res = np.hypot(rel_x - vfield[..., 0][votes], rel_y - vfield[..., 1][votes])
    scale = max(float(np.median(mag)), 1.0)
    return (mx, my), max(0.0, 1.0 - float(np.median(res)) / scale), False, vfield


def _on_border(xs: np.ndarray, ys: np.ndarray, w: int, h: int) -> bool:
    return bool((xs == 0).any() or (ys == 0).any() or (xs == w - 1).any() or (ys == h - 1).any())


def _component_regimes(
    pm, cm, d, dense, dt, origin=(0, 0), full=None
) -> list[tuple[float, float, float] | None]:
    """Per plume of the current mask (largest first): ``None`` if it moved as a whole,
    else ``(vent x, vent y, front speed px/s)`` of an attached plume.

    Each current plume is carried back by its own displacement (the dense field's mean
    over it, else the scene's ``d``) and compared with the previous mask *inside that
    carried-back footprint* (dilated by 1 px), so a fragment beside a big cloud is
    compared with its own past, not with its neighbour's. Its upwind edge moving less
    than :data:`ATTACHED_UPWIND` of the displacement makes it attached, unless that end
    touches the image border (a cloud drifting in: no vent seen). Its front speed is how
    fast it grows along the flow: the area gained between the looks (against the whole
    previous plumes its footprint touches) over its mean width
    (area / length), per second; 0 for a mature plume whose far end fades as fast as it
    is fed, or lies beyond the image border; at most the flow speed. Work is done on
    each plume's bounding box (plus the displacement), so many fragments stay cheap.
    ``pm`` and ``cm`` may be a window of the image at ``origin`` ``(x0, y0)`` of an
    image of shape ``full``; positions returned are the image's.
    """
    n, labels, stats, cents = cv2.connectedComponentsWithStats(cm.astype(np.uint8), connectivity=8)
    _, prev_labels, prev_stats, _ = cv2.connectedComponentsWithStats(
        pm.astype(np.uint8), connectivity=8
    )
    ch, cw = cm.shape
    ox, oy = origin
    h, w = full if full is not None else cm.shape
    order = sorted(range(1, n), key=lambda i: -stats[i, cv2.CC_STAT_AREA])
    out: list[tuple[float, float, float] | None] = []
    for i in order:
        if stats[i, cv2.CC_STAT_AREA] < MIN_COMPONENT_PX:
            continue
        if dense is not None:
            v = dense.sample(
                np.array([cents[i][0] + ox], np.float32), np.array([cents[i][1] + oy], np.float32)
            )[0]
            di = (float(v[0]) * dt, float(v[1]) * dt)
        else:
            di = d
        along = math.hypot(*di)
        if along < 1.0:
            out.append(None)  # too little motion to tell a vent from a drift
            continue
        u = np.array(di) / along
        bx, by, bw, bh = (int(stats[i, k]) for k in range(4))
        pad = math.ceil(along) + 3
        wx0, wy0 = max(bx - pad, 0), max(by - pad, 0)
        wx1, wy1 = min(bx + bw + pad, cw), min(by + bh + pad, ch)
        comp = labels[wy0:wy1, wx0:wx1] == i
        back = np.array([[1, 0, -di[0]], [0, 1, -di[1]]], np.float32)
        moved = cv2.warpAffine(
            comp.astype(np.uint8), back, comp.shape[::-1], flags=cv2.INTER_NEAREST
        )
        carried = cv2.dilate(moved, np.ones((3, 3), np.uint8)) > 0
        prev = carried & pm[wy0:wy1, wx0:wx1]
        if prev.sum() < MIN_COMPONENT_PX:
            out.append(None)  # new since the previous look: nothing to compare; moves with the flow
            continue
        up0, _ = _edges(prev, u)
        up1, down1 = _edges(comp, u)
        cys, cxs = np.nonzero(comp)
        s = cxs * u[0] + cys * u[1]
        upwind = s <= up1 + 1.5
        if _on_border(cxs[upwind] + wx0 + ox, cys[upwind] + wy0 + oy, w, h):
            out.append(None)  # its upwind end is cut by the image border: no vent seen
            continue
        if up1 - up0 < ATTACHED_UPWIND * along:
            downwind = s >= down1 - 1.5
            # a far end beyond the image is not seen to advance: the part inside stays
            at_border = _on_border(cxs[downwind] + wx0 + ox, cys[downwind] + wy0 + oy, w, h)
            # the front's advance from the plume's growth: area gained / mean width (the
            # area over the length), steadier than the far end's flickering tip
            length = max(down1 - up1, 1.0)
            # growth against the whole previous plume(s) it came from (its footprint alone
            # misses the part that moved out of it, and would read as growth)
            ids = np.unique(prev_labels[wy0:wy1, wx0:wx1][prev])
            prev_area = int(prev_stats[ids[ids > 0], cv2.CC_STAT_AREA].sum())
            growth = (comp.sum() - prev_area) * length / comp.sum()
            front = 0.0 if at_border else float(np.clip(growth / dt, 0.0, along / dt))
            vx, vy = _vent(comp, u)
            out.append((vx + wx0 + ox, vy + wy0 + oy, front))
        else:
            out.append(None)
    return out


def _snap(v: float) -> float:
    """Round-off of the trigonometry (1e-16) to an exact 0."""
    return 0.0 if abs(v) < 1e-12 else float(v)


def wind_to_pixels(
    speed_mps: float,
    from_deg: float,
    *,
    transform: Affine | None = None,
    gsd_m: float | None = None,
) -> tuple[float, float]:
    """Convert a meteorological wind to a velocity in pixels per second.

    Parameters
    ----------
    speed_mps : float
        Wind speed, m/s (>= 0).
    from_deg : float
        Direction the wind blows *from*, degrees clockwise from north.
    transform : affine.Affine, optional
        The image's pixel -> projected-metres transform (any rotation); the
        velocity is mapped through its inverse linear part.
    gsd_m : float, optional
        Metres per pixel of a north-up image, used when ``transform`` is absent.

    Returns
    -------
    (vx, vy) : pixels per second, x = column, y = row.

    Examples
    --------
    >>> vx, vy = wind_to_pixels(10.0, 270.0, gsd_m=5.0)  # from the west: moves east
    >>> round(vx, 6), round(vy, 6)
    (2.0, 0.0)
    >>> vx, vy = wind_to_pixels(10.0, 0.0, transform=Affine(5, 0, 0, 0, -5, 0))
    >>> round(vx, 6), round(vy, 6)  # from the north: moves south, down the rows
    (0.0, 2.0)
    """
    speed = float(speed_mps)
    direction = float(from_deg)
    if not (math.isfinite(speed) and 0 <= speed <= 100):
        raise InvalidParameterError(
            f"wind_mps: expected a speed in [0, 100] m/s, got {speed_mps!r}"
        )
    if not math.isfinite(direction):
        raise InvalidParameterError(f"wind_from_deg: expected degrees, got {from_deg!r}")
    theta = math.radians(direction)
    east, north = -speed * math.sin(theta), -speed * math.cos(theta)  # where it blows to
    if transform is not None:
        a, b, d, e = transform.a, transform.b, transform.d, transform.e
        det = a * e - b * d
        if not math.isfinite(det) or abs(det) < 1e-12:
            raise InvalidParameterError(f"transform: not invertible ({transform!r})")
        vx = (e * east - b * north) / det
        vy = (-d * east + a * north) / det
        return _snap(vx), _snap(vy)
    if gsd_m is None:
        raise InvalidParameterError(
            "wind: the image has no georeference; give its ground sampling distance (gsd_m)"
        )
    g = float(gsd_m)
    if not (math.isfinite(g) and g > 0):
        raise InvalidParameterError(f"gsd_m: expected metres per pixel > 0, got {gsd_m!r}")
    return _snap(east / g), _snap(-north / g)


def wind_motion(
    speed_mps: float,
    from_deg: float,
    *,
    transform: Affine | None = None,
    gsd_m: float | None = None,
    regime: str = "detached",
) -> Motion:
    """A :class:`Motion` from a wind prior (one look).

    One look cannot tell an attached plume from a detached cloud; ``regime``
    defaults to ``"detached"``: the current mask moved downwind by the wind
    lies inside the true plume in both regimes (an attached plume also covers
    everything between its vent and its advected far end), so pointings placed
    on it hit plume either way, while an attached prediction of a detached
    cloud points at air it has left.

    Parameters
    ----------
    speed_mps : float
        Wind speed, m/s (0 gives a calm plume).
    from_deg : float
        Direction the wind blows *from*, degrees clockwise from north.
    transform : affine.Affine or None
        The image's pixel -> projected-metres transform.
    gsd_m : float or None
        Metres per pixel of a north-up image, used when ``transform`` is absent.
    regime : {"detached", "attached", "mixed", "calm"}
        The regime to assume.

    Returns
    -------
    Motion
        The velocity in pixels per second, from the wind prior.

    Examples
    --------
    >>> wind_motion(0.0, 90.0, gsd_m=10.0).regime
    'calm'
    """
    if regime not in REGIMES:
        raise InvalidParameterError(f"regime: expected one of {', '.join(REGIMES)}, got {regime!r}")
    vx, vy = wind_to_pixels(speed_mps, from_deg, transform=transform, gsd_m=gsd_m)
    if speed_mps == 0:
        regime = "calm"
    return Motion(
        (vx, vy),
        regime=regime,
        confidence=1.0,
        source="wind-prior",
        method=f"wind {float(speed_mps):g} m/s from {float(from_deg):g} deg",
    )


def check_against_prior(estimate: Motion, prior: Motion, *, tolerance: float = 0.5) -> Motion:
    """Compare a two-look estimate with a wind prior; note disagreement, fall back when unreliable.

    The estimate is kept when it is reliable; a note is added when its velocity
    differs from the prior's by more than ``tolerance`` times the prior's speed.
    An unreliable estimate is replaced by the prior (with its regime if the
    looks could tell one), and the note says so.

    Parameters
    ----------
    estimate : Motion
        The two-look estimate.
    prior : Motion
        The wind prior.
    tolerance : float
        Largest velocity difference, as a fraction of the prior's speed, that
        counts as agreement.

    Returns
    -------
    Motion
        The estimate with a note, or the prior when the estimate is unreliable.

    Examples
    --------
    >>> est = Motion((1.0, 0.0), source="two-looks", confidence=0.9)
    >>> check_against_prior(est, Motion((1.1, 0.0))).notes
    ('agrees with the wind prior within 50 %',)
    """
    diff = math.hypot(
        estimate.velocity[0] - prior.velocity[0], estimate.velocity[1] - prior.velocity[1]
    )
    ref = max(prior.speed, 1e-9)
    if not estimate.reliable:
        regime = estimate.regime if estimate.regime != "calm" else prior.regime
        if prior.regime == "calm":
            regime = "calm"
        return replace(
            prior,
            regime=regime,
            vent=estimate.vent if regime == "attached" else None,
            notes=(
                *estimate.notes,
                f"two-look estimate unreliable (confidence {estimate.confidence:.2f}): wind prior used",
            ),
        )
    if diff > tolerance * ref:
        note = (
            f"DISAGREES with the wind prior: differs by {diff:.3f} px/s "
            f"({100 * diff / ref:.0f} % of the prior's speed)"
        )
    else:
        note = f"agrees with the wind prior within {100 * tolerance:.0f} %"
    return replace(estimate, notes=(*estimate.notes, note))
