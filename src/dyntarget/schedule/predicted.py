"""Schedules of a plan drawn on a predicted plume: each pointing placed for its own time.

A plan drawn on the plume as it will be ``lead_s`` seconds after the acquisition
is scheduled, every pointing moved on to where the plume is at its scheduled time,
and scheduled again, until the times settle (:func:`schedule_on_prediction`). The
prediction is anything with ``lead_s`` and ``pointing_shift`` (:class:`PlumeForecast`,
e.g. :class:`dyntarget.predict.Prediction`): the schedule stage does not import the
predict stage.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol

import numpy as np

from dyntarget.errors import InvalidParameterError
from dyntarget.schedule.feasibility import Schedule, make_feasible, schedule
from dyntarget.schedule.kinematics import Agility, OrbitGeometry
from dyntarget.schedule.sensor import SensorState
from dyntarget.trajectory import Trajectory


class PlumeForecast(Protocol):
    """What scheduling on a prediction needs of it (:class:`dyntarget.predict.Prediction`)."""

    @property
    def lead_s(self) -> float:
        """Seconds after the acquisition the plan was drawn for."""
        ...

    def pointing_shift(
        self,
        dt_s: np.ndarray,
        points: np.ndarray | None = None,
        attached: np.ndarray | None = None,
    ) -> np.ndarray:
        """``(N, 2)`` pixels each pointing moves in ``dt_s`` seconds.

        Parameters
        ----------
        dt_s : numpy.ndarray
            ``(N,)`` seconds after :attr:`lead_s` at which each pointing is flown
            (negative: before it).
        points : numpy.ndarray or None
            ``(N, 2)`` float pointings ``(x, y)``, pixels of the WFOV image the plan
            was drawn on (column, row); where given, a dense motion field is sampled
            there, and with ``mixed`` plumes they tell which pointings lie in
            ``attached``.
        attached : numpy.ndarray or None
            Boolean ``(H, W)`` mask of where the plumes attached to their source
            will be at :attr:`lead_s` (``Prediction.attached_mask``); with ``mixed``
            plumes, pointings inside it do not move.

        Returns
        -------
        numpy.ndarray
            ``(N, 2)`` float64 shifts ``(dx, dy)``, WFOV pixels, to add to the
            pointings (zero for a pointing that stays, e.g. on an attached plume).
        """
        ...


def schedule_on_prediction(
    trajectory: Trajectory,
    shape: tuple[int, int],
    geometry: OrbitGeometry,
    agility: Agility | str,
    prediction: PlumeForecast | None,
    *,
    budget_s: float | None = None,
    max_iterations: int = 8,
    tolerance_s: float = 0.05,
    attached: np.ndarray | None = None,
    sensor: SensorState | None = None,
    keep_order: bool = False,
    as_planned: Schedule | None = None,
) -> Schedule:
    """Schedule a plan drawn on a prediction, each pointing placed for its own time.

    The plan was drawn for the plume at ``prediction.lead_s``; a pointing flown
    at ``t`` must aim where that part of the plume is at ``t``. Plan and schedule
    are iterated: schedule (:func:`~dyntarget.schedule.make_feasible`),
    move every pointing by ``prediction.pointing_shift(t - lead_s)``, schedule
    again, until no kept pointing's time changes by more than ``tolerance_s`` (or
    ``max_iterations``). The returned schedule flies the moved pointings; its
    trajectory's ``params`` record ``prediction_iterations`` and
    ``prediction_residual_px`` (the largest gap, in pixels, between where a kept
    pointing aims and where the plume is at its final time). Without a
    prediction: :func:`~dyntarget.schedule.make_feasible` once.

    Parameters
    ----------
    trajectory : Trajectory
        The plan from :func:`plan_scene` with ``prediction=``.
    shape : tuple of int
        ``(H, W)`` of the WFOV image.
    geometry, agility
        As for :func:`dyntarget.schedule.schedule`.
    prediction : Prediction or None
        The one the plan was drawn on (``None``: the plume as seen).
    budget_s : float or None
        As for :func:`~dyntarget.schedule.make_feasible`.
    max_iterations : int
        Most schedule-and-move rounds (at least 1).
    tolerance_s : float
        Stop when no kept pointing's time changes by more than this, seconds.
    attached : numpy.ndarray or None
        With ``mixed`` plumes, ``prediction.attached_mask(mask)`` of the
        denoised current mask: pointings there are not moved (see
        :meth:`~dyntarget.predict.Prediction.pointing_shift`).
    sensor : dyntarget.schedule.SensorState or None
        Where the sensor is when the plan starts (a pass: behind the pointings
        already committed); ``None``: free at nadir at ``geometry.start_s``.
    keep_order : bool
        After the first round, keep the order it chose (the plan's own or
        earliest-deadline-first) instead of choosing again each round (the pass
        loop does: the rounds then converge on one order).
    as_planned : Schedule or None
        The schedule of the plan in its own order, when already at hand (without a
        prediction only: :func:`~dyntarget.schedule.make_feasible` reuses it).

    Returns
    -------
    Schedule
        The schedule of the moved pointings.

    Examples
    --------
    >>> from dyntarget.schedule import OrbitGeometry
    >>> from dyntarget.predict import Motion, Prediction
    >>> traj = Trajectory(np.array([[10.0, 10.0], [20.0, 10.0]]), np.zeros(2), "demo")
    >>> p = Prediction(Motion((0.5, 0.0)), 0.0)
    >>> s = schedule_on_prediction(traj, (32, 32), OrbitGeometry(start_s=4.0), "unlimited", p)
    >>> s.trajectory.points[:, 0].tolist()  # flown at t = 4 s: moved 0.5 px/s x 4 s
    [12.0, 22.0]
    """
    chosen: list[bool] = []

    def fly(t: Trajectory) -> Schedule:
        if keep_order and chosen:
            return schedule(
                t, shape, geometry, agility, reorder=chosen[0], budget_s=budget_s, sensor=sensor
            )
        s = make_feasible(t, shape, geometry, agility, budget_s=budget_s, sensor=sensor)
        chosen.append(s.reordered)
        return s

    if prediction is None:
        return make_feasible(
            trajectory, shape, geometry, agility, budget_s=budget_s, sensor=sensor,
            as_planned=as_planned,
        )  # fmt: skip
    _, sched = iterate_on_prediction(
        trajectory,
        prediction,
        fly,
        max_iterations=max_iterations,
        tolerance_s=tolerance_s,
        attached=attached,
    )
    return sched


def iterate_on_prediction(
    trajectory: Trajectory,
    prediction: PlumeForecast,
    schedule: Callable[[Trajectory], Schedule],
    *,
    max_iterations: int = 8,
    tolerance_s: float = 0.05,
    attached: np.ndarray | None = None,
) -> tuple[Trajectory, Schedule]:
    """:func:`schedule_on_prediction` with any scheduler ``schedule(trajectory) -> Schedule``.

    Returns ``(moved, schedule)``: the whole planned trajectory with every pointing
    moved on to its (last estimated) time, and its schedule (``schedule(moved)``).

    Parameters
    ----------
    trajectory : dyntarget.trajectory.Trajectory
        The plan drawn on the prediction.
    prediction : dyntarget.predict.Prediction
        The one the plan was drawn on.
    schedule : callable
        ``schedule(trajectory) -> Schedule``.
    max_iterations : int
        Most schedule-and-move rounds (at least 1).
    tolerance_s : float
        Stop when no kept pointing's time changes by more than this, seconds.
    attached : numpy.ndarray or None
        Boolean ``(H, W)`` mask (``prediction.attached_mask``): with ``mixed``
        plumes, pointings inside it are not moved.

    Returns
    -------
    moved : dyntarget.trajectory.Trajectory
        Every planned pointing moved on to its time.
    schedule : dyntarget.schedule.Schedule
        ``schedule(moved)``, with ``prediction_iterations`` and
        ``prediction_residual_px`` in its trajectory's ``params``.

    Examples
    --------
    >>> from dyntarget.predict import Motion, Prediction
    >>> from dyntarget.schedule import OrbitGeometry, make_feasible
    >>> traj = Trajectory(np.array([[10.0, 10.0]]), np.zeros(1), "demo")
    >>> fly = lambda t: make_feasible(t, (32, 32), OrbitGeometry(start_s=2.0), "unlimited")
    >>> moved, s = iterate_on_prediction(traj, Prediction(Motion((0.0, 1.0)), 0.0), fly)
    >>> moved.points.tolist()
    [[10.0, 12.0]]
    """
    if not isinstance(max_iterations, int) or max_iterations < 1:
        raise InvalidParameterError(f"max_iterations: expected an int >= 1, got {max_iterations!r}")
    base = trajectory.points
    times = np.full(len(trajectory), prediction.lead_s)
    iterations = 0
    while True:
        iterations += 1
        moved = Trajectory(
            base + prediction.pointing_shift(times - prediction.lead_s, base, attached),
            trajectory.part, trajectory.planner, dict(trajectory.params),
        )  # fmt: skip
        sched = schedule(moved)
        used = times[sched.kept]
        change = float(np.max(np.abs(sched.times - used))) if len(sched.kept) else 0.0
        times = times.copy()
        times[sched.kept] = sched.times
        if change <= tolerance_s or iterations >= max_iterations:
            break
    residual = float(
        np.max(
            np.hypot(*prediction.pointing_shift(sched.times - used, base[sched.kept], attached).T),
            initial=0.0,
        )
    )
    sched.trajectory.params.update(
        prediction_iterations=iterations, prediction_residual_px=residual
    )
    return moved, sched
