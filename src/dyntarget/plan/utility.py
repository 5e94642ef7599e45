"""``utility-max``: choose and order pointings to maximise expected utility under a time budget.

The geometric planners follow the plume's shape; this planner follows its
*expected utility*. From the classifier's plume probability ``p`` and the WFOV
blue band it predicts the paper's two utility maps the same way the simulator
computes them on the truth (:mod:`dyntarget.observe.nfov`):

* ``intensity``: ``p * blue``, divided by its maximum;
* ``gradient``: the 5x5 Sobel gradient magnitude of that, divided by its maximum;
* ``plume``: ``p`` itself.

Candidates are the pixels of a grid with the planner step (1 % of the image
width by default) whose expected utility is positive, at most
:data:`MAX_CANDIDATES` of the best. Selection is a greedy orienteering
heuristic on the kinematic model (:mod:`dyntarget.schedule`): from the
sensor's current state it takes next the feasible candidate with the highest
expected utility per second spent (slew, settle, waiting for the target to
enter the field of regard, dwell), until no candidate can be reached inside its
visibility window, the time budget or the pointing budget is spent. With
unlimited agility time costs nothing and the rule reduces to taking the
highest expected utility first, so a pointing budget is needed.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from dyntarget import defaults
from dyntarget.errors import InvalidParameterError
from dyntarget.schedule import Agility, OrbitGeometry, Timer, get_agility, visibility_windows
from dyntarget.trajectory import Trajectory

OBJECTIVES = defaults.OBJECTIVES
MAX_CANDIDATES = 1500
"""Candidates kept (highest expected utility first); bounds the planner's cost."""
_MIN_COST_S = 1e-3
"""Time charged to a pointing that costs none (unlimited agility): ranks by utility alone."""


def predicted_utility(probability: np.ndarray, image: np.ndarray, objective: str) -> np.ndarray:
    """Expected utility per WFOV pixel, 0..1, from the plume probability and the WFOV image.

    Parameters
    ----------
    probability : numpy.ndarray
        ``(H, W)`` plume probability, 0..1.
    image : numpy.ndarray
        ``(4, H, W)`` WFOV image; its band 2 (blue) weighs the intensity.
    objective : {"gradient", "intensity", "plume"}
        Which utility map (see the module docstring).

    Returns
    -------
    numpy.ndarray
        ``(H, W)`` float32 expected utility.

    Raises
    ------
    dyntarget.errors.InvalidParameterError
        For an unknown ``objective``.
    """
    if objective not in OBJECTIVES:
        raise InvalidParameterError(
            f"objective: expected one of {', '.join(OBJECTIVES)}, got {objective!r}"
        )
    p = np.asarray(probability, np.float32)
    if objective == "plume":
        return p
    intensity = p * np.asarray(image[2], np.float32)
    peak = float(intensity.max())
    intensity = intensity / peak if peak > 0 else intensity
    if objective == "intensity":
        return intensity
    gx = cv2.Sobel(intensity, cv2.CV_32F, 1, 0, ksize=5)
    gy = cv2.Sobel(intensity, cv2.CV_32F, 0, 1, ksize=5)
    g = np.hypot(gx, gy)
    gpeak = float(g.max())
    return g / gpeak if gpeak > 0 else g


def utility_max(
    probability: np.ndarray,
    image: np.ndarray,
    geometry: OrbitGeometry,
    agility: Agility | str,
    *,
    step: float,
    objective: str = "gradient",
    budget_s: float | None = None,
    max_pointings: int | None = None,
) -> Trajectory:
    """Plan greedily for the highest expected utility per second (see the module docstring).

    Parameters
    ----------
    probability : numpy.ndarray
        ``(H, W)`` plume probability, 0..1.
    image : numpy.ndarray
        ``(4, H, W)`` WFOV image.
    geometry : dyntarget.schedule.OrbitGeometry
        Where the scene lies and when the plan starts.
    agility : dyntarget.schedule.Agility or str
        The sensor's kinematics, or an agility preset name.
    step : float
        Spacing of the candidate grid, pixels (at least 1).
    objective : {"gradient", "intensity", "plume"}
        What to maximise (see the module docstring).
    budget_s : float or None
        Time budget after ``geometry.start_s``, seconds; ``None`` for none.
    max_pointings : int or None
        Pointing budget; needed with unlimited agility.

    Returns
    -------
    dyntarget.trajectory.Trajectory
        The chosen pointings in visiting order, all in part 0, untimed (empty when
        no candidate can be reached).
    """
    agility = get_agility(agility) if isinstance(agility, str) else agility
    if not (math.isfinite(step) and step >= 1):
        raise InvalidParameterError(f"step: expected a number of pixels >= 1, got {step!r}")
    if budget_s is not None and not (math.isfinite(budget_s) and budget_s >= 0):
        raise InvalidParameterError(
            f"budget_s: expected a number of seconds >= 0, got {budget_s!r}"
        )
    if max_pointings is not None and (isinstance(max_pointings, bool) or max_pointings < 0):
        raise InvalidParameterError(
            f"max_pointings: expected an integer >= 0, got {max_pointings!r}"
        )
    if agility.unlimited and max_pointings is None:
        raise InvalidParameterError(
            "max_pointings: needed with unlimited agility (time costs nothing there)"
        )
    utility = predicted_utility(probability, image, objective)
    h, w = utility.shape
    rows = np.round(np.arange(0, h, step)).astype(np.int64)
    cols = np.round(np.arange(0, w, step)).astype(np.int64)
    rr, cc = np.meshgrid(
        np.unique(rows.clip(0, h - 1)), np.unique(cols.clip(0, w - 1)), indexing="ij"
    )
    u = utility[rr, cc].ravel().astype(np.float64)
    pts = np.column_stack([cc.ravel(), rr.ravel()]).astype(np.float64)
    keep = np.flatnonzero(u > 0)
    keep = keep[np.argsort(-u[keep], kind="stable")][:MAX_CANDIDATES]
    u, pts = u[keep], pts[keep]
    params = {
        "objective": objective,
        "agility": agility.name,
        "step": float(step),
        "budget_s": budget_s,
        "max_pointings": max_pointings,
    }
    along, cross = geometry.ground(pts, (h, w))
    t_in, t_out = visibility_windows(geometry, agility, along, cross)
    limit = math.inf if budget_s is None else geometry.start_s + budget_s
    cap = math.inf if max_pointings is None else max_pointings
    timer = Timer(geometry, agility)
    open_ = t_in <= t_out
    chosen: list[int] = []
    while len(chosen) < cap and open_.any():
        idx = np.flatnonzero(open_)
        start = timer.arrival(along[idx], cross[idx], t_in[idx])
        end = start + agility.dwell_s
        ok = (end <= t_out[idx]) & (end <= limit)
        # time only advances: a window that closes before the sensor could even settle and
        # dwell after its current observation stays out of reach
        soonest = timer.t + agility.settle_s + agility.dwell_s
        open_[idx[(t_out[idx] < soonest) | (soonest > limit)]] = False
        if not ok.any():
            break
        score = u[idx] / np.maximum(end - timer.t, _MIN_COST_S)
        score[~ok] = -np.inf
        best = int(np.argmax(score))  # first on ties: higher utility (candidates sorted by it)
        j = idx[best]
        timer.take(along[j], cross[j], start[best])
        chosen.append(j)
        open_[j] = False
    if not chosen:
        return Trajectory.empty("utility-max", params)
    sel = np.asarray(chosen)
    return Trajectory(pts[sel], np.zeros(len(sel), np.int64), "utility-max", params)


def utility_max_planner(mask: np.ndarray, polygons, config, context) -> Trajectory:
    """Pointings chosen for the highest expected utility per second under orbit kinematics; needs plan --agility PRESET.

    The registered planner ``utility-max``: :func:`utility_max` on the context's
    plume probability (or the mask, when planning on a given mask), every
    ``step`` pixels of ``config``.

    Parameters
    ----------
    mask : numpy.ndarray
        ``(H, W)`` plume mask (used when the context has no probability).
    polygons : list
        Unused (utility-max ranks pixels, not polygons).
    config : dyntarget.plan.PlanConfig
        Its step is the candidate spacing.
    context : dyntarget.plan.PlanContext
        The image, the kinematics and the budgets.

    Returns
    -------
    Trajectory
        Timed-feasible pointings in the order they are taken.
    """
    if context is None or context.geometry is None or context.agility is None:
        raise InvalidParameterError("utility-max plans under an agility preset: give --agility")
    if context.image is None:
        raise InvalidParameterError("utility-max needs the WFOV image in its plan context")
    probability = context.probability
    if probability is None:
        probability = np.asarray(mask, np.float32)
    step, _ = config.resolved(mask.shape)
    return utility_max(
        probability,
        context.image,
        context.geometry,
        context.agility,
        step=max(step, 1.0),
        objective=context.objective,
        budget_s=context.budget_s,
        max_pointings=context.max_pointings,
    )


utility_max_planner.needs_context = True  # type: ignore[attr-defined]
utility_max_planner.timed = True  # type: ignore[attr-defined]
