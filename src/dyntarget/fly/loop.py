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
  re-looks of the look-ahead (``"estimated"``, :mod:`dyntarget.predict.relooks`, whose
  cost is look-ahead time: the frames due while it re-looks are taken late, catching up,
  or lost; :meth:`~dyntarget.predict.relooks.HeightTracker.take` decides when each frame
  is taken, and a late frame is the look from the nadir at its own time, ``t_k`` staying
  its reference for the schedule). The schedule is decided once, at the
  frame's plan time, with the aim each pointing will have when flown (the estimate
  from when it is usable, the prior before; without a prior, a pointing waits for its
  plume's estimate and is not flown at a plume that has none); a flight system would
  re-plan then.
* **Prediction.** ``predict`` asks the predict stage's entry point
  (:func:`dyntarget.predict.plume_motion`) for the motion, and plans once on the
  frame's segmentation carried to the lead (:func:`dyntarget.schedule.lead_s`).

The pass's settings, frame plan and record (:class:`~dyntarget.passes.record.PassConfig`,
:class:`~dyntarget.passes.record.FramePlan`, :class:`~dyntarget.passes.record.PassResult`)
live in :mod:`dyntarget.passes.record`, below both this loop and the pass's writers
(:mod:`dyntarget.view.pass_report`); what the loop reads of the world on its WFOV grid in
:mod:`dyntarget.synth.worlds` (:func:`~dyntarget.synth.worlds.wfov_look`,
:class:`~dyntarget.synth.worlds.TruthBands`), and the pass's upper bound in
:func:`dyntarget.observe.bound.pass_upper_bound`.
"""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

import cv2
import numpy as np

from dyntarget.errors import InvalidParameterError
from dyntarget.masks import mask_to_polygons
from dyntarget.observe import score_pointings
from dyntarget.observe.bound import pass_upper_bound
from dyntarget.passes.record import (
    NOT_TAKEN,
    Flown,
    FramePlan,
    FrameRecord,
    FrameView,
    PassConfig,
    PassResult,
    frame_plan,
)
from dyntarget.perceive.base import Classifier
from dyntarget.pipeline import (
    LAST_RESORT,
    PlanResult,
    Segmentation,
    plan_scene,
    plan_segmentation,
    predict_segmentation,
)
from dyntarget.predict import Motion, Prediction, plume_motion, wind_motion
from dyntarget.predict.relooks import Geometry3D, HeightTracker, Plume
from dyntarget.schedule import (
    Agility,
    OrbitGeometry,
    Schedule,
    lead_s,
    schedule_on_prediction,
    sensor_in_frame,
)
from dyntarget.schedule.aim import plume_of
from dyntarget.synth.worlds import TruthBands, World, wfov_look
from dyntarget.trajectory import Trajectory

if TYPE_CHECKING:
    from affine import Affine

    from dyntarget.observe import Sight
    from dyntarget.observe.bound import UpperBound
    from dyntarget.passes.geo import Gate, GeoSettings
    from dyntarget.schedule import ParallaxAim


MIN_OVERLAP_ROWS = 8
"""Two-look motion needs at least this many rows seen by both frames."""

COVERED_PLUME_FRACTION = 0.5
"""A plume at least this fraction of whose planned pointings were flown counts as covered."""


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
    target_height_m : float
        Height of what it tracks above ``target``, metres (a plume top it observed; 0:
        the ground).
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
    late_s : dict of int to float
        When each frame taken late was taken (the look-ahead catching up after a
        re-look, :meth:`~dyntarget.predict.relooks.HeightTracker.take`), pass seconds.
    deferred : list of _Deferred
        ``defer_cut``: pointings planned on plumes still measured provisionally, held until
        a later frame measures them again or no longer sees them.
    """

    covered: np.ndarray
    timer_t: float = 0.0
    target: tuple[float, float] | None = None  # (along, cross) in pass ground coordinates, m
    target_height_m: float = 0.0  # the height above it of what the NFOV tracks (a plume top)
    busy_until: float = 0.0  # when the loop finished its last frame
    previous: tuple[int, np.ndarray, np.ndarray] | None = None  # (frame, image, mask) last seen
    parts: int = 0
    schedule_s: float = 0.0  # the last frame's scheduling time (measured latency only)
    plumes_seen: set[int] = field(default_factory=set)
    records: list[FrameRecord] = field(default_factory=list)
    flown: Flown = field(default_factory=Flown)
    late_s: dict[int, float] = field(default_factory=dict)  # frames taken late: when
    deferred: list[_Deferred] = field(default_factory=list)  # defer_cut's held pointings


@dataclass(frozen=True, eq=False)
class _Pass:
    """What every frame of one pass shares."""

    world: World
    classifier: Classifier | None
    fallback: Classifier | None
    config: PassConfig
    frames: FramePlan
    agility: Agility
    truth: TruthBands
    gate: Gate | None
    mode: str = "off"
    """The parallax mode flown (:meth:`PassConfig.resolved_parallax`)."""
    where: Geometry3D | None = None
    """The spacecraft's track on the strip (a 3D world only)."""
    tracker: HeightTracker | None = None
    """Plumes, re-looks and heights (``"estimated"``/``"prior"`` on a 3D world)."""
    defer: bool = False
    """Whether cut plumes' pointings are held (``defer_cut`` resolved; estimated heights)."""


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
    world : the strip (:class:`~dyntarget.synth.worlds.World`).
    classifier : a fitted classifier; ``None`` plans on the truth mask at each
        frame's acquisition time (the oracle classifier).
    config : pass settings.
    fallback : a cheaper classifier for the deadline.
    on_frame : called with the pass so far after every frame (e.g. to write outputs).
    should_stop : polled after every frame; true ends the pass early (``stopped``).
    progress : show a progress bar (tqdm) over the frames.
    frame_sink : called with every frame's :class:`~dyntarget.passes.record.FrameView`
        (e.g. to draw the pass).
    geo : :class:`dyntarget.passes.geo.GeoSettings`: plan a blueprint over the pass from
        the GEO stream of the strip's world and refine every frame within it
        (:mod:`dyntarget.passes.geo`); ``None``: look-ahead only.
    upper_bound : also compute the pass's true upper bound
        (:func:`dyntarget.observe.bound.pass_upper_bound`,
        :attr:`~dyntarget.passes.record.PassResult.upper_bound`): seconds on a short strip,
        minutes on a long one.

    Returns
    -------
    PassResult

    Examples
    --------
    >>> from dyntarget.scene import Scene
    >>> from dyntarget.synth.worlds import StaticWorld
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
            relook_times=() if tracker is None else tuple(sorted(r.t_s for r in tracker.taken)),
        )  # fmt: skip

    stopped = _fly_frames(ctx, state, result, on_frame, should_stop, progress, frame_sink)
    final = result(stopped)
    if upper_bound:
        try:
            bound = _upper_bound(ctx, final.records).as_dict()
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
    truth = TruthBands(world, config.factor, config.footprint, band=frames.frame_px)
    gate, geo_info, geo_times = None, None, None
    if geo is not None:
        from dyntarget.passes.geo import prepare

        gate, geo_info, geo_times = prepare(world, frames, config, geo)
        if gate is None:
            geo_info["degraded"] = "no GEO image arrived in time: flown on the look-ahead only"
    ctx = _Pass(world, classifier, fallback, config, frames, config.limits, truth, gate)
    mode = config.resolved_parallax(world.is_3d)
    if world.is_3d:
        where = Geometry3D(
            frames.geometry, frames.wfov_shape, frames.frame_px, frames.tops[0], config.factor
        )
        tracker = None
        defer = mode == "estimated" and config.resolved_defer_cut(frames.geometry, frames.frame_px)
        if mode in ("estimated", "prior"):
            wind = _wind(config, world)
            prior = None
            if wind is not None:
                rad = math.radians(wind[1])  # blows from: moves the other way
                prior = (-wind[0] * math.sin(rad), -wind[0] * math.cos(rad))
            tracker = HeightTracker(
                where, config.limits, config.relook_km, config.relook_s, config.plume_height_m,
                prior, measure=mode == "estimated", log=_stderr, catch_up=config.catch_up,
                max_rise_mps=config.max_rise_mps, fit_s=config.compute_budget_s,
                relook_frames=config.relook_frames, hold=config.relook_hold, keep_cut=defer,
            )  # fmt: skip
        ctx = replace(ctx, mode=mode, where=where, tracker=tracker, defer=defer)
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


def _upper_bound(ctx: _Pass, records: list[FrameRecord]) -> UpperBound:
    """The pass's true upper bound (:func:`dyntarget.observe.bound.pass_upper_bound`)."""
    frames, world = ctx.frames, ctx.world
    return pass_upper_bound(
        TruthBands(world, ctx.config.factor, ctx.config.footprint, band=frames.frame_px).at,
        frames.wfov_shape, frames.frame_px, frames.geometry, ctx.agility,
        time_step_s=world.truth_step_s,  # a static world has none
        distinct=ctx.config.predict == "none",
        ready_s=[r.ready_s for r in records if not r.dropped],
        is_3d=world.is_3d, world_id=world.id,
    )  # fmt: skip


def _look(
    ctx: _Pass, k: int, t_k: float
) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
    """Frame ``k``'s WFOV image, valid pixels and (the oracle: no classifier) true mask
    (:func:`~dyntarget.synth.worlds.wfov_look`); a 3D world's: the oblique look from the
    nadir at ``t_k``."""
    config, frames = ctx.config, ctx.frames
    oblique: dict[str, Any] = {}
    if ctx.where is not None:
        oblique = {"nadir_xy": ctx.where.nadir_hr(t_k), "altitude_m": config.altitude_m}
    return wfov_look(
        ctx.world, t_k, frames.tops[k], frames.frame_px, config.factor, frames.wfov_shape[1],
        oracle=ctx.classifier is None, what=f"frame {k}", **oblique,
    )  # fmt: skip


def _render(
    ctx: _Pass, spent: list[float]
) -> Callable[[float, int, tuple[float, float]], np.ndarray]:
    """The plume mask a re-look shows (:data:`dyntarget.predict.relooks.Render`): the oracle's
    (the look's label, as a frame's) or the pass's classifier's on the look's WFOV image;
    the world's rendering time is added to ``spent`` (the simulator's, not the height work's).
    """
    config, frames, classifier = ctx.config, ctx.frames, ctx.classifier

    def render(t: float, top: int, nadir: tuple[float, float]) -> np.ndarray:
        t0 = time.perf_counter()
        image, _, mask = wfov_look(
            ctx.world, t, top, frames.frame_px, config.factor, frames.wfov_shape[1],
            oracle=classifier is None, nadir_xy=nadir, altitude_m=config.altitude_m,
            what="re-look",
        )  # fmt: skip
        spent[0] += time.perf_counter() - t0
        if mask is not None:
            return mask
        assert classifier is not None
        return np.asarray(classifier.predict(image), bool)

    return render


def _heights(
    ctx: _Pass,
    k: int,
    t_look: float,
    result: PlanResult,
    image: np.ndarray,
    stage: dict[str, float],
) -> np.ndarray | None:
    """Track frame ``k``'s plumes (taken at ``t_look``) and measure new ones
    (``stage["heights"]``: the compute, not the simulator's rendering of the re-looks); the
    frame's plume-id map (``None``: no tracker)."""
    tracker, frames = ctx.tracker, ctx.frames
    if tracker is None:
        return None
    spent = [0.0]
    t0 = time.perf_counter()
    target = result.mask if result.predicted_mask is None else result.predicted_mask
    t_k = frames.acquired_s(k)
    pids = tracker.frame(
        k, t_look, frames.tops[k], target, _render(ctx, spent),
        last=k == frames.n_frames - 1, raw=result.raw_mask,
        due=t_k if t_look > t_k else None,
    )  # fmt: skip
    stage["heights"] = time.perf_counter() - t0 - spent[0]
    return pids


def _aim(ctx: _Pass, k: int, pids: np.ndarray | None, t_look: float) -> ParallaxAim | None:
    """The parallax correction of frame ``k``'s pointings, the frame taken at ``t_look``
    (``None``: not corrected).

    Each pointing's height: ``"prior"``, the prior; ``"estimated"``, its plume's estimate
    from when it is usable (:meth:`~dyntarget.predict.relooks.HeightTracker.height_at`), the
    prior before; without a prior, a pointing on a tracked plume is flown only while its
    plume's height is known (:meth:`~dyntarget.predict.relooks.HeightTracker.known_window`:
    held until the estimate is usable, never where there is none); ``"true"``, the true
    top height, at the pointing's time, of the truth's plume whose top the look-ahead saw
    there (of the plumes with a height, the highest whose true position under the
    pointing, seen from the look-ahead at the acquisition, holds it).
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
            at = t_look if look else None
            return np.array(
                [
                    tracker.height_at(int(i), t_k + float(t), None if at is None else at)
                    for i, t in zip(plume_ids(pts), ts, strict=True)
                ],
                np.float64,
            )

        return heights_m

    def plume_ids(pts: np.ndarray) -> np.ndarray:
        """The tracked plume under each pointing (0: none), by the frame's plume-id map."""
        assert pids is not None
        rows = np.floor(pts[:, 1] + 0.5).astype(np.int64)
        cols = np.floor(pts[:, 0] + 0.5).astype(np.int64)
        inside = (rows >= 0) & (rows < shape[0]) & (cols >= 0) & (cols < shape[1])
        pid = np.zeros(len(pts), np.int64)
        pid[inside] = pids[rows[inside], cols[inside]]
        return pid

    def known_s(points: np.ndarray) -> np.ndarray:
        """When each pointing's plume height is known, seconds after ``t_k`` (NaN: on no
        tracked plume)."""
        assert tracker is not None
        pid = plume_ids(np.asarray(points, np.float64).reshape(-1, 2))
        out = np.full((len(pid), 2), np.nan)
        for i in np.unique(pid[pid > 0]):  # one window per plume, not per pointing
            out[pid == i] = tracker.known_window(int(i))
        return out - t_k

    del where  # the top the look-ahead saw at t_k, then where the NFOV meets it at its time
    held = (  # with a prior no pointing waits: the prior aims it until the estimate
        ctx.mode == "estimated" and pids is not None
        and tracker is not None and tracker.prior_m is None
    )  # fmt: skip
    return ParallaxAim(
        frames.geometry, shape, field(look=False), field(look=True), look_s=t_look - t_k,
        fill_px=_fill_px(ctx), known_s=known_s if held else None,
    )  # fmt: skip


def _fill_px(ctx: _Pass) -> float:
    """How near a pointing off every plume lies to one on a plume whose heights it is aimed
    with (:attr:`~dyntarget.schedule.ParallaxAim.fill_px`), WFOV px: twice the plan's
    transect spacing (a plume's pointings lie this close)."""
    frames = ctx.frames
    _, spacing = ctx.config.pipeline.plan.resolved((frames.frame_px, frames.wfov_shape[1]))
    return 2.0 * spacing


def _true_heights(
    ctx: _Pass, pts: np.ndarray, ts: np.ndarray, t_k: float, top: int, *, look: bool = False
) -> np.ndarray:
    """``"true"`` mode: each pointing's true plume-top height (:func:`_aim`; NaN where none,
    :meth:`~dyntarget.synth.worlds.TruthBands.true_heights`); ``look``: its height when the
    look-ahead saw it (``t_k``), else at the pointing's time."""
    where = ctx.where
    assert where is not None
    g = where.geometry
    return ctx.truth.true_heights(
        pts, ts, t_k, top, nadir=where.nadir(t_k), altitude_m=g.altitude_m,
        gsd_m=g.wfov_gsd_m, look=look,
    )  # fmt: skip


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
    t_look = t_k  # when the look-ahead takes it: later when it is behind after a re-look
    if ctx.tracker is not None:
        last = k + 1 >= frames.n_frames
        nxt = None if last else (frames.tops[k + 1], frames.acquired_s(k + 1))
        taken, why = ctx.tracker.take(t_k, top, nxt)
        if taken is None:
            start = max(t_k, state.busy_until)
            record = FrameRecord(
                k, t_k, start, start, start - t_k, {}, None, NOT_TAKEN[why],
                0, 0, 0, 0, 0, 0, 0, True,
            )  # fmt: skip
            return record, None, None
        if taken > t_k:
            t_look = state.late_s[k] = taken
    start = max(t_look, state.busy_until)
    wait = start - t_look
    if config.deadline_s is not None and wait >= config.deadline_s:  # too far behind: skip it
        record = FrameRecord(
            k, t_look, start, start, wait, {}, False, "dropped: loop behind",
            0, 0, 0, 0, 0, 0, 0, True,
        )  # fmt: skip
        return record, None, None
    if ctx.tracker is not None:
        ctx.tracker.seen(top)  # its ground is seen: what catching up may skip next
    image, valid, mask = _look(ctx, k, t_look)
    t_loop = time.perf_counter()
    result, stage, prediction = _plan_frame(ctx, k, image, valid, mask, start, state)
    heights: dict[str, float] = {}
    aim = None
    pids = None
    if ctx.where:
        pids = _heights(ctx, k, t_look, result, image, heights)
        aim = _aim(ctx, k, pids, t_look)
    t0 = time.perf_counter()
    todo = _todo(ctx, k, image, result, start, state)
    released: list[tuple[_Deferred, Schedule]] = []
    deferring = ctx.tracker if ctx.defer else None
    if deferring is not None and pids is not None:
        pending = deferring.pending_ids()
        released = _fly_released(ctx, k, pids, pending, start, stage, state)
        todo = _defer_plumes(
            k, t_look, todo, pids, pending, result, prediction, state, _fill_px(ctx)
        )
    flown, ready = _schedule_frame(ctx, todo, result, prediction, t_k, start, stage, state, aim)
    stage["schedule"] = time.perf_counter() - t0
    loop_s = time.perf_counter() - t_loop
    if config.compute_budget_s is None:  # the plan is ready after all the measured work
        ready = start + sum(stage.values())
        state.schedule_s = stage["schedule"]
    stage |= heights  # the height work is off the plan's critical path (its own stage)
    _commit(flown, ready, t_k, frames.geometry, state)
    # earlier frames' held pointings (``defer_cut``) were flown first: scored first
    before = [_score(ctx, d.k, held, d.todo, state) for d, held in released]
    gains = _score(ctx, k, flown, todo, state)
    for g in before:
        gains = _sum_gains(g, gains)
    flown_local = todo.keep[flown.kept[flown.kept < len(todo.keep)]]  # of this frame's plan
    target_mask = result.mask if result.predicted_mask is None else result.predicted_mask
    _cover_plumes(
        target_mask, todo.rows, todo.cols, flown_local, len(result.trajectory), top, state
    )
    met = None if config.deadline_s is None else (ready - t_look) <= config.deadline_s
    n_flown = len(flown.kept) + sum(len(held.kept) for _, held in released)
    record = FrameRecord(
        k, t_look, start, ready, ready - t_look, stage, met, "; ".join(result.path),
        len(result.trajectory), todo.skipped, n_flown, *gains, loop_s=loop_s,
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
    t_look = state.late_s.get(k, t_k)
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
        deadline_s=None if deadline is None else deadline - (start - t_look),
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
    drawn = prediction
    if prediction is not None and t_look > t_k:  # a late frame saw the plume later: less to go
        drawn = replace(prediction, lead_s=prediction.lead_s - (t_look - t_k))
    return _plan_on_prediction(ctx, image, valid, result, drawn, stage), stage, prediction


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


def _split_plumes(
    todo: _Todo, pids: np.ndarray, skip: set[int], fill_px: float
) -> tuple[_Todo, dict[int, _Todo]]:
    """``todo`` less its pointings on the tracked plumes ``skip`` (by the frame's plume-id
    map ``pids``, a pointing off every plume by the one whose heights it is aimed with,
    :func:`~dyntarget.schedule.aim.plume_of` within ``fill_px``; counted as skipped), and
    those pointings, plume by plume: ``defer_cut``'s plumes, held for a later frame
    (:func:`_defer_plumes`)."""
    points = todo.trajectory.points
    if not skip or not len(points) or len(todo.keep) != len(points):  # none, or a blueprint's
        return todo, {}
    on = plume_of(points, pids[todo.rows[todo.keep], todo.cols[todo.keep]], fill_px)
    keep = ~np.isin(on, list(skip))
    if keep.all():
        return todo, {}

    held = {int(i): _subset(todo, on == i, 0) for i in np.unique(on[~keep])}
    return _subset(todo, keep, todo.skipped + int(np.count_nonzero(~keep))), held


def _subset(todo: _Todo, sel: np.ndarray, skipped: int) -> _Todo:
    """The pointings ``sel`` (a mask over ``todo``'s) of ``todo``, ``skipped`` counted."""
    n = int(np.count_nonzero(sel))
    trajectory = Trajectory(todo.trajectory.points[sel], np.zeros(n), todo.trajectory.planner)
    return _Todo(trajectory, todo.part[sel], todo.keep[sel], skipped, todo.rows, todo.cols)


def _sum_gains(
    a: tuple[float, float, float, int], b: tuple[float, float, float, int]
) -> tuple[float, float, float, int]:
    """Two :func:`_score` results added."""
    return a[0] + b[0], a[1] + b[1], a[2] + b[2], a[3] + b[3]


@dataclass(frozen=True, eq=False)
class _Deferred:
    """Frame ``k``'s pointings on plume ``pid``, held (``defer_cut``): the plume was measured
    provisionally on a view that cut its upwind end."""

    k: int
    t_look: float
    pid: int
    todo: _Todo
    pids: np.ndarray
    result: PlanResult
    prediction: Prediction | None


def _defer_plumes(
    k: int,
    t_look: float,
    todo: _Todo,
    pids: np.ndarray,
    pending: set[int],
    result: PlanResult,
    prediction: Prediction | None,
    state: PassState,
    fill_px: float,
) -> _Todo:
    """Frame ``k``'s ``todo`` less its pointings on the plumes still measured provisionally
    (``pending``; none after the last frame, which measures them all; those off every plume
    by the plume they are aimed with, within ``fill_px``: :func:`_split_plumes`), which
    ``state.deferred`` holds for a later frame (:func:`_fly_released`)."""
    todo, held = _split_plumes(todo, pids, pending, fill_px)
    state.deferred.extend(
        _Deferred(k, t_look, pid, part, pids, result, prediction) for pid, part in held.items()
    )
    return todo


def _released(
    deferred: list[_Deferred], pending: set[int], pids: np.ndarray
) -> tuple[list[_Deferred], list[_Deferred]]:
    """The held pointings to fly now and those still held: a plume's are released once it
    is no longer ``pending`` (measured again) or the frame (plume-id map ``pids``) no
    longer shows it; each list in the order the pointings were held."""
    seen = set(np.unique(pids).tolist())
    go = [d for d in deferred if d.pid not in pending or d.pid not in seen]
    return go, [d for d in deferred if d.pid in pending and d.pid in seen]


def _fly_released(
    ctx: _Pass,
    k: int,
    pids: np.ndarray,
    pending: set[int],
    start: float,
    stage: dict[str, float],
    state: PassState,
) -> list[tuple[_Deferred, Schedule]]:
    """Schedule and commit the held pointings (``defer_cut``) whose plume frame ``k``
    (plume-id map ``pids``) measured again (no longer ``pending``) or no longer sees (no later
    frame would: they would be lost), in the order they were planned, before frame ``k``'s
    own; each aims with its plume's latest estimate. Those on frame ``k``'s rows are not
    flown: frame ``k`` plans that ground again, seen whole. Returns them with their
    schedules, for :func:`_score` (the simulator's work, not timed with the schedule's)."""
    if not state.deferred:
        return []
    go, state.deferred = _released(state.deferred, pending, pids)
    frames = ctx.frames
    below = frames.tops[k] + frames.frame_px  # the first strip row behind frame k
    out = []
    for d in go:
        todo = _behind(d.todo, below - frames.tops[d.k])
        if not len(todo.trajectory.points):
            continue
        t_d = frames.acquired_s(d.k)
        aim = _aim(ctx, d.k, d.pids, d.t_look)
        flown, ready = _schedule_frame(
            ctx, todo, d.result, d.prediction, t_d, start, stage, state, aim
        )
        _commit(flown, ready, t_d, frames.geometry, state)
        out.append((replace(d, todo=todo), flown))
    return out


def _behind(todo: _Todo, row: int) -> _Todo:
    """``todo``'s pointings on frame rows ``row`` and after (behind a later frame whose
    last row is ``row - 1`` on this frame's rows)."""
    sel = todo.rows[todo.keep] >= row
    return todo if sel.all() else _subset(todo, sel, 0)


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
        sensor=sensor_in_frame(
            state.timer_t, state.target, frames.geometry, t_k, ready, state.target_height_m
        ),
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
        state.target_height_m = flown.end_height_m


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
    if state.late_s:  # frames taken late, catching up after a re-look
        interval += state.late_s.get(k, frames.acquired_s(k)) - frames.acquired_s(k)
        interval -= state.late_s.get(k0, frames.acquired_s(k0)) - frames.acquired_s(k0)
        if not interval > 0:  # two looks taken at once (no settling, no exposure)
            return plume_motion(prior)
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
