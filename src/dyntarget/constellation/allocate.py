"""Which satellite points at which plume on which overflight.

An *opportunity* is an overflight a satellite knows it may use (the cueing mode decides
what it knows, :mod:`dyntarget.constellation.simulate`). Its planned value is
``cos(off-nadir)``; its realized value is the same if the plume is there and visible
then, else 0 (the planners do not know the weather). Two observations of one eruption
less than ``dup_window_s`` apart are a *duplicate*: the later one is worth nothing.
One satellite's two targets conflict when :func:`dyntarget.schedule.make_feasible`
cannot fit both in their windows (slew, settle and dwell of the agility preset).

* :func:`greedy` (centralized): opportunities by planned value (then time), each taken
  unless it duplicates a taken one or conflicts with its satellite's taken targets.
* :func:`distributed`: each satellite decides alone, in order of decision time, from
  the board as it last heard it: it takes an opportunity unless the board shows
  another satellite's *claim* on the same eruption within the duplicate window
  (first claimant wins; a claim reaches the others with the board's delay, so two
  satellites deciding within that delay can both take it: the duplicates counted).
  Without a board it predicts the others' looks from the ephemerides (``predicted``).
* :func:`bound` (exact): the MILP ``max sum v x`` over realized values, ``x`` binary,
  ``x_a + x_b <= 1`` for every duplicate pair and every conflicting pair, solved by
  HiGHS (:func:`scipy.optimize.milp`). It knows the weather and the future, so it is an
  upper bound on what any allocation from the same knowledge can realize (pairwise
  sensor conflicts relax the timing of three or more close targets: still a bound).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from dyntarget.errors import InvalidParameterError

MAX_BOUND = 2000
"""Most opportunities :func:`bound` solves (larger instances are refused)."""
CLUSTER_S = 300.0
"""Two targets of one satellite further apart in time than this never conflict."""


@dataclass(frozen=True)
class Opportunities:
    """Opportunities as arrays (one entry each).

    Parameters
    ----------
    sat, eruption : numpy.ndarray
        Satellite and eruption indices.
    t_obs : numpy.ndarray
        Observation time, seconds.
    t_dec : numpy.ndarray
        When the satellite decides (distributed allocation), seconds.
    planned, value : numpy.ndarray
        Planned and realized utility.
    cue_src, cue_t : numpy.ndarray or None
        The detection that made each opportunity known: its source (satellite index, or
        negative for the ground) and when it was posted (distributed allocation).
    """

    sat: np.ndarray
    eruption: np.ndarray
    t_obs: np.ndarray
    t_dec: np.ndarray
    planned: np.ndarray
    value: np.ndarray
    cue_src: np.ndarray | None = None
    cue_t: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.sat)


Conflict = Callable[[int, int], bool]
"""``conflict(a, b)``: whether one satellite cannot take both opportunities ``a`` and ``b``."""


def _close(opp: Opportunities, a: int, b: int, window: float) -> bool:
    return bool(abs(opp.t_obs[a] - opp.t_obs[b]) < window)


def greedy(opp: Opportunities, *, dup_window_s: float, conflict: Conflict) -> list[int]:
    """Centralized greedy: highest planned value first.

    Parameters
    ----------
    opp : Opportunities
        The opportunities.
    dup_window_s : float
        Duplicate window, seconds.
    conflict : callable
        Sensor conflict between two opportunities of one satellite.

    Returns
    -------
    list of int
        Chosen opportunities, in time order.

    Examples
    --------
    >>> o = Opportunities(np.array([0, 1]), np.array([0, 0]), np.array([0.0, 60.0]),
    ...     np.zeros(2), np.array([0.8, 0.9]), np.array([0.8, 0.9]))
    >>> greedy(o, dup_window_s=600.0, conflict=lambda a, b: False)  # one of the two: the better
    [1]
    """
    order = np.lexsort((opp.sat, opp.t_obs, -opp.planned))
    taken: list[int] = []
    by_erupt: dict[int, list[int]] = {}
    by_sat: dict[int, list[int]] = {}
    for i in order.tolist():
        e, s = int(opp.eruption[i]), int(opp.sat[i])
        if any(_close(opp, i, j, dup_window_s) for j in by_erupt.get(e, [])):
            continue
        if any(_close(opp, i, j, CLUSTER_S) and conflict(i, j) for j in by_sat.get(s, [])):
            continue
        taken.append(i)
        by_erupt.setdefault(e, []).append(i)
        by_sat.setdefault(s, []).append(i)
    return sorted(taken, key=lambda i: (opp.t_obs[i], opp.sat[i]))


def distributed(
    opp: Opportunities,
    *,
    dup_window_s: float,
    conflict: Conflict,
    heard: Callable[[int, float, int], float],
    cued: Callable[[int, int, float], bool] | None = None,
    predicted: dict[int, list[tuple[float, int]]] | None = None,
) -> list[int]:
    """Each satellite decides alone from the board as it last heard it (claims, first wins).

    Besides the claims it has heard, a satellite predicts the others: every satellite
    carries the constellation's ephemerides, so it knows who flies over the eruption
    before it, and from the board it knows which of them have heard of the eruption
    (``cued``). Among those overflights, in time order, each is taken unless one taken
    before it is within the duplicate window (the rule every satellite applies, so they
    agree wherever they have heard the same news); it yields when that rule gives its
    overflight to someone else.

    Parameters
    ----------
    opp : Opportunities
        The opportunities.
    dup_window_s : float
        Duplicate window, seconds.
    conflict : callable
        Sensor conflict between two opportunities of one satellite.
    heard : callable
        ``heard(from_sat, t, to_sat)``: when a claim posted by ``from_sat`` at ``t``
        reaches ``to_sat`` (``inf``: never; the same satellite: at once).
    cued : callable or None
        ``cued(j, sat, t)``: whether satellite ``sat`` knows at ``t`` that opportunity
        ``j``'s satellite has heard of its eruption; ``None``: no prediction (claims only).
    predicted : dict or None
        Without a board (``none``, ``self``): per eruption, the overflights ``(t_obs,
        sat)`` whose look-ahead will pass over its vent, from the ephemerides alone
        (whether that look-ahead will see a plume is not known). A satellite yields where
        the time-ordered rule over them and its own overflight gives its overflight to
        another; ``None``: no such prediction.

    Returns
    -------
    list of int
        Chosen opportunities, in time order.

    Examples
    --------
    >>> o = Opportunities(np.array([0, 1]), np.array([0, 0]), np.array([0.0, 60.0]),
    ...     np.array([-100.0, -90.0]), np.ones(2), np.ones(2))
    >>> distributed(o, dup_window_s=600.0, conflict=lambda a, b: False,
    ...     heard=lambda s, t, r: t + 30.0)  # the claim arrives after the other decided
    [0, 1]
    >>> distributed(o, dup_window_s=600.0, conflict=lambda a, b: False,
    ...     heard=lambda s, t, r: t + 5.0)  # it arrives in time: the second yields
    [0]
    """
    order = np.lexsort((opp.sat, opp.t_obs, opp.t_dec))
    claims: dict[int, list[int]] = {}
    by_sat: dict[int, list[int]] = {}
    taken: list[int] = []
    by_e: dict[int, list[int]] = {}
    for j in np.lexsort((opp.sat, opp.t_obs)).tolist():
        by_e.setdefault(int(opp.eruption[j]), []).append(j)
    for i in order.tolist():
        e, s, t = int(opp.eruption[i]), int(opp.sat[i]), float(opp.t_dec[i])
        if cued is not None and not _mine(opp, i, s, t, by_e[e], dup_window_s, cued):
            continue
        if predicted is not None and not _first_predicted(
            float(opp.t_obs[i]), s, predicted.get(e, []), dup_window_s
        ):
            continue
        if any(
            _close(opp, i, j, dup_window_s) and heard(int(opp.sat[j]), float(opp.t_dec[j]), s) <= t
            for j in claims.get(e, [])
        ):
            continue
        if any(_close(opp, i, j, CLUSTER_S) and conflict(i, j) for j in by_sat.get(s, [])):
            continue
        taken.append(i)
        claims.setdefault(e, []).append(i)
        by_sat.setdefault(s, []).append(i)
    return sorted(taken, key=lambda i: (opp.t_obs[i], opp.sat[i]))


def _last_taken(times: list[float], dup_window_s: float) -> bool:
    """The rule every satellite applies: overflights in time order, each taken unless one
    taken before it is within the duplicate window; whether the last of ``times`` is taken."""
    last, taken = -math.inf, True
    for t_j in times:
        taken = t_j - last >= dup_window_s
        if taken:
            last = t_j
    return taken


def _first_predicted(
    t_i: float, s: int, overflights: list[tuple[float, int]], dup_window_s: float
) -> bool:
    """Whether the rule over predicted overflights and ``(t_i, s)`` gives it to ``s``."""
    ordered = sorted({*overflights, (t_i, s)})
    before = ordered[: ordered.index((t_i, s)) + 1]
    return _last_taken([t for t, _ in before if t_i - t < 3 * dup_window_s], dup_window_s)


def _mine(opp, i, s, t, same_e, dup_window_s, cued) -> bool:
    """Whether the time-ordered rule gives overflight ``i`` to its own satellite, as ``s`` sees it."""
    t_i = float(opp.t_obs[i])
    times = []
    for j in same_e:  # in time order
        t_j = float(opp.t_obs[j])
        if t_j > t_i or (t_j == t_i and j != i and opp.sat[j] > opp.sat[i]):
            break
        if t_i - t_j < 3 * dup_window_s and (j == i or cued(j, s, t)):
            times.append(t_j)
        if j == i:
            return _last_taken(times, dup_window_s)
    return True


def pairs(opp: Opportunities, *, dup_window_s: float, conflict: Conflict) -> list[tuple[int, int]]:
    """Every pair that cannot both count: duplicates of one eruption and sensor conflicts.

    Parameters
    ----------
    opp : Opportunities
        The opportunities.
    dup_window_s : float
        Duplicate window, seconds.
    conflict : callable
        Sensor conflict between two opportunities of one satellite.

    Returns
    -------
    list of tuple of int
        ``(a, b)`` with ``a < b``.

    Examples
    --------
    >>> o = Opportunities(np.array([0, 1]), np.array([0, 0]), np.array([0.0, 60.0]),
    ...     np.zeros(2), np.ones(2), np.ones(2))
    >>> pairs(o, dup_window_s=600.0, conflict=lambda a, b: False)
    [(0, 1)]
    """
    out = []
    order = np.argsort(opp.t_obs, kind="stable")
    t = opp.t_obs[order]
    reach = max(dup_window_s, CLUSTER_S)
    for ia, a in enumerate(order.tolist()):
        hi = int(np.searchsorted(t, t[ia] + reach, side="left"))
        for b in order[ia + 1 : hi].tolist():
            same_e = opp.eruption[a] == opp.eruption[b] and _close(opp, a, b, dup_window_s)
            same_s = opp.sat[a] == opp.sat[b] and _close(opp, a, b, CLUSTER_S) and conflict(a, b)
            if same_e or same_s:
                out.append((min(a, b), max(a, b)))
    return sorted(out)


def bound(
    opp: Opportunities, *, dup_window_s: float, conflict: Conflict, limit: int = MAX_BOUND
) -> tuple[list[int], float]:
    """The exact best realized utility (MILP, HiGHS) and a selection that reaches it.

    Parameters
    ----------
    opp : Opportunities
        The opportunities.
    dup_window_s : float
        Duplicate window, seconds.
    conflict : callable
        Sensor conflict between two opportunities of one satellite.
    limit : int
        Most opportunities solved.

    Returns
    -------
    chosen : list of int
        The selection, in time order.
    utility : float
        Its realized utility (the bound).

    Raises
    ------
    dyntarget.errors.InvalidParameterError
        When there are more than ``limit`` opportunities.

    Examples
    --------
    >>> o = Opportunities(np.zeros(3, int), np.array([0, 0, 0]), np.array([0.0, 400.0, 800.0]),
    ...     np.zeros(3), np.ones(3), np.array([0.6, 0.7, 0.6]))
    >>> bound(o, dup_window_s=600.0, conflict=lambda a, b: False)  # the two ends beat the middle
    ([0, 2], 1.2)
    """
    from scipy.optimize import Bounds, LinearConstraint, milp
    from scipy.sparse import coo_matrix

    if len(opp) > limit:
        raise InvalidParameterError(
            f"--allocation bound: {len(opp)} opportunities, more than the exact solver's "
            f"{limit}; use fewer satellites or hours (<= 10 satellites, 6 h) or greedy"
        )
    useful = np.flatnonzero(opp.value > 0)
    if not len(useful):
        return [], 0.0
    sub = Opportunities(
        opp.sat[useful],
        opp.eruption[useful],
        opp.t_obs[useful],
        opp.t_dec[useful],
        opp.planned[useful],
        opp.value[useful],
    )
    pr = pairs(
        sub,
        dup_window_s=dup_window_s,
        conflict=lambda a, b: conflict(int(useful[a]), int(useful[b])),
    )
    n = len(useful)
    constraints = []
    if pr:
        rows = np.repeat(np.arange(len(pr)), 2)
        cols = np.asarray(pr, np.int64).reshape(-1)
        a = coo_matrix((np.ones(len(cols)), (rows, cols)), shape=(len(pr), n)).tocsr()
        constraints.append(LinearConstraint(a, -np.inf, 1.0))
    res = milp(
        -sub.value,
        integrality=np.ones(n),
        bounds=Bounds(0, 1),
        constraints=constraints,
        options={"time_limit": 300.0},
    )
    if res.x is None or res.status != 0:
        raise InvalidParameterError(f"--allocation bound: HiGHS did not solve it ({res.message})")
    chosen = [int(useful[k]) for k in np.flatnonzero(res.x > 0.5).tolist()]
    chosen.sort(key=lambda i: (opp.t_obs[i], opp.sat[i]))
    return chosen, round(float(sum(opp.value[i] for i in chosen)), 12)


def brute_force(values: Sequence[float], excluded: Sequence[tuple[int, int]]) -> float:
    """Best total value of a subset with no excluded pair, by enumeration (tests; n <= 20).

    Parameters
    ----------
    values : sequence of float
        Value of each item.
    excluded : sequence of tuple of int
        Pairs that cannot both be chosen.

    Returns
    -------
    float
        The best total.

    Examples
    --------
    >>> brute_force([1.0, 2.0, 1.5], [(0, 1), (1, 2)])
    2.5
    """
    n = len(values)
    if n > 20:
        raise InvalidParameterError(f"brute_force: {n} items is too many to enumerate (<= 20)")
    best = 0.0
    for pick in itertools.product((0, 1), repeat=n):
        if any(pick[a] and pick[b] for a, b in excluded):
            continue
        best = max(best, math.fsum(v for v, p in zip(values, pick, strict=True) if p))
    return best
