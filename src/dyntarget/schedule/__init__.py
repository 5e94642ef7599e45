"""Observation geometry and timing: which NFOV pointings can really be taken, and when.

The paper plans in the image plane as if the NFOV sensor could take every
pointing at once. Here the spacecraft moves and the sensor has finite agility.
The model (documented in ``docs/onboard.md``) is in
:mod:`dyntarget.schedule.kinematics`; the package's modules:

* :mod:`~dyntarget.schedule.kinematics`: orbit geometry, agility presets, look
  vectors, the field of regard (:func:`visibility_windows`).
* :mod:`~dyntarget.schedule.feasibility`: pointings timed and trimmed
  (:func:`schedule`, :func:`make_feasible`, :class:`Schedule`).
* :mod:`~dyntarget.schedule.predicted`: a plan drawn on a predicted plume,
  each pointing moved on to its own time (:func:`schedule_on_prediction`).
* :mod:`~dyntarget.schedule.aim`: pointings corrected for the parallax of a plume
  top between the look-ahead's view and the NFOV's at its time (:class:`ParallaxAim`).
* :mod:`~dyntarget.schedule.sensor`: the sensor's state between plans
  (:class:`SensorState`; a pass's sensor as one frame sees it, the lead time).
"""

from __future__ import annotations

from dyntarget.schedule.aim import ParallaxAim, nadir_xy
from dyntarget.schedule.feasibility import CHUNK, Schedule, Timer, make_feasible, schedule
from dyntarget.schedule.kinematics import (
    AGILITY,
    EARTH_RADIUS_M,
    GM_EARTH,
    REACH_CACHE_SIZE,
    Agility,
    OrbitGeometry,
    _reach_compute,
    angle_between_deg,
    get_agility,
    look_vectors,
    off_nadir_deg,
    pitch_deg,
    under_sight,
    visibility_windows,
)
from dyntarget.schedule.predicted import (
    PlumeForecast,
    iterate_on_prediction,
    schedule_on_prediction,
)
from dyntarget.schedule.sensor import SensorState, lead_s, sensor_in_frame

__all__ = [
    "AGILITY",
    "CHUNK",
    "EARTH_RADIUS_M",
    "GM_EARTH",
    "REACH_CACHE_SIZE",
    "Agility",
    "OrbitGeometry",
    "ParallaxAim",
    "PlumeForecast",
    "Schedule",
    "SensorState",
    "Timer",
    "_reach_compute",
    "angle_between_deg",
    "get_agility",
    "iterate_on_prediction",
    "lead_s",
    "look_vectors",
    "make_feasible",
    "nadir_xy",
    "off_nadir_deg",
    "pitch_deg",
    "schedule",
    "schedule_on_prediction",
    "sensor_in_frame",
    "under_sight",
    "visibility_windows",
]
