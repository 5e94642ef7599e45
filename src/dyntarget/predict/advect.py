"""The plume as it will be: semi-Lagrangian advection of the mask or probability.

* **detached** cloud: every pixel is carried by the plume velocity; the field
  at time ``t`` is the current field traced back along the flow (semi-Lagrangian,
  bilinear sampling, ``cv2.remap``): with a dense motion field
  (``Motion.dense``, from :func:`~dyntarget.predict.estimate_motion`) each pixel
  by its own velocity, ``f_t(x) = f_0(x0)``, ``x0 = x - t v((x + x0) / 2)``, so
  each plume moves, turns and shears by its own motion; with one velocity
  ``f_t(x) = f_0(x - v t)`` (exact in one step). Attached plumes use the scene's
  velocity ``Motion.velocity``.
* **attached** plume: the puffs already emitted are carried like a detached
  cloud, ``f_0(x - v t)``, and the vent keeps emitting: the plume's source end
  (its upwind :data:`SOURCE_BAND_PX`) is swept downwind from the vent over
  ``v t``, ``max_{0<=s<=t} f_src(x - v s)`` (a grey dilation with a line,
  OpenCV). The vent end stays. Puffs fade, so the carried puffs stop at the
  plume's far end plus the measured front speed times ``t`` (two looks only).
  Spreading of the puffs is not modelled. (``ATTACHED_MODEL = "sweep"``: the
  whole envelope swept forward at the measured front speed ``Motion.attached``,
  a first model that fills gaps the truth keeps; see ``docs/onboard.md``.)
* **mixed**: plumes of the mask near a vent of ``Motion.attached`` are attached,
  the others (detached clouds) are carried as a whole.
* **calm**: unchanged.

Pixels entering from beyond the border are background (0).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, replace

import cv2
import numpy as np

from dyntarget.errors import InvalidParameterError, InvalidSceneError
from dyntarget.predict.motion import Motion


def check_lead(lead_s: object) -> float:
    """Validate a lead time (seconds after the current look, finite, >= 0).

    Parameters
    ----------
    lead_s : object
        The lead time, anything ``float()`` accepts.

    Returns
    -------
    float
        The lead time, seconds.

    Raises
    ------
    dyntarget.errors.InvalidParameterError
        When it is not a finite number >= 0.

    Examples
    --------
    >>> check_lead(0)
    0.0
    """
    try:
        v = float(lead_s)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        v = math.nan
    if not (math.isfinite(v) and v >= 0):
        raise InvalidParameterError(f"lead_s: expected seconds >= 0, got {lead_s!r}")
    return v


def _shift(field: np.ndarray, dx: float, dy: float) -> np.ndarray:
    m = np.array([[1, 0, dx], [0, 1, dy]], np.float32)
    h, w = field.shape
    return cv2.warpAffine(
        field, m, (w, h), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0
    )


def _carry(field: np.ndarray, motion: Motion, lead: float) -> np.ndarray:
    """Detached plumes ``lead`` s ahead: one shift, or semi-Lagrangian through the dense field.

    With ``motion.dense`` the field at ``x`` is the current field at the departure
    point ``x0 = x - t v((x + x0) / 2)`` (midpoint rule, three fixed-point
    iterations on a :data:`DEPARTURE_STEP_PX` grid, then interpolated to every
    pixel; ``cv2.remap``, bilinear), so a rotating or shearing cloud turns and
    each plume moves by its own motion.
    """
    dense = motion.dense
    if dense is None:
        dx, dy = motion.displacement(lead)
        return _shift(field, dx, dy)
    h, w = field.shape
    # departure points on a grid of STEP px (the field is smooth over FIELD_SIGMA cells),
    # then interpolated to every pixel: one full-size remap of the field itself
    step = max(int(dense.scale), DEPARTURE_STEP_PX)
    hc, wc = -(-h // step), -(-w // step)
    gy, gx = np.mgrid[0:hc, 0:wc].astype(np.float32) * step + (step - 1) / 2
    t = np.float32(lead)
    v = dense.sample(gx, gy)
    x0, y0 = gx - t * v[..., 0], gy - t * v[..., 1]
    for _ in range(3):
        v = dense.sample((gx + x0) * 0.5, (gy + y0) * 0.5)
        x0, y0 = gx - t * v[..., 0], gy - t * v[..., 1]
    disp = np.stack([gx - x0, gy - y0], axis=-1)
    disp = cv2.resize(disp, (wc * step, hc * step), interpolation=cv2.INTER_LINEAR)[:h, :w]
    fy, fx = _grid(h, w)
    return cv2.remap(
        field, fx - disp[..., 0], fy - disp[..., 1], cv2.INTER_LINEAR,
        borderMode=cv2.BORDER_CONSTANT, borderValue=0,
    )  # fmt: skip


@functools.lru_cache(maxsize=4)
def _grid(h: int, w: int) -> tuple[np.ndarray, np.ndarray]:
    """Row and column coordinates ``float32 (H, W)`` (cached: the same grid every look)."""
    fy, fx = np.mgrid[0:h, 0:w].astype(np.float32)
    fy.flags.writeable = fx.flags.writeable = False
    return fy, fx


DEPARTURE_STEP_PX = 4
"""Grid (px) on which the semi-Lagrangian departure points are traced before interpolation."""


def _sweep(field: np.ndarray, dx: float, dy: float) -> np.ndarray:
    """``max over s in [0, 1] of field(x - s (dx, dy))``: grey dilation with a line."""
    r = math.ceil(max(abs(dx), abs(dy)))
    if r == 0:
        return field.copy()
    kernel = np.zeros((2 * r + 1, 2 * r + 1), np.uint8)
    # cv2.dilate: dst(x) = max over kernel offsets k of src(x + k - anchor); we need
    # offsets -s (dx, dy) from the anchor (r, r), so the line runs from (r, r) to (r - dx, r - dy)
    cv2.line(kernel, (r, r), (round(r - dx), round(r - dy)), 1, 1)
    swept = cv2.dilate(field, kernel, anchor=(r, r), borderType=cv2.BORDER_CONSTANT, borderValue=0)
    # the line kernel is rounded to whole pixels; its far end is placed exactly
    return np.maximum(swept, _shift(field, dx, dy))


def predict_field(field: np.ndarray, motion: Motion, lead_s: float) -> np.ndarray:
    """Advect a plume probability (or 0/1 field) ``lead_s`` seconds ahead.

    Parameters
    ----------
    field : float (H, W)
        Plume probability (or a mask as 0/1) at the current look.
    motion : Motion
        From :func:`~dyntarget.predict.estimate_motion` or :func:`~dyntarget.predict.wind_motion`.
    lead_s : float
        Seconds after the current look (>= 0).

    Returns
    -------
    float32 (H, W) field at ``lead_s``.

    Examples
    --------
    >>> f = np.zeros((1, 8), np.float32); f[0, 1] = 1
    >>> predict_field(f, Motion((1.0, 0.0)), 3.0)[0].round(2).tolist()
    [0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0]
    """
    arr = np.asarray(field)
    if arr.ndim != 2 or arr.size == 0:
        raise InvalidSceneError(
            f"field: expected a non-empty 2-D array (H, W), got shape {arr.shape}"
        )
    arr = arr.astype(np.float32)
    if not np.isfinite(arr).all():
        raise InvalidSceneError("field: NaN or infinite values")
    lead = check_lead(lead_s)
    dx, dy = motion.displacement(lead)
    dense = motion.dense
    if dense is not None and tuple(dense.shape) != arr.shape:
        raise InvalidSceneError(
            f"field: shape {arr.shape} does not match the motion field's grid {dense.shape}"
        )
    if motion.regime == "calm" or lead == 0 or (dense is None and dx == 0 and dy == 0):
        return arr.copy()
    if motion.regime == "detached":
        return _carry(arr, motion, lead)
    attached = attached_region(arr >= 0.5, motion)
    if not attached.all():  # a margin so the attached plume's soft edge goes with it
        attached = cv2.dilate(attached.astype(np.uint8), np.ones((5, 5), np.uint8)) > 0
    plume = np.where(attached, arr, 0.0).astype(np.float32)
    moved = _carry(np.where(attached, 0.0, arr).astype(np.float32), motion, lead)
    if ATTACHED_MODEL == "sweep":
        front = front_speed(motion) / max(motion.speed, 1e-12)  # share of the flow displacement
        return np.maximum(_sweep(plume, dx * front, dy * front), moved)
    # puffs: the attached plume's pattern is carried downwind like a detached cloud ...
    carried = _front_limited(_shift(plume, dx, dy), plume, motion, lead)
    # ... while the vent keeps emitting: its source end, swept from the vent downwind
    source = _source_end(plume, motion.velocity)
    return np.maximum(np.maximum(carried, _sweep(source, dx, dy)), moved)


def _front_limited(carried: np.ndarray, plume: np.ndarray, motion: Motion, lead: float):
    """Puffs fade: the visible far end advances at the measured front speed, not the wind's.

    ``carried`` is cut beyond the current attached plume's far end (along the flow)
    plus ``front_speed * lead``; without a measured front (a wind prior) it is kept.
    """
    if not motion.attached:
        return carried
    speed = motion.speed
    ux, uy = motion.velocity[0] / speed, motion.velocity[1] / speed
    h, w = plume.shape
    yy, xx = np.mgrid[0:h, 0:w]
    s = xx * ux + yy * uy
    inside = plume >= 0.5
    if not inside.any():
        return carried
    limit = s[inside].max() + front_speed(motion) * lead
    return np.where(s <= limit, carried, 0.0).astype(np.float32)


ATTACHED_MODEL = "advect"
"""How attached plumes are predicted: ``"advect"`` (puffs carried, source end swept) or
``"sweep"`` (the envelope swept forward at the measured front speed)."""
SOURCE_BAND_PX = 3.0
"""Depth (px along the flow) of an attached plume's source end, the part the vent refills."""


def _source_end(field: np.ndarray, velocity: tuple[float, float]) -> np.ndarray:
    """The field on each plume's upwind ``SOURCE_BAND_PX`` (its source end), zero elsewhere."""
    speed = math.hypot(*velocity)
    n, labels = cv2.connectedComponents((field >= 0.5).astype(np.uint8), connectivity=8)
    if n <= 1 or speed == 0:
        return np.zeros_like(field)
    ux, uy = velocity[0] / speed, velocity[1] / speed
    h, w = field.shape
    yy, xx = np.mgrid[0:h, 0:w]
    s = xx * ux + yy * uy
    keep = np.zeros(field.shape, bool)
    for i in range(1, n):
        comp = labels == i
        keep |= comp & (s <= s[comp].min() + SOURCE_BAND_PX)
    keep = cv2.dilate(keep.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
    return np.where(keep, field, 0.0).astype(np.float32)


VENT_RADIUS = 3.0
"""A plume of the mask within this many pixels of a measured vent is that vent's plume."""


def front_speed(motion: Motion) -> float:
    """How fast attached plumes' far ends advance, px/s: the fastest measured front, or
    the full speed when none was measured (wind prior).

    Parameters
    ----------
    motion : dyntarget.predict.Motion
        The motion estimate.

    Returns
    -------
    float
        Front speed, pixels per second.

    Examples
    --------
    >>> front_speed(Motion((3.0, 4.0), regime="attached"))
    5.0
    """
    if motion.attached:
        return max(a[2] for a in motion.attached)
    return motion.speed


def attached_region(mask: np.ndarray, motion: Motion) -> np.ndarray:
    """The pixels of ``mask`` that belong to attached plumes (bool (H, W)).

    ``attached``: every plume; ``mixed``: the 8-connected plumes within
    :data:`VENT_RADIUS` px of a vent of ``motion.attached``; otherwise none.

    Parameters
    ----------
    mask : numpy.ndarray
        ``(H, W)`` plume mask.
    motion : dyntarget.predict.Motion
        Its regime and, for ``mixed``, the vents of the attached plumes.

    Returns
    -------
    numpy.ndarray
        Boolean ``(H, W)``.

    Examples
    --------
    >>> m = np.zeros((1, 9), bool); m[0, :2] = m[0, 6:] = True
    >>> mo = Motion((1.0, 0.0), regime="mixed", attached=((0.0, 0.0, 0.0),))
    >>> attached_region(m, mo).astype(int).tolist()
    [[1, 1, 0, 0, 0, 0, 0, 0, 0]]
    """
    m = np.asarray(mask, bool)
    if motion.regime == "attached":
        return m.copy()
    if motion.regime != "mixed" or not motion.attached:
        return np.zeros_like(m)
    _, labels = cv2.connectedComponents(m.astype(np.uint8), connectivity=8)
    h, w = m.shape
    ids: set[int] = set()
    r = math.ceil(VENT_RADIUS)
    for x, y, _ in motion.attached:
        cx, cy = round(x), round(y)
        win = labels[
            max(cy - r, 0) : max(min(cy + r + 1, h), 0), max(cx - r, 0) : max(min(cx + r + 1, w), 0)
        ]
        ids.update(int(v) for v in np.unique(win) if v > 0)
    return np.isin(labels, sorted(ids))


def predict_mask(mask: np.ndarray, motion: Motion, lead_s: float) -> np.ndarray:
    """The plume mask ``lead_s`` seconds after the current look.

    The mask is advected as a 0/1 field (:func:`predict_field`) and thresholded
    at 0.5, so sub-pixel displacements move edges by the nearest pixel.

    Parameters
    ----------
    mask : numpy.ndarray
        Non-empty ``(H, W)`` boolean or integer (non-zero = plume) mask.
    motion : dyntarget.predict.Motion
        How the plume moves.
    lead_s : float
        Seconds after the current look.

    Returns
    -------
    numpy.ndarray
        Boolean ``(H, W)`` predicted mask.

    Raises
    ------
    dyntarget.errors.InvalidSceneError
        For a mask of the wrong shape or dtype.

    Examples
    --------
    >>> m = np.zeros((5, 5), bool); m[2, 0] = True
    >>> predict_mask(m, Motion((1.0, 0.0), regime="attached"), 2.0)[2].astype(int).tolist()
    [1, 1, 1, 0, 0]
    """
    arr = np.asarray(mask)
    if arr.ndim != 2 or arr.size == 0:
        raise InvalidSceneError(
            f"mask: expected a non-empty 2-D mask (H, W), got shape {arr.shape}"
        )
    if arr.dtype != bool and not np.issubdtype(arr.dtype, np.integer):
        raise InvalidSceneError(f"mask: expected a boolean or integer mask, got dtype {arr.dtype}")
    return predict_field((arr != 0).astype(np.float32), motion, lead_s) >= 0.5


@dataclass(frozen=True)
class Prediction:
    """What the pipeline needs to plan on the plume as it will be.

    ``motion`` says how the plume moves; ``lead_s`` is the time, in seconds
    after the current look-ahead acquisition, the plan is drawn for (e.g. when
    the NFOV will be there). With agility, the pipeline moves each pointing on
    to its own scheduled time (:func:`dyntarget.pipeline.schedule_on_prediction`).

    Parameters
    ----------
    motion : dyntarget.predict.Motion
        How the plume moves.
    lead_s : float
        When the plan is drawn for, seconds after the current look-ahead acquisition.

    Examples
    --------
    >>> p = Prediction(Motion((1.0, 0.0)), 2)
    >>> m = np.zeros((3, 6), bool); m[1, 0] = True
    >>> p.mask(m)[1].astype(int).tolist()
    [0, 0, 1, 0, 0, 0]
    """

    motion: Motion
    lead_s: float = 0.0

    def __post_init__(self) -> None:
        if not isinstance(self.motion, Motion):
            raise InvalidParameterError(
                f"motion: expected a dyntarget.predict.Motion, got {type(self.motion).__name__}"
            )
        object.__setattr__(self, "lead_s", check_lead(self.lead_s))

    def mask(self, mask: np.ndarray) -> np.ndarray:
        """The mask at ``lead_s`` (:func:`predict_mask`).

        Parameters
        ----------
        mask : numpy.ndarray
            ``(H, W)`` boolean or integer plume mask of the current look.

        Returns
        -------
        numpy.ndarray
            Boolean ``(H, W)`` predicted mask.
        """
        return predict_mask(mask, self.motion, self.lead_s)

    def field(self, field: np.ndarray) -> np.ndarray:
        """A probability field at ``lead_s`` (:func:`predict_field`).

        Parameters
        ----------
        field : numpy.ndarray
            ``(H, W)`` field of the current look, e.g. the plume probability.

        Returns
        -------
        numpy.ndarray
            ``(H, W)`` float32 advected field.
        """
        return predict_field(field, self.motion, self.lead_s)

    def attached_mask(self, mask: np.ndarray) -> np.ndarray:
        """Where the attached plumes of the current ``mask`` will be at ``lead_s`` (bool).

        For :meth:`pointing_shift`: pointings there are not moved.

        Parameters
        ----------
        mask : numpy.ndarray
            ``(H, W)`` plume mask of the current look.

        Returns
        -------
        numpy.ndarray
            Boolean ``(H, W)``; all false when no plume is attached.
        """
        m = np.asarray(mask, bool)
        region = attached_region(m, self.motion)
        if not region.any():
            return region
        return predict_mask(region, replace(self.motion, regime="attached"), self.lead_s)

    def pointing_shift(
        self,
        dt_s: np.ndarray,
        points: np.ndarray | None = None,
        attached: np.ndarray | None = None,
    ) -> np.ndarray:
        """Pixels to move pointings observed ``dt_s`` seconds after ``lead_s``, shape (n, 2).

        A detached cloud carries the pointed-at plume with it (``v dt``). An
        attached plume's near-vent part is steady and a point inside it at
        ``lead_s`` stays inside a continuous plume seconds later: no shift. With ``mixed`` plumes, the
        pointings at ``points`` inside ``attached`` (:meth:`attached_mask`) stay,
        the others move; without them, none moves.

        Parameters
        ----------
        dt_s : numpy.ndarray
            ``(n,)`` seconds after ``lead_s`` each pointing is observed.
        points : numpy.ndarray or None
            ``(n, 2)`` pointings ``(x, y)``, needed for ``mixed`` plumes.
        attached : numpy.ndarray or None
            Boolean ``(H, W)`` from :meth:`attached_mask`, needed for ``mixed`` plumes.

        Returns
        -------
        numpy.ndarray
            ``(n, 2)`` shifts ``(dx, dy)``, pixels.
        """
        dt = np.asarray(dt_s, np.float64).reshape(-1)
        regime = self.motion.regime
        dense = self.motion.dense
        if dense is not None and points is not None and regime != "calm":
            pts = np.asarray(points, np.float64).reshape(-1, 2)
            v = dense.sample(pts[:, 0], pts[:, 1]).astype(np.float64)
            shift = v * dt[:, None]
        else:
            shift = np.stack([self.motion.velocity[0] * dt, self.motion.velocity[1] * dt], axis=1)
        if regime == "detached":
            return shift
        if regime != "mixed" or points is None or attached is None:
            return np.zeros((len(dt), 2))
        pts = np.asarray(points, np.float64).reshape(-1, 2)
        h, w = attached.shape
        rows = np.clip(np.floor(pts[:, 1] + 0.5).astype(int), 0, h - 1)
        cols = np.clip(np.floor(pts[:, 0] + 0.5).astype(int), 0, w - 1)
        return np.where(attached[rows, cols][:, None], 0.0, shift)
