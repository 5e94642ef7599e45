"""Schedules of a plan drawn on a predicted plume: each pointing placed for its own time.

A plan drawn on the plume as it will be ``lead_s`` seconds after the acquisition
is scheduled, every pointing moved on to where the plume is at its scheduled time,
and scheduled again, until the times settle (:func:`schedule_on_prediction`). The
prediction is anything with ``lead_s`` and ``pointing_shift`` (:class:`PlumeForecast`,
e.g. :class:`dyntarget.predict.Prediction`): the schedule stage does not import the
predict stage.

With a :class:`~dyntarget.schedule.ParallaxAim` every pointing is moved as well by the
parallax between the look-ahead's view and the NFOV's at its scheduled time (the plume
top it aims at is seen elsewhere from there); the two moves add, and the iteration runs
with the aim alone too.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Protocol

import numpy as np

from dyntarget.errors import InvalidParameterError
from dyntarget.schedule.aim import ParallaxAim
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


def schedule_on_prediction(  # noqa: PLR0913 (the scheduling seam: every caller's options, keyword-only)
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
    aim: ParallaxAim | None = None,
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

    With an ``aim``, each pointing is also moved by ``aim.shift`` at its time (the
    parallax correction, :class:`~dyntarget.schedule.ParallaxAim`), with or without a
    prediction; the params then record ``parallax_iterations`` and
    ``parallax_residual_px`` (the largest gap, both moves together).

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
    aim : dyntarget.schedule.ParallaxAim or None
        Also correct every pointing for parallax at its own time (``None``: no
        correction, exactly as before). When moving the pointings keeps changing which
        fit, the last selection is settled flown in its order (see
        :func:`iterate_on_prediction`).

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

    if prediction is None and aim is None:
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
        aim=aim,
        in_order=lambda t: schedule(t, shape, geometry, agility, budget_s=budget_s, sensor=sensor),
    )
    return sched


def iterate_on_prediction(
    trajectory: Trajectory,
    prediction: PlumeForecast | None,
    schedule: Callable[[Trajectory], Schedule],
    *,
    max_iterations: int = 8,
    tolerance_s: float = 0.05,
    attached: np.ndarray | None = None,
    aim: ParallaxAim | None = None,
    in_order: Callable[[Trajectory], Schedule] | None = None,
) -> tuple[Trajectory, Schedule]:
    """:func:`schedule_on_prediction` with any scheduler ``schedule(trajectory) -> Schedule``.

    Returns ``(moved, schedule)``: the whole planned trajectory with every pointing
    moved on to its (last estimated) time, and its schedule (``schedule(moved)``).

    Parameters
    ----------
    trajectory : dyntarget.trajectory.Trajectory
        The plan drawn on the prediction.
    prediction : dyntarget.predict.Prediction or None
        The one the plan was drawn on (``None`` only with an ``aim``).
    schedule : callable
        ``schedule(trajectory) -> Schedule``.
    max_iterations : int
        Most schedule-and-move rounds (at least 1).
    tolerance_s : float
        Stop when no kept pointing's time changes by more than this, seconds.
    attached : numpy.ndarray or None
        Boolean ``(H, W)`` mask (``prediction.attached_mask``): with ``mixed``
        plumes, pointings inside it are not moved.
    aim : dyntarget.schedule.ParallaxAim or None
        Also move every pointing by ``aim.shift`` of where it aims (the planned point
        plus the prediction's move) at its time. The first round uses ``lead_s``
        (without a prediction ``0``, the acquisition: no move), or the start of the
        pointing's window (:meth:`~dyntarget.schedule.ParallaxAim.windows`) if later;
        every round flies each pointing only inside its window. A pointing never kept
        keeps its estimate (the times its neighbours in the plan are flown). Moving a
        pointing can change which pointings fit, and in which order: when the rounds do not
        settle, the last round's selection is settled alone, flown in its order by
        ``in_order`` (dropping what no longer fits), so the pointings flown aim for their
        own times (up to ``max_iterations`` rounds more).
    in_order : callable or None
        With an ``aim``: ``in_order(trajectory) -> Schedule`` flying the pointings in the
        order given (no reordering; e.g. :func:`dyntarget.schedule.schedule`), used to
        settle; ``None``: ``schedule`` itself.

    Returns
    -------
    moved : dyntarget.trajectory.Trajectory
        Every planned pointing moved on to its time.
    schedule : dyntarget.schedule.Schedule
        ``schedule(moved)``, with ``prediction_iterations`` and
        ``prediction_residual_px`` in its trajectory's ``params`` (with an ``aim``,
        ``parallax_iterations`` and ``parallax_residual_px``, and the prediction's two
        where there is one).

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
    if aim is not None:
        return _iterate_with_aim(
            trajectory, prediction, schedule, aim, max_iterations, tolerance_s, attached, in_order
        )
    if prediction is None:
        raise InvalidParameterError("prediction: expected a prediction (or an aim), got None")
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


def _iterate_with_aim(
    trajectory: Trajectory,
    prediction: PlumeForecast | None,
    schedule: Callable[[Trajectory], Schedule],
    aim: ParallaxAim,
    max_iterations: int,
    tolerance_s: float,
    attached: np.ndarray | None,
    in_order: Callable[[Trajectory], Schedule] | None,
) -> tuple[Trajectory, Schedule]:
    """:func:`iterate_on_prediction` with a parallax aim (and maybe no prediction)."""
    if not isinstance(aim, ParallaxAim):
        raise InvalidParameterError(f"aim: expected a ParallaxAim, got {type(aim).__name__}")
    base = trajectory.points
    lead = 0.0 if prediction is None else prediction.lead_s
    windows = aim.windows(base)  # when each pointing's height is known (None: any time)
    start = np.full(len(trajectory), lead)  # the first estimate of each pointing's time:
    if windows is not None:  # not before it may be flown
        known = np.isfinite(windows[:, 0])
        start[known] = np.maximum(start[known], windows[known, 0])

    def target(points: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Where pointings planned at ``points`` must aim when flown at ``t``, and the
        height of the top each is aimed at (the NFOV tracks it after observing it)."""
        seen: np.ndarray = points
        if prediction is not None:
            seen = points + prediction.pointing_shift(t - lead, points, attached)
        shift, heights = aim.move(seen, t)
        return seen + shift, heights

    def rounds(
        idx: np.ndarray, times: np.ndarray, fly: Callable[[Trajectory], Schedule], *, shrink: bool
    ) -> _Rounds:
        """Schedule-and-move rounds over the pointings ``idx`` (``times``: first estimates);
        ``shrink``: each round keeps only the pointings the last one kept, in its order."""
        iterations = 0
        while True:
            iterations += 1
            moved, heights = target(base[idx], times)
            sched = fly(
                Trajectory(  # aimed for ``times``: the tops the NFOV slews between
                    moved, trajectory.part[idx], trajectory.planner, dict(trajectory.params),
                    times, heights, None if windows is None else windows[idx],
                )
            )  # fmt: skip
            used = times[sched.kept]
            change = float(np.max(np.abs(sched.times - used))) if len(sched.kept) else 0.0
            times = times.copy()
            times[sched.kept] = sched.times
            done = change <= tolerance_s and (not shrink or len(sched.kept) == len(idx))
            if done or iterations >= max_iterations or not len(sched.kept):
                return _Rounds(idx, moved, sched, used, iterations, change)
            if shrink:
                idx, times = idx[sched.kept], sched.times.copy()
            else:  # the dropped: about when their neighbours in the plan are flown
                order = np.argsort(sched.kept)
                dropped = np.setdiff1d(np.arange(len(times)), sched.kept)
                times[dropped] = np.interp(dropped, sched.kept[order], sched.times[order])
                if windows is not None:  # not before they may be flown
                    times[dropped] = np.maximum(times[dropped], start[idx][dropped])

    first = rounds(np.arange(len(trajectory)), start, schedule, shrink=False)
    moved, sched, used, iterations = first.moved, first.schedule, first.used, first.iterations
    if first.change > tolerance_s and len(sched.kept):
        # the rounds cycle between selections (moving the pointings changes which fit, and
        # in which order): settle the last selection alone, flown in its order, dropping
        # what no longer fits, until its times settle
        last = rounds(sched.kept, sched.times.copy(), in_order or schedule, shrink=True)
        moved = moved.copy()
        moved[last.idx] = last.moved
        sched = replace(
            last.schedule,
            kept=last.idx[last.schedule.kept],
            planned=len(trajectory),
            window_end_s=sched.window_end_s,
        )
        used, iterations = last.used, iterations + last.iterations
    gap = target(base[sched.kept], sched.times)[0] - sched.trajectory.points
    residual = float(np.max(np.hypot(*gap.T), initial=0.0))
    params = sched.trajectory.params
    if prediction is not None:
        only = prediction.pointing_shift(sched.times - used, base[sched.kept], attached)
        params.update(
            prediction_iterations=iterations,
            prediction_residual_px=float(np.max(np.hypot(*only.T), initial=0.0)),
        )
    params.update(parallax_iterations=iterations, parallax_residual_px=residual)
    whole = Trajectory(moved, trajectory.part, trajectory.planner, dict(trajectory.params))
    return whole, sched


@dataclass(frozen=True)
class _Rounds:
    """What :func:`_iterate_with_aim`'s rounds end with (over a subset's own indices)."""

    idx: np.ndarray
    moved: np.ndarray
    schedule: Schedule
    used: np.ndarray
    iterations: int
    change: float
