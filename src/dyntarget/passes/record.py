"""What a pass is: its settings, where its frames lie, and the record it leaves.

The pass loop (:func:`dyntarget.fly.fly_pass`) fills these and the pass's writers
(:mod:`dyntarget.view.pass_report`) read them, so they live below both:

* :class:`PassConfig`: the settings of one pass (planner, agility, frames, prediction,
  parallax), checked once;
* :class:`FramePlan` (:func:`frame_plan`): where the look-ahead frames lie on the strip's
  WFOV grid and when they are taken (see :mod:`dyntarget.fly.loop` for the model);
* the record: a :class:`FrameRecord` per frame (one row of ``timeline.csv``), the
  :class:`Flown` pointings, and the :class:`PassResult` with its totals; a
  :class:`FrameView` of every frame for the pictures.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import asdict, dataclass, field
from functools import cached_property
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from dyntarget import defaults
from dyntarget.errors import InvalidParameterError
from dyntarget.pipeline import PipelineConfig
from dyntarget.predict import GROUNDS
from dyntarget.predict.relooks import RELOOK_FRAMES, RELOOK_KM, defers_cut, holds_relooks
from dyntarget.scene import check_factor
from dyntarget.schedule import Agility, OrbitGeometry, get_agility
from dyntarget.trajectory import Trajectory

if TYPE_CHECKING:
    from dyntarget.predict.relooks import HeightEstimate
    from dyntarget.synth.worlds import World

STAGES = ("classify", "denoise", "predict", "plan", "schedule")
"""Stages whose wall time each timeline row reports."""

PREDICT_MODES = ("none", "wind", "two-looks")
"""How a pass plans: on the look as it is, or on the plume as predicted."""
PARALLAX_MODES = ("auto", "off", "prior", "true", "estimated")
"""How a pass corrects its aim for the plumes' parallax (see :class:`PassConfig`)."""

MAX_PRIOR_HEIGHT_M = 25_000.0
"""Highest prior plume-top height accepted, metres."""
MAX_RISE_LIMIT_MPS = 500.0
"""Fastest plume-top rise the re-looks may be asked to allow for, m/s (a Plinian column's
gas-thrust region reaches a few hundred m/s; its top rises slower)."""
MAX_RELOOK_FRAMES = defaults.MAX_RELOOK_FRAMES
"""Most frames one re-look may be allowed to take (``relook_frames``)."""


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
        re-looks of the look-ahead, :mod:`dyntarget.predict.relooks`; the prior until then).
        A flat world has no parallax: every mode resolves to ``"off"`` there and the
        pass is flown exactly as without these settings.
    plume_height_m : the prior plume-top height, metres above sea level (0 < h <= 25 km);
        in ``"estimated"`` mode the fallback before or without an estimate (``None``: no
        correction until estimated).
    relook_km : how far ahead of the nadir each re-look sees the plume, km, nearest last
        (``"estimated"`` mode).
    relook_s : look-ahead time per re-look, seconds (``None``: from the agility preset's
        slew model, :func:`dyntarget.predict.relooks.relook_seconds`).
    catch_up : the regular frames due during a re-look are taken late, the look-ahead
        pitching back to them (:meth:`dyntarget.predict.relooks.HeightTracker.take`);
        ``False``: they are lost.
    max_rise_mps : where re-looks at two or more distances fit a rise, the fastest rise of
        a plume top, m/s, their windows and searches allow for (0: a steady top's search;
        100 finds the young columns of ``docs/plumes-3d.md``'s rise benchmark, at a cost on
        passes of many steady plumes).
    relook_frames : the most frames one re-look takes, a mosaic down the strip, where its
        search asks more rows than one frame holds (1: one frame, its search cut to it;
        :data:`dyntarget.predict.relooks.RELOOK_FRAMES` by default).
    relook_hold : after a re-look the look-ahead holds that re-look's pitch, where it can,
        and takes the regular frames from there, later, instead of going back (and then
        never catches up: :class:`dyntarget.predict.relooks.HeightTracker`'s ``hold``);
        ``None``, the default: where catching up is asked for and the look-ahead cannot
        gain on the ground (``slow``; :func:`dyntarget.predict.relooks.holds_relooks`);
        ``False``: never (going back, as before).
    defer_cut : the pointings a frame plans on a plume whose upwind end its top edge cuts
        are held, not flown when the frame's plan is ready: they are flown when the first
        frame that sees that end is ready, before that frame's own, aimed with the height
        measured there (:meth:`dyntarget.predict.relooks.HeightTracker.pending_ids`;
        ``"estimated"`` mode; those on that frame's rows are left to its own plan); where
        that frame gives no height, with the cut view's (``HeightTracker`` ``keep_cut``);
        where no later frame sees the plume, when the next frame taken is ready, with the
        cut view's. ``None``, the default: where frames are shorter along track than
        :data:`dyntarget.predict.relooks.DEFER_CUT_BELOW_M` (4 km;
        :func:`dyntarget.predict.relooks.defers_cut`; never with a ``predict`` mode, whose
        frames plan the predicted plume, not the ground seen). ``False``: never, flown when
        the cut frame's plan is ready, with the cut view's height (the default before 2 km
        frames were measured to gain).
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
    catch_up: bool = True
    max_rise_mps: float = 0.0
    relook_frames: int = RELOOK_FRAMES
    relook_hold: bool | None = None
    defer_cut: bool | None = None

    def __post_init__(self) -> None:
        _ = self.limits  # an unknown preset is refused here
        if self.predict not in PREDICT_MODES:
            raise InvalidParameterError(
                f"predict: expected one of {', '.join(PREDICT_MODES)}, got {self.predict!r}"
            )
        self._check_parallax()  # after predict: defer_cut is checked against it
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
        v = self.max_rise_mps
        if not (
            isinstance(v, int | float) and not isinstance(v, bool) and 0 <= v <= MAX_RISE_LIMIT_MPS
        ):
            raise InvalidParameterError(
                f"max_rise_mps: expected m/s in [0, {MAX_RISE_LIMIT_MPS:g}], got {v!r}"
            )
        n = self.relook_frames
        if not (isinstance(n, int) and not isinstance(n, bool) and 1 <= n <= MAX_RELOOK_FRAMES):
            raise InvalidParameterError(
                f"relook_frames: expected an integer in 1..{MAX_RELOOK_FRAMES}, got {n!r}"
            )
        if self.relook_hold is not None and not isinstance(self.relook_hold, bool):
            raise InvalidParameterError(
                f"relook_hold: expected true, false or null, got {self.relook_hold!r}"
            )
        if self.defer_cut is not None and not isinstance(self.defer_cut, bool):
            raise InvalidParameterError(
                f"defer_cut: expected true, false or null, got {self.defer_cut!r}"
            )
        if self.defer_cut and self.predict != "none":
            raise InvalidParameterError(
                f"defer_cut: holds pointings for a later frame that plans the same ground; "
                f"with predict {self.predict!r} a frame plans the predicted plume instead"
            )

    def resolved_defer_cut(self, geometry: OrbitGeometry, frame_px: int) -> bool:
        """Whether cut plumes' pointings are held (``defer_cut`` resolved).

        Parameters
        ----------
        geometry : OrbitGeometry
            The pass's geometry (its WFOV pixel size).
        frame_px : int
            Frame height, WFOV rows.

        Returns
        -------
        bool
            ``defer_cut`` if given, else whether the frame is shorter than 4 km
            (:func:`dyntarget.predict.relooks.defers_cut`); never with a ``predict`` mode.

        Examples
        --------
        >>> g = OrbitGeometry(wfov_gsd_m=32.0)
        >>> PassConfig().resolved_defer_cut(g, 64), PassConfig().resolved_defer_cut(g, 256)
        (True, False)
        >>> PassConfig(predict="two-looks").resolved_defer_cut(g, 64)
        False
        """
        return self.predict == "none" and defers_cut(geometry, frame_px, self.defer_cut)

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
            self.plume_height_m is None
            and self.relook_km == RELOOK_KM
            and self.relook_s is None
            and self.catch_up
            and self.max_rise_mps == 0
        ):  # no parallax settings given (or a flat world's): the record as before them
            for k in ("parallax", "plume_height_m", "relook_km", "relook_s", "catch_up"):
                d.pop(k)
        else:
            d["relook_km"] = list(self.relook_km)
        if self.max_rise_mps == 0:  # the default (records as before the setting)
            d.pop("max_rise_mps")
        if self.relook_frames == RELOOK_FRAMES:  # likewise
            d.pop("relook_frames")
        if self.relook_hold is None:  # likewise
            d.pop("relook_hold")
        if self.defer_cut is None:  # likewise
            d.pop("defer_cut")
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
    >>> from dyntarget.synth.worlds import StaticWorld
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
        The frame was not planned: the loop was behind past the deadline, or the
        look-ahead did not take it (re-looking, too late, or skipped while catching up;
        ``path`` says which).
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
RELOOK_LATE = "dropped: look-ahead re-looking, too late to catch up"
"""The path of a frame the look-ahead, behind after re-looks, could not take before the
NFOV's reach (:meth:`dyntarget.predict.relooks.HeightTracker.take`)."""
CATCH_UP_SKIP = "skipped: its ground seen by the catch-up's frames"
"""The path of a frame not taken while the look-ahead catches up: the frame seen before
it and the one taken after it see its ground."""
NOT_TAKEN = {"re-looking": RELOOK_DROP, "too late": RELOOK_LATE, "covered": CATCH_UP_SKIP}
"""The path recorded for each reason a regular frame is not taken."""

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
        The pass's true upper bound: :func:`~dyntarget.observe.bound.pass_upper_bound` as
        plain JSON values
        (:meth:`~dyntarget.observe.bound.UpperBound.as_dict`), or
        ``{"value": None, "why": ...}`` when it could not be computed (``None``: not
        asked for).
    heights : tuple of dyntarget.predict.relooks.HeightEstimate
        Per-plume top heights (``"estimated"`` or ``"prior"`` mode on a 3D world).
    is_3d : bool
        Whether the world's plumes have heights.
    parallax : str
        The parallax mode flown (:meth:`PassConfig.resolved_parallax`).
    relook_windows : tuple of (float, float)
        ``(start, end)`` pass seconds the look-ahead spent re-looking (one window may hold
        several re-looks taken straight one after another).
    relook_times : tuple of float
        Pass seconds of every re-look taken (a mosaic's first frame).
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
    """The pass's true upper bound (:func:`~dyntarget.observe.bound.pass_upper_bound`; ``None``:
    not computed)."""
    heights: tuple[HeightEstimate, ...] = ()
    """Per-plume top heights (``"estimated"`` or ``"prior"`` mode on a 3D world; empty otherwise)."""
    is_3d: bool = False
    """Whether the world's plumes have heights (the parallax figures enter :meth:`totals`)."""
    parallax: str = "off"
    """The parallax mode flown (:meth:`PassConfig.resolved_parallax`)."""
    relook_windows: tuple[tuple[float, float], ...] = ()
    """``(start, end)`` pass seconds the look-ahead spent re-looking (``"estimated"`` mode on
    a 3D world; re-looks taken straight one after another share one): frames due inside one
    are taken late or not at all."""
    relook_times: tuple[float, ...] = ()
    """Pass seconds of every re-look taken, in order (a mosaic's first frame)."""

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
            ``frames_lost_to_relooks`` (not seen at all), ``frames_caught_up`` and
            ``frames_skipped_catching_up`` (estimated heights with ``catch_up``),
            ``frames_held`` (estimated heights whose look-ahead held re-looks' pitch,
            asked for or by default: frames taken late, from a re-look's pitch held),
            ``pointings_flown_deferred`` (estimated heights holding cut plumes' pointings,
            ``defer_cut``, asked for or by default: those flown after a later frame),
            ``plumes_height_estimated``, ``height_rmse_m`` and
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

    @property
    def _catches_up(self) -> bool:
        """Whether the pass re-looked with catching up asked for (``"estimated"`` heights)."""
        config = self.config
        return self.parallax == "estimated" and config.catch_up and not self._held

    @property
    def _holds(self) -> bool:
        """Whether the pass re-looked holding the re-looks' pitch where it could."""
        return self.parallax == "estimated" and self._held

    @property
    def _held(self) -> bool:
        """Whether its look-ahead held re-looks' pitch (asked for, or by default)."""
        c, f = self.config, self.frames
        return holds_relooks(f.geometry, c.limits, f.frame_px, c.catch_up, c.relook_hold)

    @property
    def _defers(self) -> bool:
        """Whether the pass held cut plumes' pointings (asked for, or by default)."""
        c, f = self.config, self.frames
        return self.parallax == "estimated" and c.resolved_defer_cut(f.geometry, f.frame_px)

    def _late(self) -> int:
        """Frames taken after their due time (caught up, or held)."""
        return sum(
            not r.dropped and r.acquired_s > self.frames.acquired_s(r.frame) for r in self.records
        )

    def _flown_deferred(self) -> int:
        """Pointings flown after a later frame than the one whose plan they came from (the
        records count each pointing with the frame after which it flew)."""
        after = np.repeat([r.frame for r in self.records], [r.flown for r in self.records])
        return int(np.count_nonzero(after != np.asarray(self.flown.frame, np.int64)))

    def _catch_up_totals(self) -> dict[str, int]:
        """Frames the look-ahead took late after re-looks, and those it skipped meanwhile."""
        return {
            "frames_caught_up": self._late(),
            "frames_skipped_catching_up": sum(r.path == CATCH_UP_SKIP for r in self.records),
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
            "relooks": len(self.relook_times),
            "frames_lost_to_relooks": sum(
                r.path in (RELOOK_DROP, RELOOK_LATE) for r in self.records
            ),
            **(self._catch_up_totals() if self._catches_up else {}),
            **({"frames_held": self._late()} if self._holds else {}),
            **({"pointings_flown_deferred": self._flown_deferred()} if self._defers else {}),
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
