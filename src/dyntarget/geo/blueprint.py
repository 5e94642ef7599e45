"""The blueprint: which GEO targets a pass observes, in what order, with how many pointings."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from dyntarget.errors import InvalidParameterError
from dyntarget.schedule import (
    Agility,
    OrbitGeometry,
    angle_between_deg,
    look_vectors,
    visibility_windows,
)

MAX_TARGETS = 2000


@dataclass(frozen=True)
class Target:
    """A plume candidate seen from GEO, in pass ground coordinates.

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
    """

    along_m: float
    cross_m: float
    value: float
    need: int
    span: tuple[float, float] = (0.0, 0.0)


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
        Pointings kept for plumes the look-ahead finds that the blueprint does not hold:
        ``reserve`` of the pass's capacity, or all the capacity its budgets leave unused
        if that is more (every pointing when there is no target at all).
    value : float
        The blueprint's expected utility.
    slot_s : float
        The DP's time slot (one pointing's time, with the reserve).
    info : dict
        Sizes of the programme (``slots``).
    """

    targets: list[Target]
    budget: np.ndarray
    start_s: np.ndarray
    end_s: np.ndarray
    reserve: int
    value: float
    slot_s: float
    info: dict = field(default_factory=dict)

    @property
    def chosen(self) -> list[int]:
        """Indices of the targets the blueprint observes."""
        return [int(i) for i in np.flatnonzero(self.budget > 0)]


def pointing_s(agility: Agility, geometry: OrbitGeometry) -> float:
    """Time of one more pointing on the same plume: a one-footprint slew, settle and dwell.

    Parameters
    ----------
    agility : the preset.
    geometry : its WFOV GSD and altitude set the footprint's angle.

    Returns
    -------
    float: seconds.

    Examples
    --------
    >>> from dyntarget.schedule import get_agility
    >>> round(pointing_s(get_agility("slow"), OrbitGeometry()), 3)
    1.271
    """
    step_deg = math.degrees(geometry.wfov_gsd_m / geometry.altitude_m)
    return agility.slew_time_one(step_deg) + agility.settle_s + agility.dwell_s


def plan_blueprint(  # noqa: PLR0915  (to split: slots, the programme, the walk back)
    targets: list[Target],
    geometry: OrbitGeometry,
    agility: Agility,
    *,
    horizon_s: float,
    reserve: float = 0.1,
) -> Blueprint:
    """Choose targets, their order and pointings per target over the whole pass.

    **Algorithm.** Sensor time is cut into slots of one pointing's time
    ``c / (1 - reserve)`` (:func:`pointing_s`, stretched so that ``reserve`` of
    the time stays free for the look-ahead), ``T = horizon_s / slot`` of them.
    Targets are visited in along-track order; target ``i`` may be observed in
    its visibility window ``[in_i, out_i]`` (:func:`dyntarget.schedule.visibility_windows`);
    moving from ``j`` to ``i`` costs ``tr_ji`` slots: the slew between their lines
    of sight when ``i`` becomes visible, plus settling
    (:meth:`~dyntarget.schedule.Agility.slew_time_one`). With ``F_j[s]`` the best
    value of a plan whose last target is ``j`` and that frees the sensor at slot
    ``s``, and ``P_j`` its running maximum over ``s`` (waiting is allowed)::

        A_i[a] = max_j P_j[a - tr_ji]                  (arrive at i by slot a >= in_i)
        F_i[e] = max_{1 <= k <= need_i} A_i[e - k] + value_i * k,   e - 1 <= out_i

    and the blueprint is the best ``F`` over all ``i`` (or nothing), traced back.
    It is exact for this model (slots, along-track order, a slew computed at
    the window's opening). **Complexity** ``O(n^2 T + n K T)`` time and
    ``O(n T)`` memory for ``n`` targets and ``K`` the largest ``need``.

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
    >>> g = OrbitGeometry(wfov_gsd_m=32.0)
    >>> ts = [Target(300e3, 0.0, 1.0, 40), Target(320e3, 0.0, 2.0, 40)]  # 33 s to slew there
    >>> bp = plan_blueprint(ts, g, get_agility("slow"), horizon_s=120.0, reserve=0.0)
    >>> bp.budget.tolist(), bp.value > 0
    ([0, 10], True)
    """
    if not (math.isfinite(horizon_s) and horizon_s > 0):
        raise InvalidParameterError(f"horizon_s: expected seconds > 0, got {horizon_s!r}")
    if not (0.0 <= reserve <= 0.9):
        raise InvalidParameterError(f"reserve: expected a fraction in [0, 0.9], got {reserve!r}")
    if len(targets) > MAX_TARGETS:
        raise InvalidParameterError(f"targets: {len(targets)}, more than {MAX_TARGETS}")
    order = sorted(range(len(targets)), key=lambda i: targets[i].along_m)
    ts = [targets[i] for i in order]
    n = len(ts)
    budget = np.zeros(n, np.int64)
    start, end = np.full(n, np.nan), np.full(n, np.nan)
    c = pointing_s(agility, geometry)
    capacity = int(horizon_s / c) if c > 0 else 10**9  # pointings the whole pass could take
    if agility.unlimited or n == 0:
        budget[:] = [t.need for t in ts]
        value = float(sum(t.value * t.need for t in ts))
        return Blueprint(ts, budget, start, end, capacity, value, 0.0, {"slots": 0})
    slot = c / (1.0 - reserve)
    T = math.ceil(horizon_s / slot) + 1
    along = np.array([t.along_m for t in ts])
    cross = np.array([t.cross_m for t in ts])
    t_in, t_out = visibility_windows(geometry, agility, along, cross)
    lo = np.clip(np.ceil(np.maximum(t_in, 0.0) / slot), 0, T).astype(np.int64)
    hi = np.where(np.isfinite(t_out), np.floor(np.minimum(t_out, horizon_s) / slot), -1)
    hi = hi.astype(np.int64)
    when = np.where(np.isfinite(t_in), np.maximum(t_in, 0.0), 0.0)
    los = look_vectors(geometry, along, cross, when)  # (n, 3): each at its window's opening
    nadir = np.array([0.0, 0.0, -1.0])

    def tr(j: int, i: int) -> int:  # slots to move from j (-1: nadir) to i
        a = los[i] if los.ndim > 1 else los
        b = nadir if j < 0 else look_vectors(geometry, along[j], cross[j], when[i])
        ang = float(angle_between_deg(np.asarray(b), np.asarray(a)))
        return math.ceil((agility.slew_time_one(ang) + agility.settle_s) / slot - 1e-9)

    neg = -np.inf
    P = np.full((n + 1, T), neg)  # row n: the start (free at slot 0, value 0)
    Parg = np.zeros((n + 1, T), np.int64)  # slot achieving the running maximum
    P[n] = 0.0
    Kbest = np.zeros((n, T), np.int64)
    Jbest = np.full((n, T), -1, np.int64)
    for i in range(n):
        a0, a1 = lo[i], min(hi[i], T - 1)
        if a1 < a0 or ts[i].need < 1 or ts[i].value <= 0:
            continue
        arr = np.arange(a0, a1 + 1)
        A = np.full(len(arr), neg)
        J = np.full(len(arr), -1, np.int64)
        for j in [n, *range(i)]:
            d = tr(-1 if j == n else j, i)
            src = arr - d
            ok = src >= 0
            cand = np.full(len(arr), neg)
            cand[ok] = P[j, src[ok]]
            better = cand > A
            A[better], J[better] = cand[better], j
        # F[e] = u e + max_{a in [e - K, e - 1], a0 <= a <= a1} (A[a] - u a): a sliding
        # maximum over the last K arrivals (K = need), in one vectorised pass
        u, K = ts[i].value, ts[i].need
        B = A - u * arr
        pad = np.concatenate([np.full(K - 1, neg), B])
        win = np.lib.stride_tricks.sliding_window_view(pad, K)  # win[m]: B[m-K+1 .. m]
        best = win.max(axis=1)
        kk = 1 + np.argmax(win[:, ::-1] == best[:, None], axis=1)  # ties: the fewest pointings
        F = np.full(T, neg)
        Kfull = np.zeros(T, np.int64)
        ends = arr + 1  # ends - 1 = m, the last arrival slot in the window
        ok = ends < T
        F[ends[ok]] = best[ok] + u * ends[ok]
        Kfull[ends[ok]] = kk[ok]
        Jfull = np.full(T, -1, np.int64)
        Jfull[arr] = J
        Kbest[i], Jbest[i] = Kfull, Jfull
        # running maximum over slots (the sensor may idle after e)
        P[i] = np.maximum.accumulate(F)
        idx = np.where(F == P[i], np.arange(T), 0)
        Parg[i] = np.maximum.accumulate(idx)
    best_i = int(np.argmax(P[:n, T - 1])) if n else -1
    value = float(P[best_i, T - 1]) if n and np.isfinite(P[best_i, T - 1]) else 0.0
    if value > 0:
        i, e = best_i, int(Parg[best_i, T - 1])
        while i != n:
            k = int(Kbest[i, e])
            a = e - k
            budget[i] = k
            start[i], end[i] = a * slot, e * slot
            j = int(Jbest[i, a])
            if j == n:
                break
            s = a - tr(j, i)
            e = int(Parg[j, s])
            i = j
    # the reserve: the stated fraction, or all the time the blueprint leaves unused if more
    reserve_n = max(int(reserve * capacity), capacity - int(budget.sum()))
    return Blueprint(ts, budget, start, end, reserve_n, value, slot, {"slots": T})
