"""A true upper bound on the utility of a pass: no schedule the NFOV can fly scores more.

The pass loop (:mod:`dyntarget.fly.loop`) scores each flown pointing ``i`` by the
truth at its own start time ``s_i`` (rounded to the truth's time step) at the
WFOV pixel ``p_i`` it is rounded to, and sums over the pointings. The bound
relaxes every limit but three facts that hold for *every* schedule the
kinematics (:mod:`dyntarget.schedule`) allow:

1. **Windows.** ``s_i`` lies in the pointing's field-of-regard window,
   ``t_in <= s_i`` and ``s_i + dwell <= t_out``. The pointing lies within half
   a pixel of ``p_i``'s centre, so ``s_i`` lies in the pixel's window
   ``[t_in(p), t_out(p) - dwell]``, the union of its points' windows
   (:func:`pixel_windows`: the cell's nearest edge across track, its far
   edges along track; the reach ahead and behind nadir does not grow with
   the cross-track distance).
2. **Minimum time per pointing.** Each observation starts at least
   ``settle + dwell`` after the previous one (:class:`~dyntarget.schedule.Timer`:
   free ``dwell`` after a start, then slew (>= 0) and settle), also across
   frames (the sensor's state carries over). So a closed time interval of
   length ``L`` holds at most ``floor(L / (settle + dwell)) + 1`` starts.
3. **Never twice** (``distinct=True``). A pass that plans on the look as it
   is never scores one pixel twice: a pointing on a covered pixel (and a
   repeat within a plan) is dropped before scheduling, the GEO gate releases
   each pixel once, and a flown pixel is marked covered (planned pointings lie
   on the frame's grid, as the planners and the gate make them). With a
   predicted plume (``predict`` other than ``"none"``) pointings are moved
   after that check and may land on one pixel twice: ``distinct=False``.

Cut time into blocks, one per truth time step ``[q - step/2, q + step/2]``
(closed: a start on a boundary may be rounded either way); in block ``k``
the truth is one map ``u_k``. Every flown pass is then an assignment of
pointings to (pixel, block) pairs, each pixel at most once (3), block ``k``
holding at most ``c_k`` of them (2), a pixel only in a block its window meets
(1), of value ``sum u_k(p)``: the pass scores at most the best such
assignment. That is a transportation problem (its LP relaxation is
integral); by weak LP duality, for *any* prices ``lambda_k >= 0``::

    utility <= sum_k c_k lambda_k + sum_p max(0, max_k (u_k(p) - lambda_k))

(each assigned pair contributes ``u - lambda_k <= `` its pixel's term, and
block ``k`` collects ``lambda_k`` at most ``c_k`` times). The prices are the
LP's optimal duals (HiGHS, :func:`scipy.optimize.linprog`, on each block's
best candidates only: enough for an optimum, :func:`_prune`), so the bound is
the relaxation's exact optimum, and it is evaluated by the formula above
over every candidate, so a solver tolerance cannot make it too small.
Without (3) each block holds ``c_k`` copies of its best pixel:
``sum_k c_k max_p u_k(p)`` (infinite with unlimited agility: no time per
pointing). With unlimited agility (no window, no time per pointing) the
distinct bound is each pixel's best value over ``[t_start_s, t_end_s]``.

What is relaxed (so the bound is loose by): slews between pointings, the
order the spacecraft passes targets in, what the look-ahead can know and
when (the bound knows the truth at every time), the compute latency.
Cost: the truth at every time step over the field of regard (seconds for a
short strip; minutes for a 1000 km one, see ``benchmarks/geo_foresight.py
--upper-bound``) and one LP.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from dyntarget.errors import InvalidParameterError
from dyntarget.schedule import Agility, OrbitGeometry, visibility_windows

ValueAt = Callable[[float, int, int], np.ndarray]
"""``value_at(t, r0, r1)``: utility of one pointing at each WFOV pixel of rows ``r0:r1`` at ``t``."""

MAX_LP_VARIABLES = 3_000_000
"""Above this many (pixel, block) pairs the LP is not solved: prices from each block's
``c_k``-th best value instead (still a valid bound, ``exact`` false)."""
EPS_S = 1e-6
"""Blocks are widened by this much each way (times are sums of floats)."""


@dataclass(frozen=True)
class UpperBound:
    """The bound and how it was found.

    Parameters
    ----------
    value : float
        The upper bound on the pass's utility, rounded up to 4 decimals (``inf``: none finite).
    relaxation : float
        The relaxation's optimum as the LP solver reports it (``value`` is the dual
        bound, equal within the solver's tolerance when ``exact``).
    exact : bool
        Whether ``value`` is the relaxation's optimum (LP duals) rather than a bound
        from heuristic prices.
    distinct : bool
        Whether each pixel was counted at most once.
    per_pointing_s : float
        Least time between two pointings' starts, ``settle + dwell``.
    blocks : int
        Time blocks (truth time steps) in which some pixel has a positive utility.
    block_s : float
        Their length, seconds.
    candidates : int
        (pixel, block) pairs with a positive utility.
    pixels : int
        Pixels with a positive utility in some block.
    capacity : float
        Pointings the blocks hold in all (``inf``: no time per pointing).
    seconds : float
        Wall time spent.
    """

    value: float
    relaxation: float
    exact: bool
    distinct: bool
    per_pointing_s: float
    blocks: int
    block_s: float
    candidates: int
    pixels: int
    capacity: float
    seconds: float

    def as_dict(self, *, timing: bool = False) -> dict[str, Any]:
        """The bound as plain JSON values (``None`` for an infinite one).

        Parameters
        ----------
        timing : bool
            Include ``seconds`` (wall time: not the same bytes run to run).

        Returns
        -------
        dict
            Field name to value (``relaxation`` rounded to 4 decimals).

        Examples
        --------
        >>> b = UpperBound(math.inf, math.inf, True, False, 0.0, 1, 1.0, 1, 1, math.inf, 0.5)
        >>> d = b.as_dict(); d["value"], d["capacity"], "seconds" in d
        (None, None, False)
        """
        d = asdict(self)
        if not timing:
            del d["seconds"]
        if math.isfinite(d["relaxation"]):
            d["relaxation"] = round(d["relaxation"], 4)
        return {
            k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in d.items()
        }


def pixel_windows(
    geometry: OrbitGeometry,
    agility: Agility,
    shape: tuple[int, int],
    frame_px: int,
    rows: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """When some point of each strip WFOV pixel's cell is inside the field of regard.

    Pass coordinates as the loop's (:func:`dyntarget.passes.record.frame_plan`):
    frame 0 is the strip's bottom ``frame_px`` rows, acquired at pass time 0,
    its centre ``look_ahead_m`` ahead of nadir; row ``r`` lies
    ``look_ahead_m + ((frame_px - 1) / 2 - (r - (H - frame_px))) * gsd`` ahead
    of nadir at time 0, column ``c`` ``(c - (W - 1) / 2) * gsd`` across.
    The window of the cell ``[r +- 1/2] x [c +- 1/2]`` is taken from its far
    edges along track and its edge nearest the track across it (a superset of
    every window in the cell; ``t_in > t_out``: never visible).

    Parameters
    ----------
    geometry : the orbit (``look_ahead_m``, ``wfov_gsd_m``).
    agility : the sensor (field of regard, aft limit).
    shape : the strip's WFOV grid ``(H, W)``.
    frame_px : rows per look-ahead frame.
    rows : strip rows to compute (default: all).

    Returns
    -------
    (t_in, t_out) : ``(len(rows), W)`` pass seconds.

    Examples
    --------
    >>> from dyntarget.schedule import get_agility
    >>> g = OrbitGeometry(altitude_m=500e3, look_ahead_m=0.0, wfov_gsd_m=100.0)
    >>> t_in, t_out = pixel_windows(g, get_agility("fast"), (1, 1), 1)
    >>> round(float(t_in[0, 0]), 2), round(float(t_out[0, 0]) * g.ground_speed, 3)  # half a cell
    (-41.45, 50.0)
    """
    h, w = shape
    g = geometry.wfov_gsd_m
    r = np.arange(h, dtype=np.float64) if rows is None else np.asarray(rows, np.float64)
    along = geometry.look_ahead_m + ((frame_px - 1) / 2.0 - (r - (h - frame_px))) * g
    cross = np.abs((np.arange(w, dtype=np.float64) - (w - 1) / 2.0) * g)
    near = np.maximum(cross - g / 2.0, 0.0)
    a_lo = np.broadcast_to((along - g / 2.0)[:, None], (len(r), w))
    a_hi = np.broadcast_to((along + g / 2.0)[:, None], (len(r), w))
    c = np.broadcast_to(near[None, :], (len(r), w))
    t_in, _ = visibility_windows(geometry, agility, a_lo, c)
    _, t_out = visibility_windows(geometry, agility, a_hi, c)
    return t_in, t_out


def values_from_bands(
    at: Callable[[float, int], tuple[Any, int]], width: int, term: str = "intensity"
) -> ValueAt:
    """A :data:`ValueAt` over a banded truth (the pass loop's truth cache).

    Parameters
    ----------
    at : ``at(t, r) -> (band, first_row)``: the WFOV truth band holding strip row
        ``r`` at ``t`` (attributes ``term`` and ``valid``, ``(rows, width)``) and its
        first strip row (as :meth:`dyntarget.synth.worlds.TruthBands.at`).
    width : WFOV columns.
    term : which utility (``"intensity"``: the pass's ``utility``; ``"plume"``, ``"gradient"``).

    Returns
    -------
    ValueAt
        Utility per pixel, 0 on nodata.

    Examples
    --------
    >>> from types import SimpleNamespace
    >>> band = SimpleNamespace(intensity=np.arange(8.0).reshape(4, 2), valid=np.ones((4, 2), bool))
    >>> f = values_from_bands(lambda t, r: (band, 0), 2)
    >>> f(0.0, 1, 3).tolist()
    [[2.0, 3.0], [4.0, 5.0]]
    """

    def value_at(t: float, r0: int, r1: int) -> np.ndarray:
        out = np.zeros((r1 - r0, width), np.float64)
        r = r0
        while r < r1:
            band, b0 = at(t, r)
            vals = np.asarray(getattr(band, term))
            n = min(r1, b0 + vals.shape[0]) - r
            if n <= 0:
                raise InvalidParameterError(
                    f"truth band starting at row {b0} does not hold row {r}"
                )
            sl = slice(r - b0, r - b0 + n)
            out[r - r0 : r - r0 + n] = np.where(np.asarray(band.valid)[sl], vals[sl], 0.0)
            r += n
        return out

    return value_at


def upper_bound_utility(
    value_at: ValueAt,
    shape: tuple[int, int],
    frame_px: int,
    geometry: OrbitGeometry,
    agility: Agility,
    *,
    time_step_s: float | None,
    distinct: bool = True,
    t_start_s: float = 0.0,
    t_end_s: float | None = None,
) -> UpperBound:
    """An upper bound on the utility of every schedule a pass can fly (module docstring).

    Parameters
    ----------
    value_at : utility of one pointing per strip WFOV pixel at a time (:data:`ValueAt`,
        e.g. :func:`values_from_bands`); 0 where a pointing scores nothing.
    shape : the strip's WFOV grid ``(H, W)``.
    frame_px : rows per look-ahead frame (places the strip on the ground).
    geometry : the orbit and WFOV GSD.
    agility : the sensor.
    time_step_s : the truth's time step (it is constant between steps, rounded to
        the nearest); ``None``: the truth does not change (a static world; blocks of 1 s).
    distinct : each pixel scores at most once (a pass that plans on the look as it is).
    t_start_s : no pointing starts before (pass seconds; the loop: 0).
    t_end_s : no pointing starts after; needed with unlimited agility on a changing
        world (no window ends a pass: the loop's last frame's plan-ready time);
        default: when the last pixel leaves the field of regard.

    Returns
    -------
    UpperBound

    Examples
    --------
    Two pixels worth 0.5 and 0.25 at every time, unlimited agility: the bound is 0.75,
    and 0.5 for every pointing when a pixel may be pointed twice (no finite bound).

    >>> from dyntarget.schedule import get_agility
    >>> vals = lambda t, r0, r1: np.array([[0.5, 0.25]])[r0:r1]
    >>> g = OrbitGeometry(wfov_gsd_m=64.0)
    >>> upper_bound_utility(vals, (1, 2), 1, g, get_agility("unlimited"), time_step_s=None).value
    0.75
    >>> upper_bound_utility(vals, (1, 2), 1, g, get_agility("unlimited"), time_step_s=None,
    ...                     distinct=False).value
    inf
    """
    t0 = time.perf_counter()
    static = time_step_s is None
    step = 1.0 if time_step_s is None else float(time_step_s)
    if not (math.isfinite(step) and step > 0):
        raise InvalidParameterError(
            f"upper bound: needs the truth's time step > 0 s (it enumerates the truth's "
            f"times), got {time_step_s!r}"
        )
    h, w = shape
    tau = agility.settle_s + agility.dwell_s
    t_in, t_out = pixel_windows(geometry, agility, shape, frame_px)
    last = t_out - agility.dwell_s  # latest start
    ok = t_in <= last
    lo = max(t_start_s, float(t_in[ok].min())) if ok.any() else math.inf
    hi = float(last[ok].max()) if ok.any() else -math.inf
    if t_end_s is not None:
        hi = min(hi, float(t_end_s))
    if not math.isfinite(hi) and ok.any():  # no window ends the pass (unlimited agility)
        if not (static and tau == 0):
            raise InvalidParameterError(
                "upper bound: with no field of regard, a changing world or a time per "
                "pointing needs t_end_s (when the pass's last pointing may start)"
            )
        hi = lo  # one block: the truth is the same at every time, no time per pointing
    ks = range(math.ceil(lo / step - 0.5) - 1, math.floor(hi / step + 0.5) + 2) if lo <= hi else ()
    pix: list[np.ndarray] = []
    blk: list[np.ndarray] = []
    val: list[np.ndarray] = []
    cap: list[float] = []
    static_vals = value_at(0.0, 0, h) if static else None
    for k in ks:
        a = max((k - 0.5) * step - EPS_S, lo)
        b = min((k + 0.5) * step + EPS_S, hi)
        meet = ok & (t_in <= b) & (last >= a)
        rows = np.flatnonzero(meet.any(axis=1))
        if b < a or not len(rows):
            continue
        r0, r1 = int(rows[0]), int(rows[-1]) + 1
        v = static_vals[r0:r1] if static_vals is not None else value_at(k * step, r0, r1)
        v = np.where(meet[r0:r1], np.asarray(v, np.float64), 0.0)
        rr, cc = np.nonzero(v > 0)
        if not len(rr):
            continue
        pix.append((rr + r0) * w + cc)
        blk.append(np.full(len(rr), len(cap), np.int64))
        val.append(v[rr, cc])
        cap.append(math.floor((b - a) / tau) + 1 if tau > 0 else math.inf)
    p = np.concatenate(pix) if pix else np.zeros(0, np.int64)
    kk = np.concatenate(blk) if blk else np.zeros(0, np.int64)
    u = np.concatenate(val) if val else np.zeros(0)
    c = np.asarray(cap, np.float64)
    value, relax, exact = _solve(p, kk, u, c, distinct)
    return UpperBound(
        value=math.ceil(value * 1e4) / 1e4 if math.isfinite(value) else value,
        relaxation=relax,
        exact=exact,
        distinct=distinct,
        per_pointing_s=tau,
        blocks=len(cap),
        block_s=step,
        candidates=len(u),
        pixels=len(np.unique(p)),
        capacity=float(c.sum()),
        seconds=round(time.perf_counter() - t0, 3),
    )


def pass_upper_bound(
    truth_at: Callable[[float, int], tuple[Any, int]],
    wfov_shape: tuple[int, int],
    frame_px: int,
    geometry: OrbitGeometry,
    agility: Agility,
    *,
    time_step_s: float | None,
    distinct: bool,
    ready_s: Sequence[float] = (),
    is_3d: bool = False,
    world_id: str = "",
) -> UpperBound:
    """An upper bound on the utility of every schedule a pass over a strip can fly.

    :func:`upper_bound_utility` on the strip's truth at every truth time step (as the
    loop scores it, band by band: :func:`values_from_bands`), the pass's geometry and
    agility; each pixel counted once unless the pass moves pointings with a predicted
    plume (``distinct`` false).

    Parameters
    ----------
    truth_at : callable
        ``truth_at(t, r) -> (band, first_row)``: the strip's WFOV truth band holding row
        ``r`` at ``t`` (:meth:`dyntarget.synth.worlds.TruthBands.at`).
    wfov_shape : tuple of int
        The strip's WFOV grid ``(H, W)``.
    frame_px : int
        Frame height, WFOV rows.
    geometry : dyntarget.schedule.OrbitGeometry
        Orbit and WFOV GSD of the frames.
    agility : dyntarget.schedule.Agility
        The NFOV's limits.
    time_step_s : float or None
        The truth's time step (``None``: the truth does not change).
    distinct : bool
        Count each pixel once (a pass planning on the look as it is).
    ready_s : sequence of float
        When each frame's plan was ready: with unlimited agility, no pointing starts
        after the last (empty: at 0).
    is_3d : bool
        The world's plumes have heights: refused (see Raises).
    world_id : str
        The strip's name, for the message.

    Returns
    -------
    UpperBound

    Raises
    ------
    dyntarget.errors.InvalidParameterError
        On a 3D world: the bound is computed for flat worlds only.

    Examples
    --------
    >>> pass_upper_bound(lambda t, r: (None, 0), (8, 8), 8, None, None, time_step_s=None,
    ...                  distinct=True, is_3d=True, world_id="w")
    Traceback (most recent call last):
    ...
    dyntarget.errors.InvalidParameterError: world 'w' is 3D: the upper bound is computed for flat worlds only (a line of sight meets plume tops away from its aim, which the bound's reach does not model)
    """
    if is_3d:
        raise InvalidParameterError(
            f"world {world_id!r} is 3D: the upper bound is computed for flat worlds only (a line "
            "of sight meets plume tops away from its aim, which the bound's reach does not model)"
        )
    t_end = max(ready_s, default=0.0) if agility.unlimited else None
    return upper_bound_utility(
        values_from_bands(truth_at, wfov_shape[1]),
        wfov_shape,
        frame_px,
        geometry,
        agility,
        time_step_s=time_step_s,
        distinct=distinct,
        t_end_s=t_end,
    )


def dual_bound(
    pixel: np.ndarray, block: np.ndarray, value: np.ndarray, capacity: np.ndarray, price: np.ndarray
) -> float:
    """``sum_k c_k price_k + sum_p max(0, max_k (value - price_k))``: valid for any prices >= 0.

    Parameters
    ----------
    pixel, block, value : the candidate (pixel, block, utility) triples.
    capacity : ``c_k`` per block (finite).
    price : ``lambda_k >= 0`` per block.

    Returns
    -------
    float
        An upper bound on every assignment (each pixel once, block ``k`` at most ``c_k``).

    Examples
    --------
    Two pixels in one block of capacity 1 (worth 3 and 2): price 2 gives 2 + (3 - 2) = 3.

    >>> dual_bound(np.array([0, 1]), np.array([0, 0]), np.array([3.0, 2.0]),
    ...            np.array([1.0]), np.array([2.0]))
    3.0
    """
    price = np.maximum(np.asarray(price, np.float64), 0.0)
    slack = value - price[block]
    best = np.zeros(int(pixel.max()) + 1 if len(pixel) else 0)
    np.maximum.at(best, pixel, slack)
    return float(np.sum(capacity * price) + np.sum(best))


def _solve(
    p: np.ndarray, k: np.ndarray, u: np.ndarray, c: np.ndarray, distinct: bool
) -> tuple[float, float, bool]:
    """``(bound, relaxation optimum, exact)`` of the assignment (module docstring)."""
    if not len(u):
        return 0.0, 0.0, True
    if not distinct:
        best = np.zeros(len(c))
        np.maximum.at(best, k, u)
        total = float(np.sum(np.where(best > 0, c * best, 0.0)))
        return total, total, True
    # dense pixel numbers
    _, p = np.unique(p, return_inverse=True)
    if not np.isfinite(c).all():  # no time per pointing: each pixel at its best
        best = np.zeros(int(p.max()) + 1)
        np.maximum.at(best, p, u)
        total = float(best.sum())
        return total, total, True
    keep = _prune(p, k, u, c)
    p2, k2, u2 = p[keep], k[keep], u[keep]
    if len(u2) > MAX_LP_VARIABLES:
        price = _kth_best(k, u, c)
        return dual_bound(p, k, u, c, price), math.nan, False
    price, relax = _lp(p2, k2, u2, c)
    bound = dual_bound(p, k, u, c, price)
    return bound, relax, abs(bound - relax) <= 1e-6 * max(1.0, abs(relax))


def _prune(p: np.ndarray, k: np.ndarray, u: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Candidates among their block's best ``N_k``: enough for an optimal assignment.

    A pixel's candidate blocks span at most ``W`` blocks; ``N_k`` is the capacity of
    the blocks within ``W`` of ``k``. If an assignment puts a pixel in block ``k``
    outside its ``N_k`` best, those best can only be assigned within ``W`` of ``k``,
    where at most ``N_k - 1`` places are left: one of them is free, and at least as
    valuable in block ``k``: swap them.
    """
    lo = np.full(int(p.max()) + 1, len(c))
    hi = np.full(int(p.max()) + 1, -1)
    np.minimum.at(lo, p, k)
    np.maximum.at(hi, p, k)
    span = int((hi - lo).max())
    cum = np.concatenate([[0.0], np.cumsum(c)])
    idx = np.arange(len(c))
    near = cum[np.minimum(idx + span + 1, len(c))] - cum[np.maximum(idx - span, 0)]
    order = np.lexsort((-u, k))
    ks = k[order]
    first = np.searchsorted(ks, ks, side="left")
    rank = np.arange(len(ks)) - first
    keep = np.zeros(len(u), bool)
    keep[order[rank < near[ks]]] = True
    return keep


def _kth_best(k: np.ndarray, u: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Each block's ``c_k``-th best value (0 with fewer candidates): heuristic prices."""
    price = np.zeros(len(c))
    order = np.lexsort((-u, k))
    ks, us = k[order], u[order]
    first = np.searchsorted(ks, ks, side="left")
    rank = np.arange(len(ks)) - first
    hit = rank == (c[ks] - 1)
    price[ks[hit]] = us[hit]
    return price


def _lp(p: np.ndarray, k: np.ndarray, u: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, float]:
    """The transportation LP by HiGHS: its block prices (duals) and its optimum."""
    from scipy.optimize import linprog
    from scipy.sparse import coo_matrix, vstack

    m, nb, npx = len(u), len(c), int(p.max()) + 1
    j = np.arange(m)
    a_blocks = coo_matrix((np.ones(m), (k, j)), shape=(nb, m))
    a_pixels = coo_matrix((np.ones(m), (p, j)), shape=(npx, m))
    res = linprog(
        -u,
        A_ub=vstack([a_blocks, a_pixels]).tocsr(),
        b_ub=np.concatenate([c, np.ones(npx)]),
        bounds=(0, None),
        method="highs-ipm",  # faster than the simplex on these; duals after its crossover
    )
    if res.status != 0:  # pragma: no cover  (a bounded, feasible LP; kept for safety)
        return _kth_best(k, u, c), math.nan
    price = np.maximum(-np.asarray(res.ineqlin.marginals[:nb], np.float64), 0.0)
    return price, float(-res.fun)
