"""The blueprint: which targets a pass observes, in what order, with how many pointings."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from dyntarget.errors import InvalidParameterError
from dyntarget.schedule import Agility, OrbitGeometry, Timer, visibility_windows

MAX_TARGETS = 2000
STEP_PX = 2.0
"""WFOV pixels between two successive pointings on one target (the refinement flies a
target's best pixels in along-track serpentine order: neighbours one or two pixels apart)."""


@dataclass(frozen=True)
class Target:
    """A plume candidate, in pass ground coordinates.

    Parameters
    ----------
    along_m : float
        Along-track distance ahead of nadir at pass time 0, metres (its centre).
    cross_m : float
        Cross-track distance of its centre, metres.
    value : float
        Expected utility of one pointing on it (e.g. its GEO brightness anomaly).
    need : int
        Pointings that still gain (its expected area in NFOV footprints, capped).
    span : tuple of float
        ``(first, last)`` along-track rows it covers, in whatever units the caller
        matches pointings with (the pass loop: strip WFOV rows).
    curve : tuple of float
        Expected utility of its 1st, 2nd, ... pointing when it is known (best first,
        e.g. the true intensities sorted); empty: ``value`` for each of ``need``.
    """

    along_m: float
    cross_m: float
    value: float
    need: int
    span: tuple[float, float] = (0.0, 0.0)
    curve: tuple[float, ...] = ()

    def gains(self) -> np.ndarray:
        """Utility of each successive pointing (``need`` of them, best first).

        Returns
        -------
        numpy.ndarray
            ``(need,)`` gains, non-increasing.

        Examples
        --------
        >>> Target(0.0, 0.0, 0.5, 3).gains().tolist()
        [0.5, 0.5, 0.5]
        >>> Target(0.0, 0.0, 0.5, 2, curve=(0.1, 0.9, 0.4)).gains().tolist()
        [0.9, 0.4]
        """
        if self.curve:
            g = np.sort(np.asarray(self.curve, np.float64))[::-1]
            return g[: max(0, self.need)]
        return np.full(max(0, self.need), float(self.value))


@dataclass
class Blueprint:
    """The plan over the whole pass (see :func:`plan_blueprint`).

    Parameters
    ----------
    targets : list of Target
        Every candidate, in along-track order (the order they are visited in).
    budget : numpy.ndarray
        Pointings given to each target (0: given up).
    start_s, end_s : numpy.ndarray
        When the blueprint's sensor timeline starts and ends each chosen target (nan: not chosen).
    reserve : int
        Pointings of the pass's capacity kept for plumes the blueprint does not hold.
    value : float
        The blueprint's expected utility.
    slot_s : float
        The programme's time slot.
    info : dict
        Sizes of the programme (``slots``).
    step_s : numpy.ndarray
        Time of one more pointing on each target (:func:`step_s`).
    window : numpy.ndarray
        ``(n, 2)`` when each target enters and leaves the field of regard, pass seconds.
    """

    targets: list[Target]
    budget: np.ndarray
    start_s: np.ndarray
    end_s: np.ndarray
    reserve: int
    value: float
    slot_s: float
    info: dict[str, object] = field(default_factory=dict)
    step_s: np.ndarray = field(default_factory=lambda: np.zeros(0))
    window: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))

    @property
    def chosen(self) -> list[int]:
        """Indices of the targets the blueprint observes."""
        return [int(i) for i in np.flatnonzero(self.budget > 0)]


def step_s(
    geometry: OrbitGeometry,
    agility: Agility,
    along: np.ndarray,
    cross: np.ndarray,
    at: np.ndarray,
    px: float = STEP_PX,
) -> np.ndarray:
    """Time of one more pointing ``px`` WFOV pixels along track from the last: the loop's kinematics.

    The sensor tracks a ground point and takes the next one ``px`` pixels ahead,
    timed by :class:`dyntarget.schedule.Timer` exactly as the pass loop times it
    (slew between the two lines of sight at that time, settle, dwell).

    Parameters
    ----------
    geometry : the orbit (time 0: the pass's first frame).
    agility : the preset.
    along, cross : ground points, metres (pass coordinates at time 0).
    at : when, pass seconds.
    px : step, WFOV pixels.

    Returns
    -------
    numpy.ndarray: seconds per pointing.

    Examples
    --------
    >>> from dyntarget.schedule import get_agility
    >>> g = OrbitGeometry(wfov_gsd_m=64.0)
    >>> float(step_s(g, get_agility("slow"), np.array([0.0]), np.array([0.0]), np.array([0.0]))[0]) > 1.1
    True
    """
    along, cross = np.asarray(along, np.float64), np.asarray(cross, np.float64)
    at = np.asarray(at, np.float64)
    out = np.empty(along.shape)
    for n in range(len(along)):
        timer = Timer(geometry, agility)
        timer.take(float(along[n]), float(cross[n]), float(at[n]) - agility.dwell_s)
        nxt = float(along[n]) + px * geometry.wfov_gsd_m
        out[n] = timer.arrival_one(nxt, float(cross[n]), -math.inf) + agility.dwell_s - at[n]
    return out


def _transition(
    geometry: OrbitGeometry,
    agility: Agility,
    src: tuple[float, float] | None,
    free_s: np.ndarray,
    dst: tuple[float, float],
    t_in: float,
) -> np.ndarray:
    """When the sensor, free at each of ``free_s`` and tracking ``src`` (None: nadir), starts on ``dst``.

    :meth:`dyntarget.schedule.Timer.arrival`, vectorised over the departure times.
    """
    timer = Timer(geometry, agility)
    t = np.asarray(free_s, np.float64)
    timer.t = t  # type: ignore[assignment]  # Timer.arrival is elementwise in its time too
    timer.target = src
    n = len(t)
    return timer.arrival(np.full(n, dst[0]), np.full(n, dst[1]), np.full(n, t_in))


def plan_blueprint(  # noqa: C901, PLR0915  (one programme: slots, windows, transitions, walk back)
    targets: list[Target],
    geometry: OrbitGeometry,
    agility: Agility,
    *,
    horizon_s: float,
    reserve: float = 0.1,
) -> Blueprint:
    """Choose targets, their order and pointings per target over the whole pass.

    **Model: the pass loop's kinematics** (:mod:`dyntarget.schedule`, one code
    path). Target ``i`` may be observed inside its visibility window
    ``[in_i, out_i]`` (:func:`dyntarget.schedule.visibility_windows`); each
    pointing on it takes ``c_i`` (:func:`step_s`: a ``STEP_PX`` step timed by
    :class:`~dyntarget.schedule.Timer`), stretched by ``1 / (1 - reserve)``
    so that ``reserve`` of the time stays free for the look-ahead's own
    finds; moving from ``j`` (the sensor tracking it, free at time ``s``) to
    ``i`` takes what :meth:`~dyntarget.schedule.Timer.arrival` says for that
    departure time. The ``k``-th pointing on ``i`` is worth ``g_i[k]``
    (:meth:`Target.gains`, non-increasing).

    **Algorithm.** Time is cut into slots of ``min_i c_i``; ``P_j[s]`` is the
    best value of a plan whose last target is ``j`` with the sensor free by
    slot ``s`` (a running maximum: the sensor may wait). Targets are visited
    in along-track order::

        A_i[a] = max_j max {P_j[s] : arrival_ji(s) <= a}          a in [in_i, out_i]
        F_i[e] = max_k A_i[e - ceil(k q_i)] + g_i[1] + ... + g_i[k],  e <= out_i

    (``q_i = c_i / (1 - reserve)`` in slots), and the blueprint is the best
    ``P`` at the horizon, traced back. **Complexity** ``O(n^2 W + n K W)`` time
    (``W``: slots in the longest window, ``K``: the largest ``need``; each
    ``arrival`` a vectorised Timer call) and ``O(n T)`` memory for ``n``
    targets and ``T`` slots. Exact for this model up to the slot rounding
    (every time rounded up: a blueprint is always flyable by the Timer).

    Parameters
    ----------
    targets : the candidates (any order; visited in along-track order).
    geometry : the orbit (time 0: the pass's first frame).
    agility : the preset; ``unlimited`` gives every target its whole need.
    horizon_s : the pass duration the sensor may work, seconds.
    reserve : fraction of sensor time kept free for the look-ahead's own finds, in [0, 0.9].

    Returns
    -------
    Blueprint

    Examples
    --------
    >>> from dyntarget.schedule import get_agility
    >>> g = OrbitGeometry(wfov_gsd_m=64.0)
    >>> ts = [Target(300e3, 0.0, 1.0, 40), Target(320e3, 0.0, 2.0, 40)]  # 3 s apart
    >>> bp = plan_blueprint(ts, g, get_agility("slow"), horizon_s=80.0, reserve=0.0)
    >>> bp.budget.tolist()   # the richer one takes all the time left after the first slew
    [0, 19]
    >>> round(float(bp.start_s[1]), 1), round(float(bp.window[1, 1]), 1)  # ~17 s from nadir
    (17.1, 45.3)
    """
    if not (math.isfinite(horizon_s) and horizon_s > 0):
        raise InvalidParameterError(f"horizon_s: expected seconds > 0, got {horizon_s!r}")
    if not (0.0 <= reserve <= 0.9):
        raise InvalidParameterError(f"reserve: expected a fraction in [0, 0.9], got {reserve!r}")
    if len(targets) > MAX_TARGETS:
        raise InvalidParameterError(f"targets: {len(targets)}, more than {MAX_TARGETS}")
    ts = sorted(targets, key=lambda t: t.along_m)
    n = len(ts)
    budget = np.zeros(n, np.int64)
    start, end = np.full(n, np.nan), np.full(n, np.nan)
    along = np.array([t.along_m for t in ts], np.float64)
    cross = np.array([t.cross_m for t in ts], np.float64)
    t_in, t_out = visibility_windows(geometry, agility, along, cross)
    window = np.stack([t_in, t_out], axis=1) if n else np.zeros((0, 2))
    gains = [t.gains() for t in ts]
    if agility.unlimited or n == 0:
        budget[:] = [len(g) for g in gains]
        value = float(sum(g.sum() for g in gains))
        return Blueprint(ts, budget, start, end, 0, value, 0.0, {"slots": 0},
                         np.zeros(n), window)  # fmt: skip
    mid = np.clip((np.maximum(t_in, 0.0) + np.minimum(t_out, horizon_s)) / 2, 0.0, horizon_s)
    c = step_s(geometry, agility, along, cross, np.where(np.isfinite(mid), mid, 0.0))
    slot = float(c.min())
    T = math.ceil(horizon_s / slot) + 1
    q = c / (1.0 - reserve) / slot  # slots per pointing, >= 1
    lo = np.clip(np.ceil(np.maximum(t_in, 0.0) / slot - 1e-9), 0, T).astype(np.int64)
    E = np.floor(np.minimum(t_out, horizon_s) / slot + 1e-9)
    E = np.where(np.isfinite(t_out) & (t_in <= t_out), E, -1).astype(np.int64)
    E = np.minimum(E, T - 1)
    assert agility.field_of_regard_deg is not None  # limited agility (unlimited returned above)
    reach = agility.slew_time_one(2.0 * agility.field_of_regard_deg) + agility.settle_s
    neg = -np.inf
    P = np.full((n, T), neg)
    Parg = np.zeros((n, T), np.int64)  # slot achieving the running maximum
    Kbest = np.zeros((n, T), np.int64)
    Jbest = np.full((n, T), -1, np.int64)  # predecessor (-1: the start at nadir)
    Sbest = np.zeros((n, T), np.int64)  # its departure slot
    for i in range(n):
        if E[i] <= lo[i] or len(gains[i]) == 0 or gains[i][0] <= 0:
            continue
        arr = np.arange(lo[i], E[i])  # arrival slots: at least one pointing fits after
        A = np.full(len(arr), neg)
        J = np.full(len(arr), -1, np.int64)
        S = np.zeros(len(arr), np.int64)

        def relax(
            j: int,
            deps: np.ndarray,
            vals: np.ndarray,
            idx_arr: np.ndarray = arr,
            a_: np.ndarray = A,
            j_: np.ndarray = J,
            s_: np.ndarray = S,
            i_: int = i,
        ) -> None:
            src = None if j < 0 else (float(along[j]), float(cross[j]))
            t_a = _transition(geometry, agility, src, deps * slot, (along[i_], cross[i_]), t_in[i_])
            a_slot = np.ceil(t_a / slot - 1e-9).astype(np.int64)
            best = np.full(len(idx_arr), neg)
            who = np.zeros(len(idx_arr), np.int64)
            pos = a_slot - idx_arr[0]
            ok = pos < len(idx_arr)
            pos = np.maximum(pos, 0)
            for p, v, d in zip(pos[ok], vals[ok], deps[ok], strict=True):
                if v > best[p]:
                    best[p], who[p] = v, d
            run = np.maximum.accumulate(best)  # arrived earlier: wait
            at = np.where(best == run, np.arange(len(best)), 0)
            at = np.maximum.accumulate(at)
            better = run > a_
            a_[better], j_[better], s_[better] = run[better], j, who[at][better]

        relax(-1, np.array([0]), np.array([0.0]))
        far_v, far_j, far_s = neg, -1, 0  # predecessors done a whole slew before i opens
        for j in range(i):
            hi = min(int(E[j]), int(E[i]) - 1)
            if hi < lo[j] or not np.isfinite(P[j, hi]):
                continue
            if (hi + 1) * slot + reach <= t_in[i]:  # any departure arrives by in_i
                if P[j, hi] > far_v:
                    far_v, far_j, far_s = float(P[j, hi]), j, hi
                continue
            deps = np.arange(int(lo[j]), hi + 1)
            vals = P[j, deps]
            keep = np.isfinite(vals)
            relax(j, deps[keep], vals[keep])
        if far_j >= 0:
            relax(far_j, np.array([far_s]), np.array([far_v]))
        g = np.concatenate([[0.0], np.cumsum(gains[i])])
        K = min(len(g) - 1, int((E[i] - lo[i]) / q[i]) + 1)
        ks = np.arange(1, K + 1)
        d = np.ceil(ks * q[i] - 1e-9).astype(np.int64)
        fin = np.isfinite(A)
        e = arr[fin][:, None] + d[None, :]
        val = A[fin][:, None] + g[ks][None, :]
        ok = e <= E[i]
        e, val = e[ok], val[ok]
        kk = np.broadcast_to(ks[None, :], ok.shape)[ok]
        F = np.full(T, neg)
        Kf = np.zeros(T, np.int64)
        np.maximum.at(F, e, val)
        hit = val == F[e]
        Kf[e[hit][::-1]] = kk[hit][::-1]  # ties: the fewest pointings
        Kbest[i] = Kf
        Jbest[i, arr] = J
        Sbest[i, arr] = S
        P[i] = np.maximum.accumulate(F)
        idx = np.where(F == P[i], np.arange(T), 0)
        Parg[i] = np.maximum.accumulate(idx)
    last = P[:, T - 1]
    best_i = int(np.argmax(last)) if n else -1
    value = float(last[best_i]) if n and np.isfinite(last[best_i]) else 0.0
    if value > 0:
        i, e = best_i, int(Parg[best_i, T - 1])
        while i >= 0:
            k = int(Kbest[i, e])
            a = e - math.ceil(k * q[i] - 1e-9)
            budget[i] = k
            start[i], end[i] = a * slot, e * slot
            j, s = int(Jbest[i, a]), int(Sbest[i, a])
            if j < 0:
                break
            i, e = j, int(Parg[j, s])
    capacity = int(horizon_s / slot)
    reserve_n = int(reserve * capacity)
    return Blueprint(ts, budget, start, end, reserve_n, value, slot, {"slots": T}, c, window)
