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
* **One NFOV.** Pointings are timed by the kinematics
  (:func:`dyntarget.pipeline.schedule_on_prediction`, i.e.
  :func:`~dyntarget.schedule.make_feasible`, moving pointings with a predicted
  plume) from the sensor's state (:class:`~dyntarget.schedule.SensorState`:
  when it is free, what it tracks), which carries over from frame to frame: a
  new frame's pointings queue behind those already committed. Of the plan in
  its own order and earliest-deadline-first, the order keeping more pointings
  is flown.
* **Never twice.** The pass keeps the strip's covered WFOV pixels: a
  pointing on a covered pixel is dropped before scheduling, and a plume
  (connected component of the frame's denoised mask) at least half of whose
  pointings were flown marks its whole area covered, so a plume seen again by
  the next, overlapping frame gets no new pointings.
* **Scoring.** Each flown pointing is scored against the truth *at its own
  time* (``World.truth_at``) over its NFOV footprint: plume fraction,
  intensity and gradient utility (the paper's metrics, summed over the pass).
"""

from __future__ import annotations

import math
import time
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import asdict, dataclass, field, replace
from typing import Any

import cv2
import numpy as np

from dyntarget import defaults
from dyntarget.errors import InvalidParameterError, InvalidSceneError
from dyntarget.fly.world import WfovTruth, World, wfov_truth
from dyntarget.perceive.base import Classifier
from dyntarget.pipeline import (
    LAST_RESORT,
    PipelineConfig,
    plan_scene,
    schedule_on_prediction,
    two_look_motion,
)
from dyntarget.predict import GROUNDS, Prediction, wind_motion
from dyntarget.scene import LABEL_FRACTION, block_mean, check_factor
from dyntarget.schedule import (
    Agility,
    OrbitGeometry,
    Schedule,
    SensorState,
    get_agility,
    visibility_windows,
)
from dyntarget.trajectory import Trajectory

STAGES = ("classify", "denoise", "predict", "plan", "schedule")
"""Stages whose wall time each timeline row reports."""

PREDICT_MODES = ("none", "wind", "two-looks")
"""How a pass plans: on the look as it is, or on the plume as predicted."""

MIN_OVERLAP_ROWS = 8
"""Two-look motion needs at least this many rows seen by both frames."""

COVERED_PLUME_FRACTION = 0.5
"""A plume at least this fraction of whose planned pointings were flown counts as covered."""


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

    def __post_init__(self) -> None:
        get_agility(self.agility)
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

    def as_dict(self) -> dict[str, Any]:
        """The settings as a plain dict, without ``pipeline`` (recorded with the flown trajectory).

        Returns
        -------
        dict
            Field name to value.
        """
        d = asdict(self)
        d.pop("pipeline")
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
            ratio plume, plumes observed and in total, median and largest latency.
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
        }


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
    plan : dyntarget.pipeline.PlanResult
        The pipeline's result on it.
    first, end : int
        The slice of :attr:`PassResult.flown` its plan added.
    """

    frame: int
    top: int
    image: np.ndarray
    plan: Any
    first: int
    end: int


class _TruthCache:
    """Truth on the WFOV footprints, rebuilt only when the world's truth object changes.

    A long strip (a world with ``truth_rows``) is scored band by band: ``band``
    WFOV rows at a time (with the footprint's margin), recent bands kept.
    """

    def __init__(self, world: World, factor: int, footprint: int, band: int = 64) -> None:
        self.world, self.factor, self.footprint = world, factor, footprint
        self.lazy = hasattr(world, "truth_rows")
        self.band = max(1, int(band))
        self._key: Any = None
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
        tq = self.world.quantize(t)  # type: ignore[attr-defined]
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


def _label_rows(world: World, t: float, top: int, bottom: int) -> np.ndarray:
    """The true label of high-resolution rows ``top:bottom`` at ``t`` (by rows on a long strip)."""
    rows = getattr(world, "label_rows", None)
    if rows is not None:
        return rows(t, top, bottom)
    return world.truth_at(t).maps.label[top:bottom]


def _plumes_at_start(world: World) -> frozenset[int]:
    start = getattr(world, "plumes_at_start", None)
    if start is not None:
        return frozenset(start())
    ids0 = world.truth_at(0.0).ids
    return frozenset(int(i) for i in np.unique(ids0[ids0 > 0]))


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
    geo: Any = None,
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
    from tqdm import tqdm

    frames = frame_plan(world, config)
    if config.footprint > frames.wfov_shape[1]:
        raise InvalidParameterError(
            f"footprint: {config.footprint} WFOV px is wider than the strip's "
            f"{frames.wfov_shape[1]} WFOV px (--footprint); expected at most that"
        )
    agility = get_agility(config.agility)
    if config.predict == "wind" and _wind(config, world) is None:
        raise InvalidParameterError(
            "predict: 'wind' needs a wind: give wind_mps and wind_from_deg (--wind-mps, "
            "--wind-from-deg); only synthetic strips carry their own"
        )
    truth = _TruthCache(world, config.factor, config.footprint, band=frames.frame_px)
    state = PassState(covered=np.zeros(frames.wfov_shape, bool))
    plumes_at_start = _plumes_at_start(world)
    stopped = False
    gate, geo_info, geo_times = None, None, None
    if geo is not None:
        from dyntarget.fly.geo import prepare

        gate, geo_info, geo_times = prepare(world, frames, config, geo)
        if gate is None:
            geo_info["degraded"] = "no GEO image arrived in time: flown on the look-ahead only"

    def result() -> PassResult:
        info = None if geo_info is None else {**geo_info, **(gate.report() if gate else {})}
        return PassResult(
            world.id,
            config,
            frames,
            list(state.records),
            state.flown,
            plumes_at_start,
            stopped,
            info,
            geo_times,
        )

    bar = tqdm(total=frames.n_frames, desc=f"fly {world.id}", unit="frame", disable=not progress)
    try:
        for k in range(frames.n_frames):
            before = len(state.flown.x)
            record, image, planned = _fly_frame(
                k, world, classifier, fallback, config, frames, agility, truth, state, gate
            )
            state.records.append(record)
            if frame_sink is not None and image is not None:
                frame_sink(FrameView(k, frames.tops[k], image, planned, before, len(state.flown.x)))
            bar.update()
            if on_frame is not None:
                on_frame(result())
            if should_stop is not None and should_stop() and k + 1 < frames.n_frames:
                stopped = True
                break
    finally:
        bar.close()
    final = result()
    if upper_bound:
        try:
            bound = pass_upper_bound(world, config, frames, final.records).as_dict()
        except InvalidParameterError as exc:  # e.g. a truth without a time step
            bound = {"value": None, "why": str(exc)}
        final = replace(final, upper_bound=bound)
    return final


def pass_upper_bound(
    world: World, config: PassConfig, frames: FramePlan, records: list[FrameRecord] | None = None
):
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
    """
    from dyntarget.observe.bound import upper_bound_utility, values_from_bands

    agility = get_agility(config.agility)
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
        time_step_s=getattr(world, "truth_step_s", None),  # a static world has none
        distinct=config.predict == "none",
        t_end_s=t_end,
    )


def _frame_image(world: World, frames: FramePlan, k: int, factor: int, t: float):
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


def _fly_frame(  # noqa: C901, PLR0915  (next to split: frame, plan, schedule, score)
    k: int,
    world: World,
    classifier: Classifier | None,
    fallback: Classifier | None,
    config: PassConfig,
    frames: FramePlan,
    agility: Agility,
    truth: _TruthCache,
    state: PassState,
    gate: Any = None,
) -> tuple[FrameRecord, np.ndarray | None, Any]:
    t_k = frames.acquired_s(k)
    top = frames.tops[k]
    start = max(t_k, state.busy_until)
    wait = start - t_k
    deadline = config.deadline_s
    if deadline is not None and wait >= deadline:  # the loop is too far behind: skip the frame
        record = FrameRecord(
            k, t_k, start, start, wait, {}, False, "dropped: loop behind", 0, 0, 0, 0, 0, 0, 0, True
        )
        return record, None, None
    image, valid = _frame_image(world, frames, k, config.factor, t_k)
    mask = None
    if classifier is None:  # the oracle: the truth at acquisition time, on the WFOV grid
        f, width = config.factor, frames.wfov_shape[1] * config.factor
        label = _label_rows(world, t_k, top * f, (top + frames.frame_px) * f)[:, :width]
        mask = block_mean(label[None].astype(np.float32), f)[0] >= LABEL_FRACTION
    t_loop = time.perf_counter()
    predictive = config.predict != "none"
    result = plan_scene(
        image,
        classifier,
        LAST_RESORT if predictive else config.planner,  # predictive: plan below, on the prediction
        mask=mask,
        valid=valid,
        denoise=config.denoise,
        config=config.pipeline,
        deadline_s=None if deadline is None else deadline - wait,
        fallback=fallback,
    )
    stage = {s: float(result.timings.get(s, 0.0)) for s in ("classify", "denoise", "plan")}
    stage["plan"] += sum(  # the deadline's overhead, and any other step the pipeline times
        float(v) for k, v in result.timings.items() if k not in ("classify", "denoise", "plan")
    )
    stage["predict"] = 0.0
    prediction = None
    if predictive:
        t0 = time.perf_counter()
        motion = _motion(k, image, result.mask, config, frames, world, state)
        if motion is not None:
            prediction = Prediction(motion, _lead_s(frames, agility, state, t_k, start))
        stage["predict"] = time.perf_counter() - t0
        state.previous = (k, image, result.mask)
        again = plan_scene(
            image,
            None,
            config.planner,
            mask=result.mask,
            valid=valid,
            denoise=False,
            config=config.pipeline,
            prediction=prediction,
        )
        # the second call's own mask check and polygons count as planning
        stage["predict"] += float(again.timings.get("predict", 0.0))
        stage["plan"] += sum(float(v) for k, v in again.timings.items() if k != "predict")
        path = [*result.path[:-1], *again.path[1:]]
        if prediction is None:
            path.insert(-1, "predict: no motion known (planned on the look as it is)")
        result = replace(again, probability=result.probability, raw_mask=result.raw_mask, path=path)
    t0 = time.perf_counter()
    traj = result.trajectory
    planned = len(traj)
    shape = (frames.frame_px, frames.wfov_shape[1])
    hw, ww = frames.wfov_shape
    # drop pointings on covered strip pixels (and repeats of a pixel within the plan)
    cols = np.clip(np.floor(traj.points[:, 0] + 0.5).astype(np.int64), 0, shape[1] - 1)
    rows = np.clip(np.floor(traj.points[:, 1] + 0.5).astype(np.int64), 0, shape[0] - 1)
    flat = (rows + top) * shape[1] + cols
    _, first = np.unique(flat, return_index=True)
    repeat = np.ones(len(flat), bool)
    repeat[first] = False
    skip = state.covered.ravel()[flat] | repeat
    keep = np.flatnonzero(~skip)
    todo_points, todo_part = traj.points[keep], traj.part[keep]
    if gate is not None:  # refine within the blueprint: pool every plume pixel, fly the best
        on = result.mask if result.predicted_mask is None else result.predicted_mask
        pr, pc = np.nonzero(on & ~state.covered[top : top + shape[0]])
        released = gate.route(
            t_k, top, pr + top, pc, image[2, pr, pc],
            max(state.timer_t, start + (config.compute_budget_s or 0.0)),
        )  # fmt: skip
        todo_points = np.stack([released[:, 1], released[:, 0] - top], axis=1).astype(np.float64)
        todo_part = np.full(len(released), -1, np.int64)
        keep = keep[:0]  # no pointing of this frame's plan is flown as planned
    todo = Trajectory(todo_points, np.zeros(len(todo_points)), traj.planner)
    attached = None
    if prediction is not None and prediction.motion.regime == "mixed":
        attached = prediction.attached_mask(result.mask)

    def fly_from(ready: float) -> Schedule:  # the kinematics, behind the committed pointings
        return schedule_on_prediction(
            todo,
            shape,
            replace(frames.geometry, start_s=ready - t_k),
            agility,
            prediction,
            attached=attached,
            sensor=_sensor(state, frames.geometry, t_k, ready),
            keep_order=True,
        )

    # schedule what is left behind what the NFOV has already committed to
    budget = config.compute_budget_s
    if budget is not None:
        ready = start + budget
        flown = fly_from(ready)
        stage["schedule"] = time.perf_counter() - t0
        loop_s = time.perf_counter() - t_loop
    else:  # timed once to measure it, then re-timed from when the plan is really ready
        fly_from(start + sum(stage.values()))
        stage["schedule"] = time.perf_counter() - t0
        loop_s = time.perf_counter() - t_loop
        ready = start + sum(stage.values())
        flown = fly_from(ready)
    sched_t, points = flown.times, flown.trajectory.points
    assert sched_t is not None  # a scheduled trajectory is timed
    met = None if deadline is None else (ready - t_k) <= deadline
    flown_local = keep[flown.kept[flown.kept < len(keep)]]  # of this frame's plan
    state.busy_until = ready
    if len(flown.kept):
        state.timer_t = flown.end_s + t_k
        assert flown.end_target is not None  # set whenever a pointing was kept
        along, cross = flown.end_target
        state.target = (along + frames.geometry.ground_speed * t_k, cross)
    # score each flown pointing against the truth at its own time
    plume_sum = inten_sum = grad_sum = 0.0
    new_plumes = 0
    fl = state.flown
    part_of = {}
    for j, (x, y), t_local in zip(flown.kept, points, sched_t, strict=True):
        r, c = int(np.floor(y + 0.5)) + top, int(np.floor(x + 0.5))
        t_pass = t_k + float(t_local)
        pl = it = gr = 0.0
        pid = 0
        if 0 <= r < hw and 0 <= c < ww:
            w, b0 = truth.at(t_pass, r)
            rb = r - b0
            if w.valid[rb, c]:
                pl, it, gr = (
                    float(w.plume[rb, c]),
                    float(w.intensity[rb, c]),
                    float(w.gradient[rb, c]),
                )
                pid = int(w.ids[rb, c]) if pl > 0 else 0
        plume_sum, inten_sum, grad_sum = plume_sum + pl, inten_sum + it, grad_sum + gr
        if pid and pid not in state.plumes_seen:
            state.plumes_seen.add(pid)
            new_plumes += 1
        p = int(todo_part[j])
        if p not in part_of:
            part_of[p] = state.parts
            state.parts += 1
        fl.x.append(float(x))
        fl.y.append(float(y) + top)
        fl.t.append(t_pass)
        fl.frame.append(k)
        fl.part.append(part_of[p])
        fl.plume.append(pl)
        fl.intensity.append(it)
        fl.plume_id.append(pid)
        if 0 <= r < hw and 0 <= c < ww:
            state.covered[r, c] = True
    target_mask = result.mask if result.predicted_mask is None else result.predicted_mask
    _cover_plumes(target_mask, rows, cols, flown_local, planned, top, state)
    record = FrameRecord(
        k,
        t_k,
        start,
        ready,
        ready - t_k,
        stage,
        met,
        "; ".join(result.path),
        planned,
        int(np.count_nonzero(skip)),
        len(flown.kept),
        plume_sum,
        inten_sum,
        grad_sum,
        new_plumes,
        loop_s=loop_s,
    )
    return record, image, result


def _frame_transform(world: World, config: PassConfig, top: int):
    if world.transform is None:
        return None
    from affine import Affine

    return world.transform @ Affine.scale(config.factor) @ Affine.translation(0, top)


def _wind(config: PassConfig, world: World) -> tuple[float, float] | None:
    if config.wind_mps is not None:
        return (config.wind_mps, config.wind_from_deg or 0.0)
    wind = getattr(world, "wind", None)
    return None if wind is None else (wind.speed_mps, wind.from_deg)


def _motion(k, image, clean, config: PassConfig, frames: FramePlan, world: World, state):
    """The plume's motion for frame ``k``: a wind prior, or two looks checked against it."""
    top = frames.tops[k]
    prior = None
    wind = _wind(config, world)
    if wind is not None:
        prior = wind_motion(
            wind[0],
            wind[1],
            transform=_frame_transform(world, config, top),
            gsd_m=world.gsd * config.factor,
        )
    if config.predict == "wind" or state.previous is None:
        return prior
    k0, prev_image, prev_mask = state.previous
    offset = (k - k0) * frames.step  # rows frame k0 lies below frame k
    if frames.frame_px - offset < MIN_OVERLAP_ROWS:
        return prior
    return two_look_motion(
        prev_image,
        image,
        (k - k0) * frames.cadence_s,
        previous_mask=prev_mask,
        current_mask=clean,
        prior=prior,
        offset_rows=offset,
        ground=config.ground,
    )


def _lead_s(frames: FramePlan, agility: Agility, state: PassState, t_k: float, start: float):
    """When the NFOV will be on the frame: its centre enters the field of regard, or later."""
    g = frames.geometry
    t_in, _ = visibility_windows(g, agility, np.array([g.look_ahead_m]), np.array([0.0]))
    enter = float(t_in[0]) if np.isfinite(t_in[0]) else 0.0
    return max(enter, max(start, state.timer_t) - t_k, 0.0)


def _sensor(state: PassState, geometry: OrbitGeometry, t_k: float, ready: float) -> SensorState:
    """The shared NFOV's state for frame ``k`` (acquired ``t_k``), in the frame's time and ground."""
    target = state.target
    if target is not None:  # pass ground coordinates -> the frame's (nadir at t_k)
        target = (target[0] - geometry.ground_speed * t_k, target[1])
    return SensorState(max(ready, state.timer_t) - t_k, target)


def _cover_plumes(mask, rows, cols, flown, planned, top, state: PassState) -> None:
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
