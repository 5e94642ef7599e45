"""The plume as it will be: semi-Lagrangian advection of the mask or probability.

* **detached** cloud: every pixel is carried by the plume velocity ``v``; the
  field at time ``t`` is the current field traced back along the flow,
  ``f_t(x) = f_0(x - v t)`` (semi-Lagrangian step, bilinear sampling; with one
  velocity per plume the back-trajectory is exact in one step).
* **attached** plume: the vent keeps emitting and the puffs move at ``v``, so
  the envelope at ``t`` is everything the current plume sweeps when carried by
  ``v s`` for ``0 <= s <= t``: ``f_t(x) = max_s f_0(x - v s)``. The vent end
  stays; the far end moves by ``v t`` (the envelope stretches). Evaluated as a
  grey dilation with a line of length ``|v t|`` (OpenCV), no loop over ``s``.
* **calm**: unchanged.

Pixels entering from beyond the border are background (0).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from dyntarget.errors import InvalidParameterError, InvalidSceneError
from dyntarget.predict.motion import Motion


def check_lead(lead_s: object) -> float:
    """Validate a lead time (seconds after the current look, finite, >= 0).

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
    m = np.float32([[1, 0, dx], [0, 1, dy]])
    h, w = field.shape
    return cv2.warpAffine(
        field, m, (w, h), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0
    )


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
    if motion.regime == "calm" or (dx == 0 and dy == 0):
        return arr.copy()
    if motion.regime == "attached":
        return _sweep(arr, dx, dy)
    return _shift(arr, dx, dy)


def predict_mask(mask: np.ndarray, motion: Motion, lead_s: float) -> np.ndarray:
    """The plume mask ``lead_s`` seconds after the current look.

    The mask is advected as a 0/1 field (:func:`predict_field`) and thresholded
    at 0.5, so sub-pixel displacements move edges by the nearest pixel.

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
        """The mask at ``lead_s`` (:func:`predict_mask`)."""
        return predict_mask(mask, self.motion, self.lead_s)

    def field(self, field: np.ndarray) -> np.ndarray:
        """A probability field at ``lead_s`` (:func:`predict_field`)."""
        return predict_field(field, self.motion, self.lead_s)

    def pointing_shift(self, dt_s: np.ndarray) -> np.ndarray:
        """Pixels to move pointings observed ``dt_s`` seconds after ``lead_s``, shape (n, 2).

        A detached cloud carries the pointed-at plume with it (``v dt``). An
        attached plume's envelope only grows downwind, so a point inside it at
        ``lead_s`` stays inside later: no shift.
        """
        dt = np.asarray(dt_s, np.float64).reshape(-1)
        if self.motion.regime != "detached":
            return np.zeros((len(dt), 2))
        return np.stack([self.motion.velocity[0] * dt, self.motion.velocity[1] * dt], axis=1)
