"""Plume motion from two looks (dense optical flow) or from a wind prior (one look).

Method (documented in ``docs/onboard.md``, "Predictive targeting"):

1. Both frames are reduced to one *brightness* band, the mean of R, G, B and
   NIR: plumes and clouds are bright in all four, averaging four bands halves
   the sensor noise, and no band is needed that a sensor preset may lack.
   Both are scaled to 8 bits with the *same* percentiles (1 and 99 % of the two
   frames together), so brightness constancy between looks survives.
2. OpenCV's DIS optical flow (``DISOpticalFlow``, preset MEDIUM) gives a dense
   flow previous -> current and current -> previous.
3. The fixed ground: the median forward flow over textured ground pixels (away
   from both plume masks) is the frames' misregistration; it is subtracted from
   the plume's flow (so frames need not be co-registered, only share a grid).
4. Plume pixels of the previous mask whose flow is forward-backward consistent
   (within 1 px) and which carry texture that pins the flow in both directions
   (Shi-Tomasi: smaller structure-tensor eigenvalue above ``MIN_EIGEN``) vote.
   Over semi-transparent plume edges the flow is a mixture of the ground (still)
   and the plume (moving), so the moving votes are separated from the still ones:
   if fewer than ``CALM_FRACTION`` of the votes move by more than ``STILL_PX``,
   the air is calm; otherwise the velocity is the median of the moving votes.
5. Upwind and downwind edges: the masks' pixels are projected on the flow
   direction; the 1st and 99th percentiles are the upwind and downwind edges,
   and their displacement between the looks tells the regimes apart: a
   *detached* cloud moves as a whole (its upwind edge moves like the flow), an
   *attached* plume keeps its vent end (upwind edge still) while puffs move.
6. Confidence in [0, 1]: the share of plume pixels that carry trackable texture
   (saturating at 30 %), times the agreement of the votes (1 - spread / abs(median)),
   times a count term (saturating at 200 votes). Below ``LOW_CONFIDENCE`` the
   flow is not trusted: the velocity falls back on the masks' centroid shift
   and ``Motion.method`` says so.
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
        How the velocity was obtained (e.g. ``"DIS flow"``).
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


FLOWS = {"dis": "DIS", "farneback": "Farneback"}


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
        dis = cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_MEDIUM)
        return dis.calc(a, b, None)
    if flow == "farneback":  # Gaussian 9 px window, 5 iterations: the most accurate we measured
        return cv2.calcOpticalFlowFarneback(
            a, b, None, 0.5, 4, 9, 5, 5, 1.1, cv2.OPTFLOW_FARNEBACK_GAUSSIAN
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


def estimate_motion(  # noqa: PLR0915  (next to split: flow, ground, regimes, confidence)
    previous: np.ndarray,
    current: np.ndarray,
    interval_s: float,
    *,
    previous_mask: np.ndarray,
    current_mask: np.ndarray,
    flow: str = "farneback",
) -> Motion:
    """Estimate the plume's motion between two looks on the same grid.

    Parameters
    ----------
    previous, current : float32 (4, H, W)
        The earlier and the later look-ahead frame (R, G, B, NIR).
    interval_s : float
        Seconds from ``previous`` to ``current`` (> 0).
    previous_mask, current_mask : bool (H, W)
        The plume in each frame (hand label or classifier output).
    flow : str
        Dense optical flow: ``"farneback"`` (OpenCV Farneback, default) or ``"dis"``
        (OpenCV DIS); ``benchmarks/motion_methods.py`` compares them (and pysteps).

    Returns
    -------
    Motion
        Velocity relative to the ground in px/s of the current grid, the regime
        seen, the vent (attached plumes), edge displacements and a confidence.

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
    >>> m.regime, round(m.velocity[0], 1), abs(round(m.velocity[1], 1))
    ('detached', 2.0, 0.0)
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
    shape = cur.shape[1:]
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

    bp, bc = brightness(prev), brightness(cur)
    lo, hi = np.percentile(np.concatenate([bp.ravel(), bc.ravel()]), [1, 99])
    near_plume = cv2.dilate((pm | cm).astype(np.uint8), np.ones((9, 9), np.uint8)) > 0

    # dense flow on the plume's bounding box (plus a margin): cost follows the plume, not the image
    ys, xs = np.nonzero(pm | cm)
    h, w = shape
    y0, y1 = _span(int(ys.min()), int(ys.max()) + 1, h)
    x0, x1 = _span(int(xs.min()), int(xs.max()) + 1, w)
    p8 = _to_u8(bp[y0:y1, x0:x1], lo, hi)
    c8 = _to_u8(bc[y0:y1, x0:x1], lo, hi)
    fwd, bwd = dense_flow(p8, c8, flow), dense_flow(c8, p8, flow)
    gy, gx = np.mgrid[0 : y1 - y0, 0 : x1 - x0].astype(np.float32)
    back_at = cv2.remap(
        bwd, gx + fwd[..., 0], gy + fwd[..., 1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE
    )
    fb_err = np.hypot(fwd[..., 0] + back_at[..., 0], fwd[..., 1] + back_at[..., 1])
    consistent = fb_err < 1.0
    # texture that pins the flow down in both directions (not just an edge): the smaller
    # eigenvalue of the local structure tensor (Shi-Tomasi), in 8-bit units of the scaled band
    textured = cv2.cornerMinEigenVal(p8.astype(np.float32), 5, 3) > MIN_EIGEN

    # the fixed ground's apparent motion (misregistration): the flow over textured ground
    # around the plume; where the margin has too little, phase correlation of the frames
    ground_votes = ~near_plume[y0:y1, x0:x1] & textured & consistent
    if ground_votes.sum() >= 50:
        gdx = _snap_still(float(np.median(fwd[..., 0][ground_votes])))
        gdy = _snap_still(float(np.median(fwd[..., 1][ground_votes])))
        ground_ok = True
    else:
        gdx, gdy, ground_ok = _ground_shift(bp, bc, near_plume)

    pm_c = pm[y0:y1, x0:x1]
    inner = cv2.erode(pm_c.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
    if not inner.any():
        inner = pm_c
    votes = inner & textured & consistent
    n_votes = int(votes.sum())
    rel_x = fwd[..., 0][votes] - gdx
    rel_y = fwd[..., 1][votes] - gdy
    mag = np.hypot(rel_x, rel_y)
    moving = mag > STILL_PX
    n_moving = int(moving.sum())
    texture_share = n_votes / max(int(inner.sum()), 1)
    notes: list[str] = []
    if not ground_ok:
        notes.append("ground registration failed (no texture outside the plume): assumed aligned")
    elif abs(gdx) > STILL_PX or abs(gdy) > STILL_PX:
        notes.append(f"ground moved by ({gdx:+.2f}, {gdy:+.2f}) px between the looks (removed)")

    calm = n_votes > 0 and n_moving < CALM_FRACTION * n_votes
    if n_votes == 0:
        vx = vy = 0.0
        agreement = 0.0
    elif calm:
        vx = vy = 0.0
        agreement = 1.0 - n_moving / n_votes
    else:
        mx, my = _mode(rel_x[moving], rel_y[moving])
        spread = float(
            np.median(np.hypot(rel_x[moving] - mx, rel_y[moving] - my))
        )  # median distance of the votes from the mode, px
        agreement = max(0.0, 1.0 - spread / max(math.hypot(mx, my), 1e-6))
        vx, vy = mx / dt, my / dt
    confidence = min(1.0, texture_share / 0.3) * agreement * min(1.0, n_votes / 200.0)
    confidence = float(np.clip(confidence, 0.0, 1.0))
    method = f"{FLOWS[flow]} flow"
    if confidence < LOW_CONFIDENCE:
        # the flow is not trusted: fall back on how the masks moved
        ys0, xs0 = np.nonzero(pm)
        ys1, xs1 = np.nonzero(cm)
        dx, dy = float(xs1.mean() - xs0.mean()), float(ys1.mean() - ys0.mean())
        if math.hypot(dx, dy) < STILL_PX:
            dx = dy = 0.0
        vx, vy = dx / dt, dy / dt
        calm = dx == 0.0 and dy == 0.0
        method = "mask centroid shift (flow unreliable)"
        notes.append(
            f"low confidence: only {100 * texture_share:.0f} % of the plume carries trackable texture"
        )

    if calm:
        return Motion(
            (0.0, 0.0), regime="calm", confidence=confidence, source="two-looks",
            method=method, ground_shift=(gdx, gdy), upwind_shift=0.0, downwind_shift=0.0,
            interval_s=dt, notes=tuple(notes),
        )  # fmt: skip
    u = np.array([vx, vy]) / math.hypot(vx, vy)
    up0, down0 = _edges(pm, u)
    up1, down1 = _edges(cm, u)
    along = math.hypot(vx, vy) * dt
    up_shift, down_shift = up1 - up0, down1 - down0
    if along < 1.0:
        notes.append(f"the plume moved only {along:.2f} px between the looks: regime uncertain")
    parts = _component_regimes(pm, cm, (vx * dt, vy * dt), u, along, dt)
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
    )


def _component_regimes(pm, cm, d, u, along, dt) -> list[tuple[float, float, float] | None]:
    """Per plume of the current mask (largest first): ``None`` if it moved as a whole,
    else ``(vent x, vent y, front speed px/s)`` of an attached plume.

    A current component is matched with the previous components it overlaps when
    carried back by the displacement ``d``; its upwind edge moving less than
    :data:`ATTACHED_UPWIND` of the displacement makes it attached, unless that end
    touches the image border (a cloud drifting in: no vent seen). Its front speed
    is how fast it grows along the flow: the area gained between the looks over its
    mean width (area / length), per second; 0 for a mature plume whose far end fades
    as fast as it is fed, or lies beyond the image border; at most the flow speed.
    """
    n, labels, stats, _ = cv2.connectedComponentsWithStats(cm.astype(np.uint8), connectivity=8)
    _, prev_labels = cv2.connectedComponents(pm.astype(np.uint8), connectivity=8)
    h, w = cm.shape
    back = np.float32([[1, 0, -d[0]], [0, 1, -d[1]]])
    order = sorted(range(1, n), key=lambda i: -stats[i, cv2.CC_STAT_AREA])
    out: list[tuple[float, float, float] | None] = []
    for i in order:
        if stats[i, cv2.CC_STAT_AREA] < MIN_COMPONENT_PX:
            continue
        comp = labels == i
        carried = cv2.warpAffine(comp.astype(np.uint8), back, (w, h), flags=cv2.INTER_NEAREST) > 0
        carried = cv2.dilate(carried.astype(np.uint8), np.ones((5, 5), np.uint8)) > 0
        ids = np.unique(prev_labels[carried & pm])
        prev = np.isin(prev_labels, ids[ids > 0])
        if not prev.any():
            out.append(None)  # new since the previous look: nothing to compare; moves with the flow
            continue
        up0, _ = _edges(prev, u)
        up1, down1 = _edges(comp, u)
        cys, cxs = np.nonzero(comp)
        upwind = cxs * u[0] + cys * u[1] <= up1 + 1.5
        if (
            (cxs[upwind] == 0).any() or (cys[upwind] == 0).any()
            or (cxs[upwind] == w - 1).any() or (cys[upwind] == h - 1).any()
        ):  # fmt: skip
            out.append(None)  # its upwind end is cut by the image border: no vent seen
            continue
        if up1 - up0 < ATTACHED_UPWIND * along:
            downwind = cxs * u[0] + cys * u[1] >= down1 - 1.5
            at_border = (
                (cxs[downwind] == 0).any() or (cys[downwind] == 0).any()
                or (cxs[downwind] == w - 1).any() or (cys[downwind] == h - 1).any()
            )  # fmt: skip
            # a far end beyond the image is not seen to advance: the part inside stays
            # the front's advance from the plume's growth: area gained / mean width (the
            # area over the length), steadier than the far end's flickering tip
            length = max(down1 - up1, 1.0)
            growth = (comp.sum() - prev.sum()) * length / comp.sum()
            front = 0.0 if at_border else float(np.clip(growth / dt, 0.0, along / dt))
            vx, vy = _vent(comp, u)
            out.append((vx, vy, front))
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
