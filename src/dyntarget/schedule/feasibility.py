"""Feasibility: pointings timed under the kinematics, those that cannot be taken dropped.

:func:`schedule` walks a trajectory in order, times every pointing and drops
those that cannot be taken inside their visibility window (or the budget);
with ``reorder=True`` it first sorts the pointings by the time they leave the
field of regard (earliest deadline first; the planner's order on ties), since
points the spacecraft passes first must be taken first. :func:`make_feasible`
flies whichever of the two keeps more pointings. The model: :mod:`dyntarget.schedule`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from dyntarget.errors import InvalidParameterError
from dyntarget.schedule.kinematics import (
    Agility,
    OrbitGeometry,
    _angle_deg,
    _look_one,
    angle_between_deg,
    get_agility,
    look_vectors,
    under_sight,
    visibility_windows,
)
from dyntarget.schedule.sensor import SensorState
from dyntarget.trajectory import Trajectory


@dataclass(frozen=True, eq=False)
class Schedule:
    """A trajectory re-timed under a geometry and an agility preset.

    ``trajectory`` holds the kept pointings in the order they are taken,
    ``times`` when each observation starts (s after the WFOV acquisition),
    ``kept`` their indices in the planned trajectory, ``planned`` how many
    pointings were planned. ``window_end_s`` is when the last planned point
    leaves the field of regard (``inf`` without limits).

    Parameters
    ----------
    trajectory : dyntarget.trajectory.Trajectory
        The kept pointings, timed, in the order taken.
    times : numpy.ndarray
        ``(k,)`` observation start times, seconds after the WFOV acquisition.
    kept : numpy.ndarray
        ``(k,)`` int64 indices of the kept pointings in the planned trajectory.
    planned : int
        Number of pointings planned.
    start_s : float
        When the sensor started, seconds.
    end_s : float
        When the sensor was free after the last observation, seconds.
    window_end_s : float
        When the last visible planned point leaves the field of regard, seconds.
    agility : str
        Name of the agility preset.
    end_target : tuple of float or None
        ``(along, cross)`` ground point the sensor tracks after the last observation
        (this geometry's frame, metres at ``t = 0``); ``None``: nothing taken, the
        sensor is where it started.
    end_height_m : float
        Height of the point it tracks, metres above ``end_target`` (a plume top; 0:
        the ground point).
    reordered : bool
        Whether the pointings were flown earliest-deadline-first (``reorder=True``).
    """

    trajectory: Trajectory
    times: np.ndarray
    kept: np.ndarray
    planned: int
    start_s: float
    end_s: float
    window_end_s: float
    agility: str
    end_target: tuple[float, float] | None = None
    reordered: bool = False
    end_height_m: float = 0.0

    @property
    def fraction_feasible(self) -> float:
        """Share of the planned pointings that were kept (1.0 for an empty plan)."""
        return len(self.kept) / self.planned if self.planned else 1.0

    @property
    def total_s(self) -> float:
        """From the plan's start to the end of the last observation."""
        return self.end_s - self.start_s

    @property
    def time_left_s(self) -> float:
        """Between the end of the last observation and the end of the window."""
        return self.window_end_s - self.end_s


class Timer:
    """Step-by-step timing of pointings: what the sensor tracks and when it is free.

    Between observations the sensor keeps tracking what it observed last, so a slew
    covers the angle between that and the next target as seen at the arrival time (from
    nadir for the first pointing). A target is a ground point, or a point at a height
    above one (``height_m``: a plume top, fixed above the ground, whose line of sight
    turns otherwise than that of the ground behind it).

    Parameters
    ----------
    geometry : OrbitGeometry
        The orbit and the start time (the sensor starts at nadir at ``start_s``).
    agility : Agility
        The sensor's kinematics.
    """

    def __init__(self, geometry: OrbitGeometry, agility: Agility) -> None:
        self.geometry, self.agility = geometry, agility
        self.t = geometry.start_s
        self.target: tuple[float, float] | None = None  # None: looking at nadir
        self.height = 0.0  # of the point tracked, metres above ``target``

    def _from(self, t: np.ndarray) -> np.ndarray:
        if self.target is None:
            return np.array([0.0, 0.0, -1.0])
        along, cross = np.asarray(self.target[0]), np.asarray(self.target[1])
        return look_vectors(self.geometry, along, cross, t, self.height)

    def arrival(
        self,
        along: np.ndarray,
        cross: np.ndarray,
        t_in: np.ndarray,
        height_m: float | np.ndarray = 0.0,
    ) -> np.ndarray:
        """When observations of the given targets could start if taken next (vectorised).

        Parameters
        ----------
        along : numpy.ndarray
            Along-track ground distances of the targets from nadir at ``t = 0``, metres.
        cross : numpy.ndarray
            Cross-track ground distances, metres.
        t_in : numpy.ndarray
            When each target enters the field of regard, seconds.
        height_m : float or numpy.ndarray
            Height of the targets above those ground points, metres (0: the ground).

        Returns
        -------
        numpy.ndarray
            Earliest observation start per target, seconds (slew and settle from the
            current target, and not before ``t_in``).
        """
        if self.agility.unlimited:  # no slews: when the sensor is free (and the target visible)
            free: np.ndarray = np.maximum(np.full(np.shape(along), self.t), t_in)
            return free
        ta = np.full(np.shape(along), self.t)
        for _ in range(4):  # the geometry changes during the slew: fixed-point iteration
            when = np.maximum(ta, t_in)
            angle = angle_between_deg(
                self._from(when), look_vectors(self.geometry, along, cross, when, height_m)
            )
            ta = self.t + self.agility.slew_time(angle) + self.agility.settle_s
        arrival: np.ndarray = np.maximum(ta, t_in)
        return arrival

    def arrival_one(self, along: float, cross: float, t_in: float, height_m: float = 0.0) -> float:
        """:meth:`arrival` for one target, in scalar arithmetic: the same floats, faster.

        Scheduling times pointings one after another, so this runs once per pointing;
        numpy's per-call overhead on one-element arrays was most of a frame's
        scheduling time. Every operation is the one :meth:`arrival` does, in the same
        order (``math.sin``/``cos``/``sqrt`` give numpy's results to the bit; the arc
        cosine stays numpy's), so the result is bit-identical (tested).

        Parameters
        ----------
        along, cross : float
            Along- and cross-track ground distances of the target from nadir at
            ``t = 0``, metres.
        t_in : float
            When the target enters the field of regard, seconds.
        height_m : float
            Height of the target above that ground point, metres (0: the ground).

        Returns
        -------
        float
            Earliest observation start, seconds.
        """
        if self.agility.unlimited:
            return max(float(self.t), t_in)
        ta = float(self.t)
        for _ in range(4):
            when = max(ta, t_in)
            origin = (
                (0.0, 0.0, -1.0)
                if self.target is None
                else _look_one(self.geometry, *self.target, when, self.height)
            )
            angle = _angle_deg(origin, _look_one(self.geometry, along, cross, when, height_m))
            ta = self.t + self.agility.slew_time_one(angle) + self.agility.settle_s
        return max(ta, t_in)

    def take(self, along: float, cross: float, start: float, height_m: float = 0.0) -> None:
        """Take an observation: the sensor dwells on the target from ``start`` and then tracks it.

        Parameters
        ----------
        along : float
            Along-track ground distance of the target from nadir at ``t = 0``, metres.
        cross : float
            Cross-track ground distance, metres.
        start : float
            When the observation starts, seconds (the sensor is free at ``start + dwell_s``).
        height_m : float
            Height of the target above that ground point, metres (a plume top; 0: the
            ground point).
        """
        self.t = start + self.agility.dwell_s
        self.target = (float(along), float(cross))
        self.height = float(height_m)


CHUNK = 32
"""Pointings :func:`schedule` screens at once (a speed setting; the result does not depend on it)."""


def schedule(
    trajectory: Trajectory,
    shape: tuple[int, int],
    geometry: OrbitGeometry,
    agility: Agility | str,
    *,
    reorder: bool = False,
    budget_s: float | None = None,
    sensor: SensorState | None = None,
) -> Schedule:
    """Time every pointing in order, dropping those that cannot be taken in their window.

    ``reorder``: first sort by the time each point leaves the field of regard.
    ``budget_s``: also drop pointings that would end later than ``start_s + budget_s``.
    ``sensor``: the sensor is busy until ``sensor.free_s`` and then slews from
    ``sensor.target`` (default: free at nadir at ``start_s``).

    A trajectory with ``heights`` aims each pointing at a plume top: its line of sight,
    at the time it was aimed for (its ``times``), meets the ground at its point and the
    top that high on the way (:func:`~dyntarget.schedule.kinematics.under_sight`). The
    sensor slews between those tops and tracks each after observing it (:class:`Timer`);
    their visibility windows are their ground points'. A trajectory with ``windows``
    takes each pointing only inside its own window as well (it waits for its start,
    tracking what it observed last).

    Pointings are screened :data:`CHUNK` at a time: while pointings are skipped the
    sensor's state does not change, so the first pointing of a chunk that can be
    taken is the one a pointing-by-pointing walk would take (the same floats).

    Parameters
    ----------
    trajectory : dyntarget.trajectory.Trajectory
        The plan, in WFOV pixels.
    shape : tuple of int
        The WFOV image's ``(H, W)``.
    geometry : OrbitGeometry
        The orbit, the scene's placement and the start time.
    agility : Agility or str
        The sensor's kinematics, or a preset name.
    reorder : bool
        Sort the pointings earliest deadline first before timing them.
    budget_s : float or None
        Time budget after ``geometry.start_s``, seconds; ``None`` for none.
    sensor : SensorState or None
        Where the sensor is when the plan starts (a pass: the pointings committed
        before); ``None``: free at nadir at ``geometry.start_s``.

    Returns
    -------
    Schedule
        The kept pointings, timed, with the trajectory's ``params`` plus ``agility``.

    Examples
    --------
    >>> t = Trajectory(np.array([[8.0, 8.0], [8.0, 8.0]]), np.zeros(2), "demo")
    >>> s = schedule(t, (16, 16), OrbitGeometry(), "unlimited", sensor=SensorState(3.0))
    >>> s.times.tolist()   # unlimited agility: every pointing when the sensor is free
    [3.0, 3.0]
    """
    agility = get_agility(agility) if isinstance(agility, str) else agility
    if budget_s is not None and not (budget_s >= 0 and math.isfinite(budget_s)):
        raise InvalidParameterError(
            f"budget_s: expected a number of seconds >= 0, got {budget_s!r}"
        )
    along, cross = geometry.ground(trajectory.points, shape)
    t_in, t_out = visibility_windows(geometry, agility, along, cross)
    visible = t_out[t_in <= t_out]  # the field of regard's, whatever the trajectory allows
    if trajectory.windows is not None:  # and only when the trajectory allows each
        t_in = np.maximum(t_in, trajectory.windows[:, 0])
        t_out = np.minimum(t_out, trajectory.windows[:, 1])
        t_out[np.isposinf(t_in)] = -np.inf  # never: not even without limits
    order = np.argsort(t_out, kind="stable") if reorder else np.arange(len(trajectory))
    limit = math.inf if budget_s is None else geometry.start_s + budget_s
    timer = Timer(geometry, agility)
    if sensor is not None:
        timer.t = max(geometry.start_s, sensor.free_s)
        if sensor.target is not None:
            timer.target = (float(sensor.target[0]), float(sensor.target[1]))
            timer.height = float(sensor.height_m)
        else:
            timer.target = None
    heights = trajectory.heights
    ta, tc = along, cross  # what the sensor slews to and tracks: the ground points, or tops
    if heights is not None:
        assert trajectory.times is not None  # heights come with the times they are for
        ta, tc = along.copy(), cross.copy()
        up = heights > 0
        ta[up], tc[up] = under_sight(
            geometry, along[up], cross[up], trajectory.times[up], heights[up]
        )
    kept, times = _walk(timer, order, ta, tc, t_in, t_out, limit, heights)
    kept_idx = np.asarray(kept, np.int64)
    keep_traj = Trajectory(
        trajectory.points[kept_idx],
        trajectory.part[kept_idx],
        trajectory.planner,
        {**trajectory.params, "agility": agility.name},
        np.asarray(times, np.float64),
        None if heights is None else heights[kept_idx],
        None if trajectory.windows is None else trajectory.windows[kept_idx],
    )
    return Schedule(
        trajectory=keep_traj,
        times=np.asarray(times, np.float64),
        kept=kept_idx,
        planned=len(trajectory),
        start_s=geometry.start_s,
        end_s=timer.t,
        window_end_s=float(visible.max()) if len(visible) else geometry.start_s,
        agility=agility.name,
        end_target=timer.target,
        reordered=bool(reorder),
        end_height_m=timer.height,
    )


def _walk(
    timer: Timer,
    order: np.ndarray,
    along: np.ndarray,
    cross: np.ndarray,
    t_in: np.ndarray,
    t_out: np.ndarray,
    limit: float,
    heights: np.ndarray | None = None,
) -> tuple[list[int], list[float]]:
    """Take the pointings of ``order`` that fit their window (and ``limit``), in order
    (``heights``: of the targets above ``along``, ``cross``; ``None``: the ground)."""
    agility = timer.agility
    kept: list[int] = []
    times: list[float] = []
    floor = agility.settle_s + agility.dwell_s  # a pointing ends at least this after timer.t
    pos = 0
    while pos < len(order):
        # the first pointing of the next CHUNK in order that can still be taken: the
        # timer does not move while pointings are skipped, so screening a chunk at
        # once (Timer.arrival is elementwise) gives exactly the one-by-one result
        chunk = order[pos : pos + CHUNK]
        maybe = (t_in[chunk] <= t_out[chunk]) & (timer.t + floor <= t_out[chunk])
        first = int(np.argmax(maybe))
        if maybe[first]:  # most often the first candidate is taken: time it alone
            j = int(chunk[first])
            h = 0.0 if heights is None else float(heights[j])
            start = timer.arrival_one(float(along[j]), float(cross[j]), float(t_in[j]), h)
            end = start + agility.dwell_s
            if end <= t_out[j] and end <= limit:
                timer.take(along[j], cross[j], start, h)
                kept.append(j)
                times.append(start)
                pos += first + 1
                continue
            maybe[first] = False  # timed above: it cannot be taken
        ok = np.zeros(len(chunk), bool)
        begin = np.zeros(len(chunk))
        if maybe.any():
            c = chunk[maybe]
            begin[maybe] = timer.arrival(
                along[c], cross[c], t_in[c], 0.0 if heights is None else heights[c]
            )
            end = begin[maybe] + agility.dwell_s
            ok[maybe] = (end <= t_out[c]) & (end <= limit)
        if not ok.any():
            pos += len(chunk)
            continue
        i = int(np.argmax(ok))
        j = int(chunk[i])
        timer.take(
            along[j], cross[j], float(begin[i]), 0.0 if heights is None else float(heights[j])
        )
        kept.append(j)
        times.append(float(begin[i]))
        pos += i + 1
    return kept, times


def make_feasible(
    trajectory: Trajectory,
    shape: tuple[int, int],
    geometry: OrbitGeometry,
    agility: Agility | str,
    *,
    budget_s: float | None = None,
    as_planned: Schedule | None = None,
    sensor: SensorState | None = None,
) -> Schedule:
    """The better of flying the plan in its own order and reordered earliest-deadline-first.

    Both are re-timed and trimmed by :func:`schedule`; the one that keeps more
    pointings wins (the planner's order on ties). Reordering rescues points a
    plan would visit too late, but interleaves transects across track and so
    costs slews; which matters more depends on the plan and the agility. Pass
    ``as_planned`` when that schedule (same arguments, no reordering) is already at hand.

    Parameters
    ----------
    trajectory : dyntarget.trajectory.Trajectory
        The plan, in WFOV pixels.
    shape : tuple of int
        The WFOV image's ``(H, W)``.
    geometry : OrbitGeometry
        The orbit, the scene's placement and the start time.
    agility : Agility or str
        The sensor's kinematics, or a preset name.
    budget_s : float or None
        Time budget after ``geometry.start_s``, seconds.
    as_planned : Schedule or None
        The schedule of the plan in its own order, if already computed.
    sensor : SensorState or None
        Where the sensor is when the plan starts (see :func:`schedule`).

    Returns
    -------
    Schedule
        The schedule that keeps more pointings.
    """
    if as_planned is None:
        as_planned = schedule(
            trajectory, shape, geometry, agility, budget_s=budget_s, sensor=sensor
        )
    reordered = schedule(
        trajectory, shape, geometry, agility, reorder=True, budget_s=budget_s, sensor=sensor
    )
    return reordered if len(reordered.kept) > len(as_planned.kept) else as_planned
