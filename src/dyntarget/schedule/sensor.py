"""The NFOV sensor's state between plans: when it is free and what it tracks."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from dyntarget.errors import InvalidParameterError
from dyntarget.schedule.kinematics import Agility, OrbitGeometry, visibility_windows


@dataclass(frozen=True)
class SensorState:
    """What the NFOV is doing when a plan starts, when it is not idle at nadir.

    A pass schedules frame after frame on one sensor: a new plan queues behind the
    pointings already committed, and its first slew starts from the ground point
    the sensor tracks then.

    Parameters
    ----------
    free_s : float
        When the sensor is free, seconds in the schedule's time (not before the
        geometry's ``start_s``: the later of the two is used).
    target : tuple of float or None
        ``(along, cross)`` ground point it tracks, metres from nadir at ``t = 0`` in
        the schedule's geometry; ``None``: it looks at nadir.
    height_m : float
        Height of the point it tracks above ``target``, metres (a plume top it last
        observed; 0: the ground point).
    """

    free_s: float
    target: tuple[float, float] | None = None
    height_m: float = 0.0

    def __post_init__(self) -> None:
        if not math.isfinite(self.free_s):
            raise InvalidParameterError(f"free_s: expected a finite number, got {self.free_s!r}")
        if not (math.isfinite(self.height_m) and self.height_m >= 0):
            raise InvalidParameterError(f"height_m: expected metres >= 0, got {self.height_m!r}")


def sensor_in_frame(
    free_s: float,
    target: tuple[float, float] | None,
    geometry: OrbitGeometry,
    acquired_s: float,
    ready_s: float,
    height_m: float = 0.0,
) -> SensorState:
    """A pass's shared NFOV as seen from one frame (acquired ``acquired_s`` into the pass).

    A pass keeps the sensor in its own time and ground coordinates (along track from
    nadir at ``t = 0``); a frame's schedule counts time from the frame's acquisition and
    ground from nadir then.

    Parameters
    ----------
    free_s : float
        When the sensor is free, seconds into the pass.
    target : tuple of float or None
        ``(along, cross)`` it tracks in the pass's ground coordinates, metres
        (``None``: nadir).
    geometry : OrbitGeometry
        The frame's geometry (its ground speed).
    acquired_s : float
        When the frame was acquired, seconds into the pass.
    ready_s : float
        When the frame's plan is ready, seconds into the pass.
    height_m : float
        Height of the point it tracks above ``target``, metres (0: the ground point).

    Returns
    -------
    SensorState
        Free at the later of ``ready_s`` and ``free_s``, in the frame's time and ground.

    Examples
    --------
    >>> g = OrbitGeometry()
    >>> s = sensor_in_frame(12.0, (g.ground_speed * 10.0 + 500.0, 30.0), g, 10.0, 11.0)
    >>> round(s.free_s, 6), round(s.target[0], 6), s.target[1]
    (2.0, 500.0, 30.0)
    """
    if target is not None:  # pass ground coordinates -> the frame's (nadir at acquired_s)
        target = (target[0] - geometry.ground_speed * acquired_s, target[1])
    return SensorState(max(ready_s, free_s) - acquired_s, target, height_m)


def lead_s(
    geometry: OrbitGeometry, agility: Agility, acquired_s: float, start_s: float, free_s: float
) -> float:
    """How long after a frame's acquisition the NFOV will be on it.

    When the frame's centre (``geometry.look_ahead_m`` ahead of nadir at acquisition)
    enters the field of regard, or later: not before the loop starts on the frame
    (``start_s``) nor before the sensor is free (``free_s``), all seconds into the pass.

    Parameters
    ----------
    geometry : OrbitGeometry
        The frame's geometry.
    agility : Agility
        The sensor's field of regard.
    acquired_s, start_s, free_s : float
        When the frame was acquired, when the loop started on it and when the sensor is
        free, seconds into the pass.

    Returns
    -------
    float
        Seconds after the acquisition, at least 0.

    Examples
    --------
    >>> from dyntarget.schedule.kinematics import get_agility
    >>> g, fast = OrbitGeometry(), get_agility("fast")  # 500 km ahead: in reach 29.4 s later
    >>> round(lead_s(g, fast, 10.0, 12.0, 15.5), 1), lead_s(g, fast, 10.0, 12.0, 100.5)
    (29.4, 90.5)
    """
    t_in, _ = visibility_windows(
        geometry, agility, np.array([geometry.look_ahead_m]), np.array([0.0])
    )
    enter = float(t_in[0]) if np.isfinite(t_in[0]) else 0.0
    return max(enter, max(start_s, free_s) - acquired_s, 0.0)
