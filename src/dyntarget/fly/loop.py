"""The pass loop: look-ahead frames along a strip, Algorithm 1 per frame, one shared NFOV.

Model (documented in ``docs/onboard.md``, section "Flying a pass"):

* **Frames.** The strip's WFOV grid (``factor`` x coarser than the world) is
  cut into frames ``frame_px`` rows high and as wide as the strip. Frame 0 is
  the bottom of the strip (the first ground reached: image "up" is the flight
  direction); frame ``k`` lies ``k * step`` WFOV rows further up, ``step =
  round(frame_px * (1 - overlap))``. The spacecraft flies ``step * gsd`` metres
  between frames, so frames are taken every ``cadence_s = step * gsd / v``
  seconds (``v``: ground speed of the nadir point); frame ``k`` is acquired at
  ``t_k = k * cadence_s``, its centre ``look_ahead_m`` ahead of nadir — the
  kinematics' geometry (:mod:`dyntarget.schedule`) holds in every frame.
* **Latency.** One process handles the frames in order: frame ``k`` starts at
  ``max(t_k, end of frame k-1)`` (a frame waits while the loop is behind), and
  its plan is ready after the measured compute (classify, denoise, plan,
  schedule) or a fixed ``compute_budget_s``. ``latency_s`` = ready - ``t_k``.
  With ``deadline_s``, the time left after the wait is the deadline of
  :func:`dyntarget.pipeline.plan_scene` (its fallbacks apply); a frame whose
  wait alone exceeds the deadline is dropped.
* **One NFOV.** Pointings are timed by the kinematics, once per frame
  (:func:`dyntarget.schedule.schedule_on_prediction`, i.e.
  :func:`~dyntarget.schedule.make_feasible`, moving pointings with a predicted
  plume) from the sensor's state (:class:`~dyntarget.schedule.SensorState`:
  when it is free, what it tracks; :func:`~dyntarget.schedule.sensor_in_frame`),
  which carries over from frame to frame: a new frame's pointings queue behind
  those already committed. Of the plan in its own order and
  earliest-deadline-first, the order keeping more pointings is flown. With
  measured latency a frame's pointings are timed from its stages so far plus
  the previous frame's scheduling time (its own is known only once scheduled);
  its ``ready_s`` is the measured one.
* **Never twice.** The pass keeps the strip's covered WFOV pixels: a
  pointing on a covered pixel is dropped before scheduling, and a plume
  (connected component of the frame's denoised mask) at least half of whose
  pointings were flown marks its whole area covered, so a plume seen again by
  the next, overlapping frame gets no new pointings.
* **Scoring.** Each flown pointing is scored against the truth *at its own
  time* (``World.truth_at``) over its NFOV footprint
  (:func:`dyntarget.observe.score_pointings`): plume fraction, intensity and
  gradient utility (the paper's metrics, summed over the pass).
* **3D worlds** (plumes with heights, ``world.is_3d``; a flat world skips all of
  this and flies exactly as before). Frame ``k`` is the oblique look from the nadir at
  ``t_k`` (``World.look_at``; with ``--truth`` the mask it shows, parallax included);
  pointings are scored as lines of sight (:class:`dyntarget.observe.Sight`: the
  highest plume top the line meets, at the pointing's time); and the aim is corrected
  for the parallax (:class:`dyntarget.schedule.ParallaxAim` in the schedule) with a
  height per pointing by :attr:`PassConfig.parallax`: none (``"off"``), the prior,
  the world's true heights (``"true"``) or heights measured on the pass from
  re-looks of the look-ahead (``"estimated"``, :mod:`dyntarget.fly.heights`, whose
  cost is frames not taken while it re-looks). The schedule is decided once, at the
  frame's plan time, with the aim each pointing will have when flown (the estimate
  from when it is usable, the prior before); a flight system would re-plan then.
* **Prediction.** ``predict`` asks the predict stage's entry point
  (:func:`dyntarget.predict.plume_motion`) for the motion, and plans once on the
  frame's segmentation carried to the lead (:func:`dyntarget.schedule.lead_s`).
"""

from __future__ import annotations

import itertools
import math
import sys
import time
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import asdict, dataclass, field, replace
from functools import cached_property
from typing import TYPE_CHECKING, Any, Protocol

import cv2
import numpy as np

from dyntarget import defaults
from dyntarget.errors import InvalidParameterError, InvalidSceneError
from dyntarget.fly.heights import RELOOK_KM, Geometry3D, HeightEstimate, HeightTracker, Plume
from dyntarget.fly.world import WfovTruth, World, wfov_truth
from dyntarget.masks import mask_to_polygons
from dyntarget.observe import score_pointings
from dyntarget.perceive.base import Classifier
from dyntarget.pipeline import (
    LAST_RESORT,
    PipelineConfig,
    PlanResult,
    Segmentation,
    plan_scene,
    plan_segmentation,
    predict_segmentation,
)
from dyntarget.predict import GROUNDS, Motion, Prediction, plume_motion, wind_motion
from dyntarget.scene import LABEL_FRACTION, block_mean, check_factor
from dyntarget.schedule import (
    Agility,
    OrbitGeometry,
    Schedule,
    get_agility,
    lead_s,
    schedule_on_prediction,
    sensor_in_frame,
)
from dyntarget.trajectory import Trajectory

if TYPE_CHECKING:
    from affine import Affine

    from dyntarget.fly.geo import GeoSettings
    from dyntarget.observe import Sight
    from dyntarget.observe.bound import UpperBound
    from dyntarget.schedule import ParallaxAim

STAGES = ("classify", "denoise", "predict", "plan", "schedule")
"""Stages whose wall time each timeline row reports."""

PREDICT_MODES = ("none", "wind", "two-looks")
"""How a pass plans: on the look as it is, or on the plume as predicted."""

MIN_OVERLAP_ROWS = 8
"""Two-look motion needs at least this many rows seen by both frames."""

COVERED_PLUME_FRACTION = 0.5
"""A plume at least this fraction of whose planned pointings were flown counts as covered."""

PARALLAX_MODES = ("auto", "off", "prior", "true", "estimated")
"""How a pass corrects its aim for the plumes' parallax (see :class:`PassConfig`)."""

MAX_PRIOR_HEIGHT_M = 25_000.0
"""Highest prior plume-top height accepted, metres."""


@dataclass(frozen=True)
class PassConfig:
    """Settings of one pass (see the module docstring for the model).

    Parameters
    ----------
    planner : registered planner name.
    agility : agility preset name (``dyntarget agility``).
    factor : high-res -> WFOV downsampling factor.
    frame_px : frame height in WFOV pixels (default: the strip's width, square frames).
    overlap : fraction of a frame's rows the next frame sees again, in [0, 1).
    altitude_m, look_ahead_m : orbit geometry (see :class:`~dyntarget.schedule.OrbitGeometry`).
    compute_budget_s : fixed compute time per frame instead of the measured one
        (a deterministic timeline).
    deadline_s : time allowed from acquisition to plan, per frame (fallbacks apply).
    footprint : NFOV footprint in WFOV pixels (odd).
    denoise : apply Algorithm 2.
    predict : ``"none"`` (plan on the look as it is), ``"wind"`` (carry the plume
        with a wind prior to when the NFOV will be there) or ``"two-looks"``
        (motion from the overlap of this frame and the previous one, checked
        against the wind prior when there is one).
    wind_mps, wind_from_deg : the wind prior (meteorological convention); by
        default a moving strip's own wind (an ideal forecast).
    ground : with ``"two-looks"``: ``"auto"`` (decided from the frames),
        ``"fixed"`` or ``"moving"`` background (:func:`dyntarget.predict.estimate_motion`).
    pipeline : settings of the pipeline run on each frame
        (:class:`~dyntarget.pipeline.PipelineConfig`).
    parallax : how the NFOV's aim is corrected for the plumes' parallax on a 3D world
        (plumes at heights, seen displaced by the oblique look-ahead):
        ``"auto"`` (``"estimated"`` on a 3D world, ``"off"`` on a flat one), ``"off"``
        (aim at the plume where the look-ahead saw it), ``"prior"`` (every plume at
        ``plume_height_m``), ``"true"`` (the world's true heights: the benchmark's
        "corrected with the true height") or ``"estimated"`` (measured on the pass from
        re-looks of the look-ahead, :mod:`dyntarget.fly.heights`; the prior until then).
        A flat world has no parallax: every mode resolves to ``"off"`` there and the
        pass is flown exactly as without these settings.
    plume_height_m : the prior plume-top height, metres above sea level (0 < h <= 25 km);
        in ``"estimated"`` mode the fallback before or without an estimate (``None``: no
        correction until estimated).
    relook_km : how far ahead of the nadir each re-look sees the plume, km, nearest last
        (``"estimated"`` mode).
    relook_s : look-ahead time per re-look, seconds (``None``: from the agility preset's
        slew model, :func:`dyntarget.fly.heights.relook_seconds`).
    """

    planner: str = "lawnmower-transect"
    agility: str = "fast"
    factor: int = 4
    frame_px: int | None = None
    overlap: float = 0.5
    altitude_m: float = defaults.ALTITUDE_M
    look_ahead_m: float = defaults.LOOK_AHEAD_M
    compute_budget_s: float | None = None
    deadline_s: float | None = None
    footprint: int = 1
    denoise: bool = True
    predict: str = "none"
    wind_mps: float | None = None
    wind_from_deg: float | None = None
    ground: str = "auto"
    pipeline: PipelineConfig = field(default_factory=PipelineConfig)
    parallax: str = "auto"
    plume_height_m: float | None = None
    relook_km: tuple[float, ...] = RELOOK_KM
    relook_s: float | None = None

    def __post_init__(self) -> None:
        _ = self.limits  # an unknown preset is refused here
        self._check_parallax()
        if self.predict not in PREDICT_MODES:
            raise InvalidParameterError(
                f"predict: expected one of {', '.join(PREDICT_MODES)}, got {self.predict!r}"
            )
        if self.ground not in GROUNDS:
            raise InvalidParameterError(
                f"ground: expected one of {', '.join(GROUNDS)}, got {self.ground!r}"
            )
        if self.wind_mps is not None and not (math.isfinite(self.wind_mps) and self.wind_mps >= 0):
            raise InvalidParameterError(f"wind_mps: expected m/s >= 0, got {self.wind_mps!r}")
        if not (0.0 <= self.overlap < 1.0):
            raise InvalidParameterError(
                f"overlap: expected a fraction in [0, 1), got {self.overlap!r}"
            )
        for name in ("compute_budget_s", "deadline_s"):
            v = getattr(self, name)
            if v is not None and not (math.isfinite(v) and v > 0):
                raise InvalidParameterError(f"{name}: expected seconds > 0, got {v!r}")
        if self.frame_px is not None and (
            isinstance(self.frame_px, bool)
            or not isinstance(self.frame_px, int)
            or self.frame_px < 8
        ):
            raise InvalidParameterError(
                f"frame_px: expected an integer >= 8 WFOV pixels, got {self.frame_px!r}"
            )
        fp = self.footprint
        if isinstance(fp, bool) or not isinstance(fp, int) or fp < 1 or fp % 2 == 0:
            raise InvalidParameterError(
                f"footprint: expected an odd positive number of WFOV pixels, got {fp!r}"
            )

    def _check_parallax(self) -> None:
        """Refuse a bad parallax mode, prior height or re-look setting, in one line."""
        if self.parallax not in PARALLAX_MODES:
            raise InvalidParameterError(
                f"parallax: expected one of {', '.join(PARALLAX_MODES)}, got {self.parallax!r}"
            )
        h = self.plume_height_m
        if h is not None and not (
            isinstance(h, int | float) and math.isfinite(h) and 0 < h <= MAX_PRIOR_HEIGHT_M
        ):
            raise InvalidParameterError(
                f"plume_height_m: expected metres in (0, {MAX_PRIOR_HEIGHT_M:g}], got {h!r}"
            )
        if self.parallax == "prior" and h is None:
            raise InvalidParameterError(
                "parallax: 'prior' needs a prior height: give plume_height_m (--plume-height-km)"
            )
        km = self.relook_km
        ok = isinstance(km, tuple) and len(km) > 0
        ok = ok and all(
            isinstance(v, int | float) and math.isfinite(v) and 0 < v * 1e3 < self.look_ahead_m
            for v in km
        )
        if not ok or any(b >= a for a, b in itertools.pairwise(km)):
            raise InvalidParameterError(
                f"relook_km: expected distances in (0, {self.look_ahead_m / 1e3:g}) km ahead of "
                f"the nadir, nearest last, got {km!r}"
            )
        r = self.relook_s
        if r is not None and not (isinstance(r, int | float) and math.isfinite(r) and r > 0):
            raise InvalidParameterError(f"relook_s: expected seconds > 0, got {r!r}")

    def resolved_parallax(self, is_3d: bool) -> str:
        """The parallax mode flown on a world: ``"auto"`` resolved, ``"off"`` on a flat world.

        Parameters
        ----------
        is_3d : bool
            Whether the world's plumes have heights.

        Returns
        -------
        str
            ``"off"``, ``"prior"``, ``"true"`` or ``"estimated"``.

        Examples
        --------
        >>> PassConfig().resolved_parallax(True), PassConfig().resolved_parallax(False)
        ('estimated', 'off')
        """
        if not is_3d:
            return "off"
        return "estimated" if self.parallax == "auto" else self.parallax

    @cached_property
    def limits(self) -> Agility:
        """The agility preset :attr:`agility` names (looked up once per pass settings).

        Returns
        -------
        dyntarget.schedule.Agility
            The preset.
        """
        return get_agility(self.agility)

    def as_dict(self) -> dict[str, Any]:
        """The settings as a plain dict, without ``pipeline`` (recorded with the flown trajectory).

        The parallax settings are left out when none was given (``parallax`` ``"auto"``
        or ``"off"``, the rest at their defaults): the record of a flat world's pass is
        what it was before them.

        Returns
        -------
        dict
            Field name to value.
        """
        d = asdict(self)
        d.pop("pipeline")
        if self.parallax in ("auto", "off") and (
            self.plume_height_m is None and self.relook_km == RELOOK_KM and self.relook_s is None
        ):  # no parallax settings given (or a flat world's): the record as before them
            for k in ("parallax", "plume_height_m", "relook_km", "relook_s"):
                d.pop(k)
        else:
            d["relook_km"] = list(self.relook_km)
        return d


@dataclass(frozen=True)
class FramePlan:
    """Where the frames of a pass lie on the strip's WFOV grid, and when they are taken.

    Parameters
    ----------
    wfov_shape : tuple of int
        The strip's WFOV grid ``(H, W)``.
    frame_px : int
        Frame height, WFOV rows.
    step : int
        WFOV rows between consecutive frames.
    cadence_s : float
        Seconds between frame acquisitions.
    tops : tuple of int
        Top WFOV row of each frame, frame 0 (the bottom of the strip) first.
    geometry : dyntarget.schedule.OrbitGeometry
        Orbit and WFOV GSD of every frame.
    """

    wfov_shape: tuple[int, int]
    frame_px: int
    step: int
    cadence_s: float
    tops: tuple[int, ...]
    geometry: OrbitGeometry

    @property
    def n_frames(self) -> int:
        """Number of frames of the pass."""
        return len(self.tops)

    def acquired_s(self, k: int) -> float:
        """When frame ``k`` is acquired, seconds into the pass.

        Parameters
        ----------
        k : int
            Frame index.

        Returns
        -------
        float
            ``k * cadence_s``.
        """
        return k * self.cadence_s


def frame_plan(world: World, config: PassConfig) -> FramePlan:
    """Cut the strip into look-ahead frames (see the module docstring).

    Parameters
    ----------
    world : the strip.
    config : the pass settings.

    Returns
    -------
    FramePlan: frame tops (WFOV rows, bottom frame first), step and cadence.

    Examples
    --------
    >>> from dyntarget.scene import Scene
    >>> from dyntarget.fly.world import StaticWorld
    >>> img = np.zeros((4, 256, 64), np.float32); lab = np.zeros((256, 64), bool)
    >>> w = StaticWorld(Scene(img, label=lab, gsd=8.0))
    >>> fp = frame_plan(w, PassConfig(factor=4))
    >>> fp.tops, fp.step, round(fp.cadence_s * fp.geometry.ground_speed, 6)
    ((48, 40, 32, 24, 16, 8, 0), 8, 256.0)
    """
    factor = check_factor(config.factor, world.shape)
    hw, ww = world.shape[0] // factor, world.shape[1] // factor
    frame_px = config.frame_px or ww
    if frame_px > hw:
        raise InvalidParameterError(
            f"frame_px: a frame of {frame_px} WFOV rows does not fit the strip's {hw} rows "
            f"(at factor {factor}); give a longer strip or smaller frames"
        )
    step = max(1, round(frame_px * (1.0 - config.overlap)))
    n = (hw - frame_px) // step + 1
    tops = tuple(hw - frame_px - k * step for k in range(n))
    gsd_w = world.gsd * factor
    geometry = OrbitGeometry(
        altitude_m=config.altitude_m, look_ahead_m=config.look_ahead_m, wfov_gsd_m=gsd_w
    )
    return FramePlan((hw, ww), frame_px, step, step * gsd_w / geometry.ground_speed, tops, geometry)


@dataclass
class FrameRecord:
    """One row of the timeline.

    Parameters
    ----------
    frame : int
        Frame index.
    acquired_s : float
        When the frame was acquired, seconds into the pass.
    start_s : float
        When the loop started on it.
    ready_s : float
        When its plan was ready.
    latency_s : float
        ``ready_s - acquired_s``.
    stage_s : dict of str to float
        Wall seconds per stage (:data:`STAGES`).
    deadline_met : bool or None
        Whether the deadline was met (``None``: no deadline).
    path : str
        What the pipeline ran, ``"; "``-joined.
    planned : int
        Pointings planned.
    skipped_covered : int
        Pointings dropped because their pixel was already covered.
    flown : int
        Pointings flown.
    plume_px : float
        Sum of the plume fractions the flown pointings observed.
    intensity : float
        Sum of their intensity utility.
    gradient : float
        Sum of their gradient utility.
    new_plumes : int
        True plumes observed for the first time in the pass.
    dropped : bool
        The frame was dropped (the loop was behind past the deadline).
    loop_s : float
        Wall time of the onboard work on this frame.
    """

    frame: int
    acquired_s: float
    start_s: float
    ready_s: float
    latency_s: float
    stage_s: dict[str, float]
    deadline_met: bool | None
    path: str
    planned: int
    skipped_covered: int
    flown: int
    plume_px: float
    intensity: float
    gradient: float
    new_plumes: int
    dropped: bool = False
    loop_s: float = 0.0
    """Wall time of the onboard work on this frame (frame in hand -> plan scheduled), all of it."""

    def row(self, *, measured: bool) -> dict[str, Any]:
        """The timeline row; stage times only when latency was measured (else not deterministic).

        Parameters
        ----------
        measured : bool
            Whether latency was measured (not a fixed compute budget).

        Returns
        -------
        dict
            Column name to value, formatted for ``timeline.csv``.
        """
        out: dict[str, Any] = {
            "frame": self.frame,
            "acquired_s": f"{self.acquired_s:.4f}",
            "start_s": f"{self.start_s:.4f}",
            "ready_s": f"{self.ready_s:.4f}",
            "latency_s": f"{self.latency_s:.4f}",
        }
        for s in STAGES:
            out[f"{s}_s"] = f"{self.stage_s.get(s, 0.0):.4f}" if measured else ""
        out["loop_s"] = f"{self.loop_s:.4f}" if measured else ""
        out |= {
            "deadline_met": "" if self.deadline_met is None else str(self.deadline_met).lower(),
            "pointings_planned": self.planned,
            "pointings_skipped_covered": self.skipped_covered,
            "pointings_flown": self.flown,
            "plume_px_gained": f"{self.plume_px:.4f}",
            "utility_gained": f"{self.intensity:.4f}",
            "gradient_gained": f"{self.gradient:.4f}",
            "new_plumes": self.new_plumes,
            "dropped": str(self.dropped).lower(),
            "path": self.path,
        }
        return out


RELOOK_DROP = "dropped: look-ahead re-looking"
"""The path of a frame not taken because the look-ahead was re-looking at a plume."""

TIMELINE_COLUMNS = tuple(
    FrameRecord(0, 0, 0, 0, 0, {}, None, "", 0, 0, 0, 0, 0, 0, 0).row(measured=True)
)


@dataclass
class Flown:
    """The pointings flown so far, on the strip's WFOV grid, with their pass times.

    Parameters
    ----------
    x, y : list of float
        Pointings on the strip's WFOV grid, pixels.
    t : list of float
        When each was observed, seconds into the pass.
    frame : list of int
        The frame whose plan each came from.
    part : list of int
        Plume visited, numbered over the pass.
    plume : list of float
        Plume fraction each observed of the truth at its time.
    intensity : list of float
        Intensity utility each observed.
    plume_id : list of int
        Id of the true plume each observed (0: none).
    """

    x: list[float] = field(default_factory=list)
    y: list[float] = field(default_factory=list)
    t: list[float] = field(default_factory=list)
    frame: list[int] = field(default_factory=list)
    part: list[int] = field(default_factory=list)
    plume: list[float] = field(default_factory=list)
    intensity: list[float] = field(default_factory=list)
    plume_id: list[int] = field(default_factory=list)

    def trajectory(self, planner: str, params: dict[str, Any]) -> Trajectory:
        """The flown pointings as one timed trajectory (strip WFOV pixels, pass seconds).

        Parameters
        ----------
        planner : str
            The planner's name.
        params : dict
            Settings recorded with the trajectory.

        Returns
        -------
        dyntarget.trajectory.Trajectory
            Timed in seconds into the pass (empty and untimed when nothing was flown).
        """
        if not self.x:
            return Trajectory.empty(planner, params)
        return Trajectory(
            np.column_stack([self.x, self.y]), np.asarray(self.part), planner, params,
            np.asarray(self.t, np.float64),
        )  # fmt: skip


@dataclass
class PassState:
    """Everything the loop carries from frame to frame.

    Parameters
    ----------
    covered : numpy.ndarray
        Boolean ``(H, W)`` WFOV pixels of the strip already covered.
    timer_t : float
        When the NFOV sensor is free, seconds into the pass.
    target : tuple of float or None
        ``(along, cross)`` of what the sensor tracks, metres (``None``: nadir).
    busy_until : float
        When the loop finished its last frame, seconds.
    previous : tuple or None
        ``(frame, image, mask)`` last seen, for two-look motion.
    parts : int
        Plumes visited so far (the next part number).
    schedule_s : float
        Wall seconds the last frame took to schedule (measured latency only: a
        frame's pointings are timed from its stages so far plus this).
    plumes_seen : set of int
        True plume ids observed so far.
    records : list of FrameRecord
        The timeline so far.
    flown : Flown
        The pointings flown so far.
    """

    covered: np.ndarray
    timer_t: float = 0.0
    target: tuple[float, float] | None = None  # (along, cross) in pass ground coordinates, m
    busy_until: float = 0.0  # when the loop finished its last frame
    previous: tuple[int, np.ndarray, np.ndarray] | None = None  # (frame, image, mask) last seen
    parts: int = 0
    schedule_s: float = 0.0  # the last frame's scheduling time (measured latency only)
    plumes_seen: set[int] = field(default_factory=set)
    records: list[FrameRecord] = field(default_factory=list)
    flown: Flown = field(default_factory=Flown)


@dataclass(frozen=True, eq=False)
class PassResult:
    """A flown pass: the timeline, the flown pointings and the totals.

    Parameters
    ----------
    world_id : str
        The strip's id.
    config : PassConfig
        The pass settings.
    frames : FramePlan
        Where and when the frames were taken.
    records : list of FrameRecord
        The timeline, one record per frame handled.
    flown : Flown
        The pointings flown.
    plumes_at_start : frozenset of int
        Plume ids in the strip's truth at t = 0.
    stopped : bool
        The pass was stopped before its last frame.
    geo : dict or None
        Settings and outcome of the GEO blueprint (``None``: look-ahead only).
    geo_times : dict or None
        Wall-clock seconds of the GEO targets and blueprint (not in ``geo``: timings
        differ between identical runs).
    upper_bound : dict or None
        The pass's true upper bound: :func:`pass_upper_bound` as plain JSON values
        (:meth:`~dyntarget.observe.bound.UpperBound.as_dict`), or
        ``{"value": None, "why": ...}`` when it could not be computed (``None``: not
        asked for).
    heights : tuple of dyntarget.fly.heights.HeightEstimate
        Per-plume top heights (``"estimated"`` or ``"prior"`` mode on a 3D world).
    is_3d : bool
        Whether the world's plumes have heights.
    parallax : str
        The parallax mode flown (:meth:`PassConfig.resolved_parallax`).
    relook_windows : tuple of (float, float)
        ``(start, end)`` pass seconds of every re-look the look-ahead took.
    """

    world_id: str
    config: PassConfig
    frames: FramePlan
    records: list[FrameRecord]
    flown: Flown
    plumes_at_start: frozenset[int]
    """Plume ids in the strip's truth at t = 0."""
    stopped: bool = False
    geo: dict[str, Any] | None = None
    """GEO foresight: its settings and what the blueprint did (``None``: look-ahead only)."""
    geo_times: dict[str, float] | None = None
    """Wall-clock seconds of the GEO targets and blueprint (kept out of :attr:`geo`)."""
    upper_bound: dict[str, Any] | None = None
    """The pass's true upper bound (:func:`pass_upper_bound`; ``None``: not computed)."""
    heights: tuple[HeightEstimate, ...] = ()
    """Per-plume top heights (``"estimated"`` or ``"prior"`` mode on a 3D world; empty otherwise)."""
    is_3d: bool = False
    """Whether the world's plumes have heights (the parallax figures enter :meth:`totals`)."""
    parallax: str = "off"
    """The parallax mode flown (:meth:`PassConfig.resolved_parallax`)."""
    relook_windows: tuple[tuple[float, float], ...] = ()
    """``(start, end)`` pass seconds of every re-look the look-ahead took (``"estimated"``
    mode on a 3D world): frames acquired inside one are not taken."""

    @property
    def measured(self) -> bool:
        """Whether latency was measured (no fixed ``compute_budget_s``)."""
        return self.config.compute_budget_s is None

    def totals(self) -> dict[str, Any]:
        """One row of pass results (what a campaign table holds).

        Returns
        -------
        dict
            Strip, planner, agility, frame and pointing counts, plume pixels, utility,
            ratio plume, plumes observed and in total, median and largest latency,
            ``parallax`` (the mode flown); on a 3D world also ``relooks``,
            ``frames_lost_to_relooks``, ``plumes_height_estimated``, ``height_rmse_m`` and
            ``height_bias_m`` (estimates against the true heights; ``None`` when none) and
            ``heights_median_s`` (the height work's median wall time per frame; ``None``
            with a fixed compute budget).
        """
        lat = np.array([r.latency_s for r in self.records if not r.dropped], np.float64)
        observed = {i for i in self.flown.plume_id if i > 0}
        return {
            "strip": self.world_id,
            "planner": self.config.planner,
            "agility": self.config.agility,
            "frames": len(self.records),
            "frames_dropped": sum(r.dropped for r in self.records),
            "deadlines_missed": sum(r.deadline_met is False for r in self.records),
            "pointings_flown": len(self.flown.x),
            "plume_px": round(float(sum(self.flown.plume)), 4),
            "utility": round(float(sum(self.flown.intensity)), 4),
            "ratio_plume": round(float(np.mean(self.flown.plume)), 4) if self.flown.x else 0.0,
            "plumes_observed": len(observed),
            "plumes_total": len(self.plumes_at_start | observed),  # a cloud may drift in later
            "latency_median_s": round(float(np.median(lat)), 4) if len(lat) else None,
            "latency_max_s": round(float(np.max(lat)), 4) if len(lat) else None,
            "parallax": self.parallax,
            **(self._parallax_totals() if self.is_3d else {}),
        }

    def _parallax_totals(self) -> dict[str, Any]:
        """Re-looks, frames they cost, plumes measured and the height error against the truth."""
        est = [e for e in self.heights if e.height_source == "estimated"]
        err = np.array(
            [e.top_height_m - e.true_height_m for e in est
             if e.top_height_m is not None and e.true_height_m is not None],
            np.float64,
        )  # fmt: skip
        hs = [r.stage_s["heights"] for r in self.records if "heights" in r.stage_s]
        return {
            "relooks": len(self.relook_windows),
            "frames_lost_to_relooks": sum(r.path == RELOOK_DROP for r in self.records),
            "plumes_height_estimated": len(est),
            "height_rmse_m": round(float(np.sqrt(np.mean(err**2))), 1) if len(err) else None,
            "height_bias_m": round(float(np.mean(err)), 1) if len(err) else None,
            "heights_median_s": round(float(np.median(hs)), 4) if hs and self.measured else None,
        }


class FramePlanned(Protocol):
    """What a view of a frame reads of its plan (a :class:`~dyntarget.pipeline.PlanResult`)."""

    @property
    def probability(self) -> np.ndarray | None:
        """``(H, W)`` plume probability (``None``: planned from a given mask)."""
        ...

    @property
    def polygons(self) -> list[Any]:
        """The polygons planned over."""
        ...


@dataclass(frozen=True, eq=False)
class FrameView:
    """What one frame saw and sent: for views of the pass (not kept by the loop itself).

    Parameters
    ----------
    frame : int
        Frame index.
    top : int
        The frame's top row on the strip's WFOV grid.
    image : numpy.ndarray
        The frame's ``(4, H, W)`` WFOV image.
    plan : FramePlanned
        The pipeline's result on it (:class:`~dyntarget.pipeline.PlanResult`; read back
        from a spilled view, its probability and polygons).
    first, end : int
        The slice of :attr:`PassResult.flown` its plan added.
    """

    frame: int
    top: int
    image: np.ndarray
    plan: FramePlanned
    first: int
    end: int


class Gate(Protocol):
    """Onboard refinement within a GEO blueprint (:class:`dyntarget.geo.refine.BlueprintGate`)."""

    def route(
        self,
        t_k: float,
        top: int,
        rows: np.ndarray,
        cols: np.ndarray,
        values: np.ndarray,
        free_s: float,
    ) -> np.ndarray:
        """Pool a frame's plume pixels; the ``(N, 2)`` strip ``(row, col)`` to fly now.

        Parameters
        ----------
        t_k : float
            The frame's acquisition time, seconds into the pass.
        top : int
            The frame's top row on the strip's WFOV grid.
        rows, cols : numpy.ndarray
            ``(n,)`` int, strip WFOV row and column of each of the frame's plume
            pixels not yet covered (the loop passes ``frame row + top``).
        values : numpy.ndarray
            ``(n,)`` float, each pixel's value: the frame's red WFOV reflectance
            there (band 2 of the ``(4, H, W)`` image).
        free_s : float
            When the sensor is free of the pointings already committed, seconds
            into the pass.

        Returns
        -------
        numpy.ndarray
            ``(N, 2)`` int64 strip WFOV ``(row, col)`` of the pointings to fly now,
            in flight order (``N`` may be 0).
        """
        ...

    def report(self) -> dict[str, int]:
        """What the refinement did (for summary.json).

        Returns
        -------
        dict of str to int
            Counters of the refinement (in :class:`~dyntarget.geo.refine.BlueprintGate`:
            targets released, of them the blueprint's, the look-ahead's own targets,
            pointings pooled and released, releases capped by the blueprint, caps
            lifted), merged into the pass's ``geo`` record.
        """
        ...


class _TruthCache:
    """Truth on the WFOV footprints, rebuilt only when the world's truth object changes.

    A long strip (``world.is_long``) is scored band by band: ``band``
    WFOV rows at a time (with the footprint's margin), recent bands kept.
    """

    def __init__(self, world: World, factor: int, footprint: int, band: int = 64) -> None:
        self.world, self.factor, self.footprint = world, factor, footprint
        self.lazy = world.is_long
        self.band = max(1, int(band))
        self._key: int | None = None
        self._value: WfovTruth | None = None
        self._bands: OrderedDict[tuple[float, int], WfovTruth] = OrderedDict()

    def at(self, t: float, r: int = 0) -> tuple[WfovTruth, int]:
        """The WFOV truth at ``t`` holding strip WFOV row ``r``, and its first row."""
        if not self.lazy:
            truth = self.world.truth_at(t)
            if self._key != id(truth) or self._value is None:
                self._value = wfov_truth(truth, self.factor, self.footprint)
                self._key = id(truth)
            return self._value, 0
        tq = self.world.quantize(t)
        b = int(r) // self.band
        key = (tq, b)
        hit = self._bands.get(key)
        r0 = b * self.band
        if hit is None:
            f, pad = self.factor, self.footprint // 2
            hw = self.world.shape[0] // f
            a, z = max(0, r0 - pad), min(hw, r0 + self.band + pad)
            w = wfov_truth(self.world.truth_rows(tq, a * f, z * f), f, self.footprint)  # type: ignore[attr-defined]
            lo, hi = r0 - a, min(r0 - a + self.band, z - a)
            hit = WfovTruth(*(getattr(w, n)[lo:hi] for n in WFOV_FIELDS))
            self._bands[key] = hit
            if len(self._bands) > 32:
                self._bands.popitem(last=False)
        else:
            self._bands.move_to_end(key)
        return hit, r0


WFOV_FIELDS = ("plume", "intensity", "gradient", "ids", "valid")


@dataclass(frozen=True, eq=False)
class _Pass:
    """What every frame of one pass shares."""

    world: World
    classifier: Classifier | None
    fallback: Classifier | None
    config: PassConfig
    frames: FramePlan
    agility: Agility
    truth: _TruthCache
    gate: Gate | None
    mode: str = "off"
    """The parallax mode flown (:meth:`PassConfig.resolved_parallax`)."""
    where: Geometry3D | None = None
    """The spacecraft's track on the strip (a 3D world only)."""
    tracker: HeightTracker | None = None
    """Plumes, re-looks and heights (``"estimated"``/``"prior"`` on a 3D world)."""


def fly_pass(
    world: World,
    classifier: Classifier | None,
    config: PassConfig,
    *,
    fallback: Classifier | None = None,
    on_frame: Callable[[PassResult], None] | None = None,
    should_stop: Callable[[], bool] | None = None,
    progress: bool = False,
    frame_sink: Callable[[FrameView], None] | None = None,
    geo: GeoSettings | None = None,
    upper_bound: bool = False,
) -> PassResult:
    """Fly a pass over ``world`` (see the module docstring for the model).

    Parameters
    ----------
    world : the strip (:class:`~dyntarget.fly.world.World`).
    classifier : a fitted classifier; ``None`` plans on the truth mask at each
        frame's acquisition time (the oracle classifier).
    config : pass settings.
    fallback : a cheaper classifier for the deadline.
    on_frame : called with the pass so far after every frame (e.g. to write outputs).
    should_stop : polled after every frame; true ends the pass early (``stopped``).
    progress : show a progress bar (tqdm) over the frames.
    frame_sink : called with every frame's :class:`FrameView` (e.g. to draw the pass).
    geo : :class:`dyntarget.fly.geo.GeoSettings`: plan a blueprint over the pass from
        the GEO stream of the strip's world and refine every frame within it
        (:mod:`dyntarget.fly.geo`); ``None``: look-ahead only.
    upper_bound : also compute the pass's true upper bound (:func:`pass_upper_bound`,
        :attr:`PassResult.upper_bound`): seconds on a short strip, minutes on a long one.

    Returns
    -------
    PassResult

    Examples
    --------
    >>> from dyntarget.scene import Scene
    >>> from dyntarget.fly.world import StaticWorld
    >>> img = np.full((4, 256, 64), 0.05, np.float32); lab = np.zeros((256, 64), bool)
    >>> lab[100:120, 20:40] = True; img[:, lab] = 0.8
    >>> w = StaticWorld(Scene(img, label=lab, gsd=8.0))
    >>> r = fly_pass(w, None, PassConfig(agility="unlimited", compute_budget_s=0.01))
    >>> r.totals()["plumes_observed"], r.totals()["frames"]
    (1, 7)
    """
    ctx, geo_info, geo_times = _prepare(world, classifier, fallback, config, geo)
    state = PassState(covered=np.zeros(ctx.frames.wfov_shape, bool))
    plumes_at_start = world.plumes_at_start()

    def result(stopped: bool = False) -> PassResult:
        gate = ctx.gate
        info = None if geo_info is None else {**geo_info, **(gate.report() if gate else {})}
        tracker = ctx.tracker
        return PassResult(
            world.id, config, ctx.frames, list(state.records), state.flown,
            plumes_at_start, stopped, info, geo_times,
            parallax=ctx.mode,
            heights=() if tracker is None else tracker.estimates(_true_height(ctx)),
            is_3d=ctx.where is not None,
            relook_windows=() if tracker is None else tuple(sorted(tracker.busy)),
        )  # fmt: skip

    stopped = _fly_frames(ctx, state, result, on_frame, should_stop, progress, frame_sink)
    final = result(stopped)
    if upper_bound:
        try:
            bound = pass_upper_bound(world, config, ctx.frames, final.records).as_dict()
        except InvalidParameterError as exc:  # e.g. a truth without a time step
            bound = {"value": None, "why": str(exc)}
        final = replace(final, upper_bound=bound)
    return final


def _prepare(
    world: World,
    classifier: Classifier | None,
    fallback: Classifier | None,
    config: PassConfig,
    geo: GeoSettings | None,
) -> tuple[_Pass, dict[str, Any] | None, dict[str, float] | None]:
    """The pass's shared context, checked; with ``geo``, its blueprint gate, settings, times."""
    frames = frame_plan(world, config)
    if config.footprint > frames.wfov_shape[1]:
        raise InvalidParameterError(
            f"footprint: {config.footprint} WFOV px is wider than the strip's "
            f"{frames.wfov_shape[1]} WFOV px (--footprint); expected at most that"
        )
    if config.predict == "wind" and _wind(config, world) is None:
        raise InvalidParameterError(
            "predict: 'wind' needs a wind: give wind_mps and wind_from_deg (--wind-mps, "
            "--wind-from-deg); only synthetic strips carry their own"
        )
    truth = _TruthCache(world, config.factor, config.footprint, band=frames.frame_px)
    gate, geo_info, geo_times = None, None, None
    if geo is not None:
        from dyntarget.fly.geo import prepare

        gate, geo_info, geo_times = prepare(world, frames, config, geo)
        if gate is None:
            geo_info["degraded"] = "no GEO image arrived in time: flown on the look-ahead only"
    ctx = _Pass(world, classifier, fallback, config, frames, config.limits, truth, gate)
    mode = config.resolved_parallax(bool(getattr(world, "is_3d", False)))
    if getattr(world, "is_3d", False):
        where = Geometry3D(
            frames.geometry, frames.wfov_shape, frames.frame_px, frames.tops[0], config.factor
        )
        tracker = None
        if mode in ("estimated", "prior"):
            wind = _wind(config, world)
            prior = None
            if wind is not None:
                rad = math.radians(wind[1])  # blows from: moves the other way
                prior = (-wind[0] * math.sin(rad), -wind[0] * math.cos(rad))
            tracker = HeightTracker(
                where, config.limits, config.relook_km, config.relook_s, config.plume_height_m,
                prior, measure=mode == "estimated", log=_stderr,
            )  # fmt: skip
        ctx = replace(ctx, mode=mode, where=where, tracker=tracker)
    return ctx, geo_info, geo_times


def _stderr(line: str) -> None:
    print(line, file=sys.stderr)


def _fly_frames(
    ctx: _Pass,
    state: PassState,
    result: Callable[[], PassResult],
    on_frame: Callable[[PassResult], None] | None,
    should_stop: Callable[[], bool] | None,
    progress: bool,
    frame_sink: Callable[[FrameView], None] | None,
) -> bool:
    """Fly the frames in order; whether the pass was stopped before its last."""
    from tqdm import tqdm

    frames = ctx.frames
    bar = tqdm(
        total=frames.n_frames, desc=f"fly {ctx.world.id}", unit="frame", disable=not progress
    )
    try:
        for k in range(frames.n_frames):
            before = len(state.flown.x)
            record, image, planned = _fly_frame(k, ctx, state)
            state.records.append(record)
            if frame_sink is not None and image is not None and planned is not None:
                frame_sink(FrameView(k, frames.tops[k], image, planned, before, len(state.flown.x)))
            bar.update()
            if on_frame is not None:
                on_frame(result())
            if should_stop is not None and should_stop() and k + 1 < frames.n_frames:
                return True
    finally:
        bar.close()
    return False


def pass_upper_bound(
    world: World, config: PassConfig, frames: FramePlan, records: list[FrameRecord] | None = None
) -> UpperBound:
    """An upper bound on the utility of every schedule a pass over ``world`` can fly.

    :func:`dyntarget.observe.bound.upper_bound_utility` on the strip's truth at every
    truth time step (as the loop scores it), the pass's geometry and agility; each
    pixel counted once unless the pass moves pointings with a predicted plume.

    Parameters
    ----------
    world : the strip.
    config : the pass settings.
    frames : its frame plan.
    records : the flown timeline: with unlimited agility, no pointing starts after
        its last plan was ready.

    Returns
    -------
    dyntarget.observe.bound.UpperBound

    Raises
    ------
    dyntarget.errors.InvalidParameterError
        On a 3D world (:attr:`World.is_3d`): the bound is computed for flat worlds only.
    """
    from dyntarget.observe.bound import upper_bound_utility, values_from_bands

    if world.is_3d:
        raise InvalidParameterError(
            f"world {world.id!r} is 3D: the upper bound is computed for flat worlds only (a line "
            "of sight meets plume tops away from its aim, which the bound's reach does not model)"
        )

    agility = config.limits
    truth = _TruthCache(world, config.factor, config.footprint, band=frames.frame_px)
    t_end = None
    if agility.unlimited:
        t_end = max((r.ready_s for r in records or [] if not r.dropped), default=0.0)
    return upper_bound_utility(
        values_from_bands(truth.at, frames.wfov_shape[1]),
        frames.wfov_shape,
        frames.frame_px,
        frames.geometry,
        agility,
        time_step_s=world.truth_step_s,  # a static world has none
        distinct=config.predict == "none",
        t_end_s=t_end,
    )


def _frame_image(
    world: World, frames: FramePlan, k: int, factor: int, t: float
) -> tuple[np.ndarray, np.ndarray | None]:
    top = frames.tops[k]
    hr = world.image_at(t, top * factor, (top + frames.frame_px) * factor)
    expected = (4, frames.frame_px * factor, frames.wfov_shape[1] * factor)
    if hr.shape[0] != 4 or hr.shape[1] != expected[1] or hr.shape[2] < expected[2]:
        raise InvalidSceneError(
            f"world {world.id!r}: frame {k} image has shape {hr.shape}, expected {expected}"
        )
    image = block_mean(np.asarray(hr, np.float32)[:, :, : expected[2]], factor)
    valid = None
    if world.valid is not None:
        v = world.valid[top * factor : (top + frames.frame_px) * factor, : expected[2]]
        valid = block_mean(v[None].astype(np.float32), factor)[0] == 1.0
    return image, valid


def _look(
    ctx: _Pass, k: int, t_k: float
) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
    """Frame ``k``'s WFOV image, valid pixels and (the oracle: no classifier) true mask."""
    config, frames = ctx.config, ctx.frames
    if ctx.where is not None:
        return _look_3d(ctx, k, t_k)
    image, valid = _frame_image(ctx.world, frames, k, config.factor, t_k)
    if ctx.classifier is not None:
        return image, valid, None
    f, width, top = config.factor, frames.wfov_shape[1] * config.factor, frames.tops[k]
    label = ctx.world.label_rows(t_k, top * f, (top + frames.frame_px) * f)[:, :width]
    return image, valid, block_mean(label[None].astype(np.float32), f)[0] >= LABEL_FRACTION


def _look_3d(
    ctx: _Pass, k: int, t_k: float
) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
    """A 3D world's frame ``k``: the oblique look from the nadir at ``t_k`` (and the mask it shows)."""
    config, frames, world = ctx.config, ctx.frames, ctx.world
    assert ctx.where is not None
    f, top = config.factor, frames.tops[k]
    width = frames.wfov_shape[1] * f
    hr, label = world.look_at(
        t_k, top * f, (top + frames.frame_px) * f,
        nadir_xy=ctx.where.nadir_hr(t_k), altitude_m=config.altitude_m,
    )  # fmt: skip
    expected = (4, frames.frame_px * f, width)
    if hr.shape[0] != 4 or hr.shape[1] != expected[1] or hr.shape[2] < expected[2]:
        raise InvalidSceneError(
            f"world {world.id!r}: frame {k} image has shape {hr.shape}, expected {expected}"
        )
    image = block_mean(np.asarray(hr, np.float32)[:, :, :width], f)
    valid = None
    if world.valid is not None:
        v = world.valid[top * f : (top + frames.frame_px) * f, :width]
        valid = block_mean(v[None].astype(np.float32), f)[0] == 1.0
    if ctx.classifier is not None:
        return image, valid, None
    mask = block_mean(np.asarray(label)[None, :, :width].astype(np.float32), f)[0]
    return image, valid, mask >= LABEL_FRACTION


def _render(
    ctx: _Pass, spent: list[float]
) -> Callable[[float, int, tuple[float, float]], np.ndarray]:
    """The plume mask a re-look shows (:data:`dyntarget.fly.heights.Render`): the oracle's
    (the look's label, as a frame's) or the pass's classifier's on the look's WFOV image;
    the world's rendering time is added to ``spent`` (the simulator's, not the height work's).
    """
    config, frames = ctx.config, ctx.frames
    f, width, rows = config.factor, frames.wfov_shape[1] * config.factor, frames.frame_px

    def render(t: float, top: int, nadir: tuple[float, float]) -> np.ndarray:
        t0 = time.perf_counter()
        hr, label = ctx.world.look_at(
            t, top * f, (top + rows) * f, nadir_xy=nadir, altitude_m=config.altitude_m
        )
        if ctx.classifier is None:
            mask = block_mean(np.asarray(label)[None, :, :width].astype(np.float32), f)[0]
            spent[0] += time.perf_counter() - t0
            return np.asarray(mask >= LABEL_FRACTION)
        image = block_mean(np.asarray(hr, np.float32)[:, :, :width], f)
        spent[0] += time.perf_counter() - t0
        return np.asarray(ctx.classifier.predict(image), bool)

    return render


def _heights(
    ctx: _Pass, k: int, result: PlanResult, image: np.ndarray, stage: dict[str, float]
) -> np.ndarray | None:
    """Track frame ``k``'s plumes and measure new ones (``stage["heights"]``: the compute, not
    the simulator's rendering of the re-looks); the frame's plume-id map (``None``: no tracker)."""
    tracker, frames = ctx.tracker, ctx.frames
    if tracker is None:
        return None
    spent = [0.0]
    t0 = time.perf_counter()
    target = result.mask if result.predicted_mask is None else result.predicted_mask
    pids = tracker.frame(
        k, frames.acquired_s(k), frames.tops[k], target, _render(ctx, spent),
        last=k == frames.n_frames - 1, raw=result.raw_mask,
    )  # fmt: skip
    stage["heights"] = time.perf_counter() - t0 - spent[0]
    return pids


def _aim(ctx: _Pass, k: int, pids: np.ndarray | None) -> ParallaxAim | None:
    """The parallax correction of frame ``k``'s pointings (``None``: not corrected).

    Each pointing's height: ``"prior"``, the prior; ``"estimated"``, its plume's estimate
    from when it is usable (:meth:`~dyntarget.fly.heights.HeightTracker.height_at`), the
    prior before (NaN without one: not corrected); ``"true"``, the true top height, at the
    pointing's time, of the truth's plume whose top the look-ahead saw there (of the
    plumes with a height, the highest whose true position under the pointing, seen from
    the look-ahead at the acquisition, holds it).
    """
    if ctx.where is None or ctx.mode == "off":
        return None
    from dyntarget.schedule import ParallaxAim

    frames, where, tracker = ctx.frames, ctx.where, ctx.tracker
    t_k, top = frames.acquired_s(k), frames.tops[k]
    shape = (frames.frame_px, frames.wfov_shape[1])

    def field(look: bool) -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
        def heights_m(points: np.ndarray, t_s: np.ndarray) -> np.ndarray:
            pts = np.asarray(points, np.float64).reshape(-1, 2)
            ts = np.broadcast_to(np.asarray(t_s, np.float64), (len(pts),))
            if ctx.mode == "true":
                return _true_heights(ctx, pts, ts, t_k, top, look=look)
            assert tracker is not None
            if ctx.mode == "prior" or pids is None:
                return np.full(len(pts), tracker.height_at(0, t_k), np.float64)
            rows = np.floor(pts[:, 1] + 0.5).astype(np.int64)
            cols = np.floor(pts[:, 0] + 0.5).astype(np.int64)
            inside = (rows >= 0) & (rows < shape[0]) & (cols >= 0) & (cols < shape[1])
            pid = np.zeros(len(pts), np.int64)
            pid[inside] = pids[rows[inside], cols[inside]]
            at = t_k if look else None
            return np.array(
                [
                    tracker.height_at(int(i), t_k + float(t), None if at is None else at)
                    for i, t in zip(pid, ts, strict=True)
                ],
                np.float64,
            )

        return heights_m

    del where  # the top the look-ahead saw at t_k, then where the NFOV meets it at its time
    return ParallaxAim(frames.geometry, shape, field(look=False), field(look=True))


def _true_heights(
    ctx: _Pass, pts: np.ndarray, ts: np.ndarray, t_k: float, top: int, *, look: bool = False
) -> np.ndarray:
    """``"true"`` mode: each pointing's true plume-top height (:func:`_aim`), NaN where none;
    ``look``: its height when the look-ahead saw it (``t_k``), else at the pointing's time."""
    from dyntarget import parallax

    world, where = ctx.world, ctx.where
    assert where is not None
    out = np.full(len(pts), np.nan)
    at_look = world.heights_at(t_k)
    if at_look is None or not len(pts):
        return out
    g = where.geometry
    nx, ny = where.nadir(t_k)
    along = (ny - (pts[:, 1] + top)) * g.wfov_gsd_m
    cross = (pts[:, 0] - nx) * g.wfov_gsd_m
    best = np.full(len(pts), -1.0)
    hw, ww = ctx.frames.wfov_shape
    for i in np.argsort(at_look)[::-1]:
        h = float(at_look[i])
        if i == 0 or h <= 0:
            continue
        ta, tc = parallax.unshift_xy(g.altitude_m, along, cross, h)
        r = np.floor(ny - ta / g.wfov_gsd_m + 0.5).astype(np.int64)
        c = np.floor(nx + tc / g.wfov_gsd_m + 0.5).astype(np.int64)
        todo = np.flatnonzero((r >= 0) & (r < hw) & (c >= 0) & (c < ww) & (best < 0))
        while len(todo):  # one truth band at a time, its pointings at once
            truth, r0 = ctx.truth.at(t_k, int(r[todo[0]]))
            band = (r[todo] >= r0) & (r[todo] < r0 + truth.ids.shape[0])
            band[0] = True
            js = todo[band]
            hit = truth.ids[r[js] - r0, c[js]] == int(i)
            best[js[hit]] = float(i)
            todo = todo[~band]
    for j in np.flatnonzero(best > 0):
        now = at_look if look else world.heights_at(t_k + float(ts[j]))
        out[j] = float(now[int(best[j])]) if now is not None else np.nan
    return out


def _true_height(ctx: _Pass) -> Callable[[Plume], float | None]:
    """The true top height of the truth plume a tracked plume shows (the most common id
    under its pixels' true positions, with each plume's height at its first frame's time)."""

    def true_height(p: Plume) -> float | None:
        if ctx.where is None:
            return None
        top = ctx.frames.tops[p.frame]
        pts = np.column_stack([p.cols, p.rows - top]).astype(np.float64)
        h = _true_heights(ctx, pts, np.zeros(len(pts)), p.t_k, top)
        h = h[np.isfinite(h)]
        if not len(h):
            return None
        vals, counts = np.unique(h, return_counts=True)
        return float(vals[np.argmax(counts)])

    return true_height


@dataclass(frozen=True, eq=False)
class _Todo:
    """A frame's plan less the pointings on covered pixels: what goes to the scheduler."""

    trajectory: Trajectory
    part: np.ndarray
    keep: np.ndarray
    """Indices, in the plan, of the pointings flown as planned (none within a blueprint)."""
    skipped: int
    rows: np.ndarray
    cols: np.ndarray
    """The frame pixel of every planned pointing."""


def _fly_frame(
    k: int, ctx: _Pass, state: PassState
) -> tuple[FrameRecord, np.ndarray | None, PlanResult | None]:
    """Frame ``k``: look, plan, schedule behind the committed pointings, score, record."""
    frames, config = ctx.frames, ctx.config
    t_k, top = frames.acquired_s(k), frames.tops[k]
    start = max(t_k, state.busy_until)
    wait = start - t_k
    if ctx.tracker is not None and ctx.tracker.busy_at(t_k):  # the look-ahead is re-looking
        record = FrameRecord(
            k, t_k, start, start, wait, {}, None, RELOOK_DROP, 0, 0, 0, 0, 0, 0, 0, True
        )
        return record, None, None
    if config.deadline_s is not None and wait >= config.deadline_s:  # too far behind: skip it
        record = FrameRecord(
            k, t_k, start, start, wait, {}, False, "dropped: loop behind", 0, 0, 0, 0, 0, 0, 0, True
        )
        return record, None, None
    image, valid, mask = _look(ctx, k, t_k)
    t_loop = time.perf_counter()
    result, stage, prediction = _plan_frame(ctx, k, image, valid, mask, start, state)
    heights: dict[str, float] = {}
    aim = _aim(ctx, k, _heights(ctx, k, result, image, heights)) if ctx.where else None
    t0 = time.perf_counter()
    todo = _todo(ctx, k, image, result, start, state)
    flown, ready = _schedule_frame(ctx, todo, result, prediction, t_k, start, stage, state, aim)
    stage["schedule"] = time.perf_counter() - t0
    loop_s = time.perf_counter() - t_loop
    if config.compute_budget_s is None:  # the plan is ready after all the measured work
        ready = start + sum(stage.values())
        state.schedule_s = stage["schedule"]
    stage |= heights  # the height work is off the plan's critical path (its own stage)
    _commit(flown, ready, t_k, frames.geometry, state)
    gains = _score(ctx, k, flown, todo, state)
    flown_local = todo.keep[flown.kept[flown.kept < len(todo.keep)]]  # of this frame's plan
    target_mask = result.mask if result.predicted_mask is None else result.predicted_mask
    _cover_plumes(
        target_mask, todo.rows, todo.cols, flown_local, len(result.trajectory), top, state
    )
    met = None if config.deadline_s is None else (ready - t_k) <= config.deadline_s
    record = FrameRecord(
        k, t_k, start, ready, ready - t_k, stage, met, "; ".join(result.path),
        len(result.trajectory), todo.skipped, len(flown.kept), *gains, loop_s=loop_s,
    )  # fmt: skip
    return record, image, result


def _stage_times(timings: dict[str, float]) -> dict[str, float]:
    """Classify, denoise, plan (with the deadline's overhead and any other step) and predict."""
    stage = {s: float(timings.get(s, 0.0)) for s in ("classify", "denoise", "plan")}
    stage["plan"] += sum(
        float(v) for k, v in timings.items() if k not in ("classify", "denoise", "plan")
    )
    stage["predict"] = 0.0
    return stage


def _plan_frame(
    ctx: _Pass,
    k: int,
    image: np.ndarray,
    valid: np.ndarray | None,
    mask: np.ndarray | None,
    start: float,
    state: PassState,
) -> tuple[PlanResult, dict[str, float], Prediction | None]:
    """Segment and plan frame ``k`` (under the deadline left); predictive: on the prediction.

    A predictive frame segments under the deadline with the last-resort planner
    (microseconds), estimates the motion on the denoised mask, and then plans on the
    prediction from that segmentation (:func:`_plan_on_prediction`): the pipeline runs once.
    """
    config, frames = ctx.config, ctx.frames
    t_k = frames.acquired_s(k)
    predictive = config.predict != "none"
    deadline = config.deadline_s
    result = plan_scene(
        image,
        ctx.classifier,
        LAST_RESORT if predictive else config.planner,  # predictive: plan below, on the prediction
        mask=mask,
        valid=valid,
        denoise=config.denoise,
        config=config.pipeline,
        deadline_s=None if deadline is None else deadline - (start - t_k),
        fallback=ctx.fallback,
    )
    stage = _stage_times(result.timings)
    if not predictive:
        return result, stage, None
    t0 = time.perf_counter()
    motion = _motion(ctx, k, image, result.mask, state)
    prediction = None
    if motion is not None:
        prediction = Prediction(
            motion, lead_s(frames.geometry, ctx.agility, t_k, start, state.timer_t)
        )
    stage["predict"] = time.perf_counter() - t0
    state.previous = (k, image, result.mask)
    return _plan_on_prediction(ctx, image, valid, result, prediction, stage), stage, prediction


def _plan_on_prediction(
    ctx: _Pass,
    image: np.ndarray,
    valid: np.ndarray | None,
    seen: PlanResult,
    prediction: Prediction | None,
    stage: dict[str, float],
) -> PlanResult:
    """Plan on the frame's denoised mask carried to the prediction (as seen without one).

    The segmentation is the one ``seen`` holds (no second classification or denoising);
    its time to predict adds to ``stage["predict"]``, the planning's to ``stage["plan"]``.
    """
    t0 = time.perf_counter()
    planner = ctx.config.planner
    mask = seen.mask if valid is None else seen.mask & valid
    polygons = seen.polygons if np.array_equal(mask, seen.mask) else mask_to_polygons(mask)
    seg = Segmentation(None, mask, mask, polygons, valid, image, {})
    path = list(seen.path[:-1])
    if prediction is None:
        target = seg
        path.append("predict: no motion known (planned on the look as it is)")
    else:
        target = predict_segmentation(seg, prediction)
        stage["predict"] += target.timings["predict"]
        m = prediction.motion
        path.append(f"predict: {m.regime}, {prediction.lead_s:g} s ahead ({m.source})")
    t1 = time.perf_counter()
    trajectory = plan_segmentation(target, planner, ctx.config.pipeline)
    t2 = time.perf_counter()
    stage["plan"] += (t2 - t0) - target.timings.get("predict", 0.0)  # polygons and planning
    return PlanResult(
        seen.probability, seen.raw_mask, mask, target.polygons, trajectory,
        {**target.timings, "plan": t2 - t1}, [*path, f"plan: {planner}"],
        planner=planner, prediction=prediction,
        predicted_mask=None if prediction is None else target.mask,
    )  # fmt: skip


def _todo(
    ctx: _Pass, k: int, image: np.ndarray, result: PlanResult, start: float, state: PassState
) -> _Todo:
    """The plan less repeats and covered pixels; within a blueprint, what the gate releases."""
    frames = ctx.frames
    t_k, top = frames.acquired_s(k), frames.tops[k]
    traj = result.trajectory
    shape = (frames.frame_px, frames.wfov_shape[1])
    cols = np.clip(np.floor(traj.points[:, 0] + 0.5).astype(np.int64), 0, shape[1] - 1)
    rows = np.clip(np.floor(traj.points[:, 1] + 0.5).astype(np.int64), 0, shape[0] - 1)
    flat = (rows + top) * shape[1] + cols
    _, first = np.unique(flat, return_index=True)
    repeat = np.ones(len(flat), bool)
    repeat[first] = False
    skip = state.covered.ravel()[flat] | repeat
    keep = np.flatnonzero(~skip)
    points, part = traj.points[keep], traj.part[keep]
    if ctx.gate is not None:  # refine within the blueprint: pool every plume pixel, fly the best
        on = result.mask if result.predicted_mask is None else result.predicted_mask
        pr, pc = np.nonzero(on & ~state.covered[top : top + shape[0]])
        free = max(state.timer_t, start + (ctx.config.compute_budget_s or 0.0))
        released = ctx.gate.route(t_k, top, pr + top, pc, image[2, pr, pc], free)
        points = np.stack([released[:, 1], released[:, 0] - top], axis=1).astype(np.float64)
        part = np.full(len(released), -1, np.int64)
        keep = keep[:0]  # no pointing of this frame's plan is flown as planned
    todo = Trajectory(points, np.zeros(len(points)), traj.planner)
    return _Todo(todo, part, keep, int(np.count_nonzero(skip)), rows, cols)


def _schedule_frame(
    ctx: _Pass,
    todo: _Todo,
    result: PlanResult,
    prediction: Prediction | None,
    t_k: float,
    start: float,
    stage: dict[str, float],
    state: PassState,
    aim: ParallaxAim | None = None,
) -> tuple[Schedule, float]:
    """Schedule the frame's pointings behind what the NFOV has committed to, once.

    With ``aim`` (a 3D world), every pointing is moved by the parallax correction for
    its time (:func:`~dyntarget.schedule.schedule_on_prediction` ``aim=``).

    Returns the schedule and when the plan is ready: ``start + compute_budget_s``, or
    without a budget ``start`` + the stages measured so far + the previous frame's
    scheduling time (this frame's own is known only once it is scheduled).
    """
    frames = ctx.frames
    budget = ctx.config.compute_budget_s
    ready = start + (budget if budget is not None else sum(stage.values()) + state.schedule_s)
    attached = None
    if prediction is not None and prediction.motion.regime == "mixed":
        attached = prediction.attached_mask(result.mask)
    kw: dict[str, Any] = {} if aim is None else {"aim": aim}
    flown = schedule_on_prediction(
        todo.trajectory,
        (frames.frame_px, frames.wfov_shape[1]),
        replace(frames.geometry, start_s=ready - t_k),
        ctx.agility,
        prediction,
        attached=attached,
        sensor=sensor_in_frame(state.timer_t, state.target, frames.geometry, t_k, ready),
        keep_order=True,
        **kw,
    )
    return flown, ready


def _commit(
    flown: Schedule, ready: float, t_k: float, geometry: OrbitGeometry, state: PassState
) -> None:
    """The loop is free at ``ready``; the sensor after the last pointing flown, tracking it."""
    state.busy_until = ready
    if len(flown.kept):
        state.timer_t = flown.end_s + t_k
        assert flown.end_target is not None  # set whenever a pointing was kept
        along, cross = flown.end_target
        state.target = (along + geometry.ground_speed * t_k, cross)


def _score(
    ctx: _Pass, k: int, flown: Schedule, todo: _Todo, state: PassState
) -> tuple[float, float, float, int]:
    """Score the flown pointings (:func:`dyntarget.observe.score_pointings`) and keep them.

    Returns the plume fraction, intensity and gradient gained and the plumes seen first.
    """
    frames = ctx.frames
    t_k, top = frames.acquired_s(k), frames.tops[k]
    points = flown.trajectory.points
    assert flown.times is not None  # a scheduled trajectory is timed
    t_pass = [t_k + float(t) for t in flown.times]
    if ctx.where is None:
        scores = score_pointings(points, t_pass, top, frames.wfov_shape, ctx.truth.at)
    else:  # a 3D world: each pointing is a line of sight meeting the highest plume first
        scores = score_pointings(
            points, t_pass, top, frames.wfov_shape, ctx.truth.at, sight=_sight(ctx)
        )
    new_plumes = 0
    for pid in scores.plume_id:
        if pid and pid not in state.plumes_seen:
            state.plumes_seen.add(pid)
            new_plumes += 1
    fl = state.flown
    part_of: dict[int, int] = {}
    for j in flown.kept:
        p = int(todo.part[j])
        if p not in part_of:
            part_of[p] = state.parts
            state.parts += 1
        fl.part.append(part_of[p])
    fl.x.extend(float(x) for x in points[:, 0])
    fl.y.extend(float(y) + top for y in points[:, 1])
    fl.t.extend(t_pass)
    fl.frame.extend([k] * len(t_pass))
    fl.plume.extend(scores.plume)
    fl.intensity.extend(scores.intensity)
    fl.plume_id.extend(scores.plume_id)
    if ctx.where is None:
        state.covered[scores.rows[scores.inside], scores.cols[scores.inside]] = True
    else:  # 3D: the aim is not where the look-ahead saw the plume; cover what was planned
        _cover_planned(todo.trajectory.points[flown.kept], top, state)
    return (*scores.totals(), new_plumes)


def _cover_planned(planned: np.ndarray, top: int, state: PassState) -> None:
    """Mark the look-ahead pixels of flown pointings as covered (a 3D world's pass).

    The next frames see a plume where the look-ahead sees it (its parallax included), and
    their plans are checked against ``covered`` there: marking the aims (moved by the
    parallax correction, kilometres away) would let every overlapping frame plan the same
    plume again.
    """
    hw, ww = state.covered.shape
    rows = np.floor(planned[:, 1] + 0.5).astype(np.int64) + top
    cols = np.floor(planned[:, 0] + 0.5).astype(np.int64)
    inside = (rows >= 0) & (rows < hw) & (cols >= 0) & (cols < ww)
    state.covered[rows[inside], cols[inside]] = True


def _sight(ctx: _Pass) -> Sight:
    """The NFOV's lines of sight on a 3D world (:class:`dyntarget.observe.Sight`)."""
    from dyntarget.observe import Sight

    where, world = ctx.where, ctx.world
    assert where is not None

    def heights(t: float) -> np.ndarray:
        h = world.heights_at(t)
        return np.zeros(1) if h is None else h

    return Sight(
        nadir=where.nadir,
        gsd_m=where.geometry.wfov_gsd_m,
        altitude_m=where.geometry.altitude_m,
        heights=heights,
    )


def _frame_transform(world: World, config: PassConfig, top: int) -> Affine | None:
    if world.transform is None:
        return None
    from affine import Affine

    return world.transform @ Affine.scale(config.factor) @ Affine.translation(0, top)


def _wind(config: PassConfig, world: World) -> tuple[float, float] | None:
    if config.wind_mps is not None:
        return (config.wind_mps, config.wind_from_deg or 0.0)
    wind = world.wind
    return None if wind is None else (wind.speed_mps, wind.from_deg)


def _motion(
    ctx: _Pass, k: int, image: np.ndarray, clean: np.ndarray, state: PassState
) -> Motion | None:
    """The plume's motion for frame ``k``: a wind prior, or two looks checked against it."""
    config, frames, world = ctx.config, ctx.frames, ctx.world
    prior = None
    wind = _wind(config, world)
    if wind is not None:
        prior = wind_motion(
            wind[0],
            wind[1],
            transform=_frame_transform(world, config, frames.tops[k]),
            gsd_m=world.gsd * config.factor,
        )
    if config.predict == "wind" or state.previous is None:
        return plume_motion(prior)
    k0, prev_image, prev_mask = state.previous
    offset = (k - k0) * frames.step  # rows frame k0 lies below frame k
    if frames.frame_px - offset < MIN_OVERLAP_ROWS:
        return plume_motion(prior)
    looks = (prev_image, image, prev_mask, clean)
    interval = (k - k0) * frames.cadence_s
    return plume_motion(prior, looks, interval, offset_rows=offset, ground=config.ground)


def _cover_plumes(
    mask: np.ndarray,
    rows: np.ndarray,
    cols: np.ndarray,
    flown: np.ndarray,
    planned: int,
    top: int,
    state: PassState,
) -> None:
    """Mark the area of every plume of the frame's mask that was flown enough as covered."""
    if planned == 0 or not mask.any():
        return
    n, comp = cv2.connectedComponents(mask.astype(np.uint8), connectivity=8)
    on = comp[rows, cols]
    planned_per = np.bincount(on, minlength=n)
    flown_per = np.bincount(on[flown], minlength=n) if len(flown) else np.zeros(n, np.int64)
    h = mask.shape[0]
    for i in range(1, n):
        if planned_per[i] and flown_per[i] >= COVERED_PLUME_FRACTION * planned_per[i]:
            state.covered[top : top + h][comp == i] = True
