"""Plume-top heights measured on a pass: re-looks of the look-ahead, their cost, the estimates.

A 3D world's plumes appear displaced by their parallax in the look-ahead frames
(:mod:`dyntarget.parallax`). The pass loop (:mod:`dyntarget.fly.loop`) corrects its
NFOV aim for it with a height per plume; in ``"estimated"`` mode that height is
measured here, from the look-ahead stream itself.

Model (what is and is not modelled):

* **Plumes.** A connected component of a frame's denoised mask with at least
  :data:`MIN_PLUME_PX` WFOV pixels is a plume. It is the plume already tracked when
  it overlaps (within :data:`MATCH_PX` pixels) the apparent footprint of one tracked
  plume on the strip's WFOV grid (the look-ahead's parallax changes by a fraction of a
  pixel between overlapping frames); otherwise it is new, and measured at once (the
  frame's own pointings need its height). A new plume too small for a re-look and
  touching the frame's top edge (the side ahead, cut by the frame) waits for the next
  frame, which sees more of it (the last frame does not wait).
* **Re-looks.** For a new plume of at least :data:`MIN_RELOOK_PX` pixels the
  look-ahead re-points at it when its apparent centre (as frame ``k`` saw it) is
  ``relook_km[i]`` ahead of the nadir, one re-look per distance: at ``t_k + (along_k -
  d_i) / v``. A re-look sees a window of the frame's size on the strip: frame ``k``'s
  rows moved by the disparity the prior height predicts (where the plume will appear),
  clipped to the strip. It occupies the look-ahead for ``relook_s`` (the pitch change
  there and back on the agility preset's slew model, two settles and one exposure:
  :func:`relook_seconds`); a regular frame acquired meanwhile is not taken (the loop
  records it dropped) - that is the cost. A re-look that would start while the
  look-ahead is busy with another waits for it, at most one re-look's duration, else
  it is not taken. All the plumes of one frame share its re-looks.
* **Measurement.** The plume's apparent displacement between frame ``k`` and each
  re-look is :func:`dyntarget.predict.height.plume_disparity` (inside the component,
  the prior's disparity as the guess, searched over the frame's height); the looks'
  apparent positions (the component's centroid, moved by each disparity) and the
  nadir at each look's time go to :func:`~dyntarget.predict.height.fit_height` with a
  Gaussian wind prior (the pass's wind, else the world's own wind: an ideal forecast,
  sigma :data:`WIND_PRIOR_SIGMA_MPS`). Positions are given a standard deviation of
  :data:`POSITION_SIGMA_PX` WFOV pixels (the fit scales its covariance up when the
  residuals say more). Everything is measured at the look-ahead's WFOV resolution.
* **When it is known.** The simulator renders a plume's re-looks as soon as its frame
  is planned (the world is known), but the estimate is usable only from ``t_e`` = the
  last re-look's time + the measured compute time of the measurement and fit: the
  NFOV's pointings flown at or after ``t_e`` aim with the estimate, earlier ones with
  the prior (or not corrected). The schedule is decided once at the frame's plan time
  with the aim each pointing will have when flown; a flight system would re-plan at
  ``t_e``.
* **Failures.** A plume too small for a re-look, one whose re-looks the look-ahead
  had no time for, one too thin or without texture for the flow, a degenerate fit or
  one whose standard deviation exceeds :data:`MAX_SIGMA_M`
  keeps the prior (``height_source`` ``"prior"``) or nothing (``"none"``), with one
  line on stderr naming the plume and the reason.
* **Known bias:** the wind prior is the wind, but the shape of a plume attached to
  its vent does not drift with the wind between looks (the wind blows through it):
  an along-track wind then biases the height by about 60 m per m/s at the default
  geometry (``docs/plumes-3d.md``); cross-track wind does not.
* **Not modelled:** the rise velocity (a rise needs a longer sequence of heights than
  two re-looks give: ``rise_mps`` is ``None``), the plume's change of shape between
  looks beyond a translation, re-looks of several plumes in one window across frames,
  and the look-ahead's own scanning being re-planned around the re-looks.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import cv2
import numpy as np

from dyntarget import parallax
from dyntarget.errors import InvalidParameterError
from dyntarget.predict.height import Look, fit_height, plume_disparity
from dyntarget.scene import block_mean
from dyntarget.schedule import Agility, OrbitGeometry
from dyntarget.schedule.kinematics import angle_between_deg, look_vectors

MIN_PLUME_PX = 16
"""Fewest WFOV pixels of a component tracked as a plume."""
MIN_RELOOK_PX = 64
"""Fewest WFOV pixels of a plume worth a re-look (smaller: no interior to measure)."""
MATCH_PX = 2
"""A component within this many WFOV pixels of a tracked plume's footprint is that plume."""
POSITION_SIGMA_PX = 0.5
"""Standard deviation of a look's measured position, WFOV pixels."""
WIND_PRIOR_SIGMA_MPS = 3.0
"""Standard deviation of the wind prior, m/s per axis."""
MAX_SIGMA_M = 1500.0
"""A fit less certain than this (one sigma, metres) is not used: the looks disagree
(e.g. the flow followed something else than the plume in a re-look)."""
GUESS_HEIGHT_M = 8500.0
"""Height guessed for the disparity's search when no prior is given (mid-range of 2-15 km)."""
RELOOK_KM = (400.0, 300.0)
"""Default re-look distances ahead of the nadir, km."""


def relook_seconds(geometry: OrbitGeometry, agility: Agility, distance_m: float) -> float:
    """Look-ahead time one re-look at ``distance_m`` ahead of the nadir costs, seconds.

    The look-ahead pitches from its usual direction (``look_ahead_m`` ahead) to the
    re-look's and back, on the preset's rest-to-rest slew model
    (:meth:`~dyntarget.schedule.Agility.slew_time_one`), settling after each slew
    (``settle_s`` twice), and exposes one frame (``dwell_s``).

    Parameters
    ----------
    geometry : dyntarget.schedule.OrbitGeometry
        The orbit (altitude, look-ahead distance).
    agility : dyntarget.schedule.Agility
        The pointing preset.
    distance_m : float
        Ground distance ahead of the nadir of the re-look, metres.

    Returns
    -------
    float
        Seconds the look-ahead is busy.

    Examples
    --------
    500 km up, 500 -> 300 km ahead is a pitch change of 13.27 deg (41.61 to 28.34 deg off
    nadir); ``fast`` (10 deg/s, 20 deg/s^2) slews it in 13.27 / 10 + 10 / 20 = 1.83 s,
    twice, plus 2 x 0.05 s settling and a 0.05 s exposure (``slow``: 32.6 s):

    >>> from dyntarget.schedule import get_agility
    >>> round(relook_seconds(OrbitGeometry(), get_agility("fast"), 300e3), 2)
    3.8
    """
    if not (math.isfinite(distance_m) and distance_m > 0):
        raise InvalidParameterError(f"re-look distance: expected metres > 0, got {distance_m!r}")
    a = look_vectors(geometry, np.array([geometry.look_ahead_m]), np.zeros(1), 0.0)
    b = look_vectors(geometry, np.array([distance_m]), np.zeros(1), 0.0)
    angle = float(angle_between_deg(a, b)[0])
    slew = agility.slew_time_one(angle)
    return 2.0 * (slew + agility.settle_s) + agility.dwell_s


@dataclass(frozen=True)
class HeightEstimate:
    """One plume's top height as the pass measured it (or took it from the prior).

    Parameters
    ----------
    plume_id : int
        The plume, numbered over the pass from 1 (not the truth's id).
    x_px, y_px : float
        Ground position of the plume top (parallax-corrected), strip high-resolution
        pixels (the apparent position where no height is known).
    top_height_m, top_height_sigma_m : float or None
        Top height above sea level and its standard deviation, metres (``None``: none).
    rise_mps : float or None
        Rise velocity: not measured (``None``; a rise needs a longer sequence).
    height_source : str
        ``"estimated"``, ``"prior"`` or ``"none"``.
    true_height_m : float or None
        The true top height of the vent or cloud it belongs to, where the world knows it.
    frame : int
        The frame that first saw it.
    relooks : int
        Re-looks taken of it.
    ready_s : float or None
        When the estimate was usable (last re-look + compute), seconds into the pass.
    reason : str
        Why no height was estimated (empty when estimated).
    """

    plume_id: int
    x_px: float
    y_px: float
    top_height_m: float | None
    top_height_sigma_m: float | None
    rise_mps: float | None
    height_source: str
    true_height_m: float | None
    frame: int
    relooks: int
    ready_s: float | None
    reason: str = ""

    def as_dict(self) -> dict[str, object]:
        """The estimate as plain JSON values.

        Returns
        -------
        dict
            Field name to value.
        """
        return {k: getattr(self, k) for k in self.__dataclass_fields__}


@dataclass
class Relook:
    """A re-look the look-ahead took: when, which rows (strip WFOV), what it saw."""

    t_s: float
    duration_s: float
    top: int
    image: np.ndarray | None = None


@dataclass
class Plume:
    """A plume tracked over the pass (apparent footprint, re-looks, estimate)."""

    pid: int
    frame: int
    t_k: float
    rows: np.ndarray
    """Strip WFOV rows of its component in the frame that first saw it."""
    cols: np.ndarray
    relooks: list[Relook] = field(default_factory=list)
    height_m: float | None = None
    sigma_m: float | None = None
    ground_xy: tuple[float, float] | None = None
    """Strip WFOV px of the top's ground position at the first frame's time."""
    ready_s: float = math.inf
    source: str = "none"
    reason: str = ""
    true_id: int = 0


@dataclass(frozen=True)
class Geometry3D:
    """Where the spacecraft is during a pass, on the strip's WFOV grid."""

    geometry: OrbitGeometry
    wfov_shape: tuple[int, int]
    frame_px: int
    top0: int
    factor: int

    def nadir(self, t: float) -> tuple[float, float]:
        """The nadir at pass time ``t``, strip WFOV px ``(x, y)`` (``docs``' formula)."""
        g = self.geometry
        x = (self.wfov_shape[1] - 1) / 2.0
        y = (
            self.top0
            + (self.frame_px - 1) / 2.0
            + (g.look_ahead_m - g.ground_speed * t) / g.wfov_gsd_m
        )
        return x, y

    def nadir_hr(self, t: float) -> tuple[float, float]:
        """The nadir at ``t`` in strip high-resolution px (WFOV px ``i`` centres at ``i f + (f-1)/2``)."""
        x, y = self.nadir(t)
        f = self.factor
        return x * f + (f - 1) / 2.0, y * f + (f - 1) / 2.0

    def along(self, y: float, t: float) -> float:
        """Metres ahead of the nadir at ``t`` of strip WFOV row ``y``."""
        return (self.nadir(t)[1] - y) * self.geometry.wfov_gsd_m

    def disparity_rows(self, y: float, t0: float, t1: float, height_m: float) -> float:
        """Rows a feature at ``height_m`` seen at row ``y`` at ``t0`` appears lower at ``t1``
        (its parallax shrinks as the nadir approaches; the drift with the wind not counted)."""
        g = self.geometry
        true_along = float(parallax.sight_at_height(g.altitude_m, self.along(y, t0), height_m))
        s0 = self.along(y, t0) - true_along
        d1 = true_along - g.ground_speed * (t1 - t0)
        s1 = float(parallax.parallax_shift(g.altitude_m, d1, height_m))
        return (s0 - s1) / g.wfov_gsd_m


Render = Callable[[float, int, int, tuple[float, float]], np.ndarray]
"""``render(t, top_hr, bottom_hr, nadir_hr) -> (4, rows, W)`` high-res look of the world."""


class HeightTracker:
    """Plumes of a pass, their re-looks and height estimates (the module docstring's model).

    Parameters
    ----------
    where : Geometry3D
        The pass's geometry on the strip's WFOV grid.
    agility : dyntarget.schedule.Agility
        The preset whose slew model times a re-look.
    relook_km : tuple of float
        Re-look distances ahead of the nadir, km.
    relook_s : float or None
        Seconds per re-look (``None``: :func:`relook_seconds` per distance).
    prior_m : float or None
        The prior height (also the disparity's guess; :data:`GUESS_HEIGHT_M` without one).
    wind : tuple of float or None
        ``(east, north)`` wind prior, m/s (``None``: no prior; two looks then degenerate).
    measure : bool
        Take re-looks and estimate heights (``"estimated"`` mode); otherwise only track.
    log : callable
        Where a plume's fallback line goes (stderr in the pass loop).
    """

    def __init__(
        self,
        where: Geometry3D,
        agility: Agility,
        relook_km: tuple[float, ...],
        relook_s: float | None,
        prior_m: float | None,
        wind: tuple[float, float] | None,
        *,
        measure: bool,
        log: Callable[[str], None],
    ) -> None:
        self.where, self.agility, self.prior_m, self.wind = where, agility, prior_m, wind
        self.measure, self.log = measure, log
        self.distances_m = tuple(float(d) * 1e3 for d in relook_km)
        self.durations_s = tuple(
            relook_s if relook_s is not None else relook_seconds(where.geometry, agility, d)
            for d in self.distances_m
        )
        self.labels = np.zeros(where.wfov_shape, np.int32)
        """Strip WFOV px -> tracked plume (1-based; 0: none), apparent footprints."""
        self.plumes: list[Plume] = []
        self.busy: list[tuple[float, float]] = []
        """``(start, end)`` of every re-look taken, pass seconds."""
        if measure:  # loaded before the pass (as at boot), not in the first plume's time
            import scipy.optimize  # noqa: F401

    # -- the look-ahead's time -------------------------------------------------------
    def busy_at(self, t: float) -> bool:
        """Whether the look-ahead is re-looking at pass time ``t``."""
        return any(a <= t < b for a, b in self.busy)

    def _free_from(self, t: float, duration: float) -> float:
        """The first time at or after ``t`` at which ``duration`` s of look-ahead are free."""
        start = t
        for a, b in sorted(self.busy):
            if start < b and start + duration > a:
                start = b
        return start

    # -- per frame -------------------------------------------------------------------
    def frame(
        self,
        k: int,
        t_k: float,
        top: int,
        mask: np.ndarray,
        image: np.ndarray,
        render: Render,
        *,
        last: bool,
    ) -> np.ndarray:
        """Track frame ``k``'s plumes, take and measure re-looks of new ones.

        Parameters
        ----------
        k, t_k, top : frame index, acquisition time and top strip WFOV row.
        mask : ``(H_f, W)`` bool denoised mask the plan used.
        image : ``(4, H_f, W)`` the frame's WFOV image.
        render : the world's look (:data:`Render`), for the re-looks.
        last : the pass's last frame (no plume waits for a next one).

        Returns
        -------
        numpy.ndarray
            ``(H_f, W)`` int32: the tracked plume (1-based) of each component pixel, 0 elsewhere.
        """
        n, comp, stats, _ = cv2.connectedComponentsWithStats(mask.astype(np.uint8), connectivity=8)
        out = np.zeros(mask.shape, np.int32)
        new: list[tuple[int, np.ndarray, np.ndarray]] = []
        near = np.ones((2 * MATCH_PX + 1, 2 * MATCH_PX + 1), np.uint8)
        for i in range(1, n):
            if stats[i, cv2.CC_STAT_AREA] < MIN_PLUME_PX:
                continue
            on = comp == i
            grown = cv2.dilate(on.astype(np.uint8), near) > 0
            under = self.labels[top : top + mask.shape[0]][grown]
            under = under[under > 0]
            rows, cols = np.nonzero(on)
            if len(under):
                pid = int(np.bincount(under).argmax())
                out[on] = pid
                self.labels[rows + top, cols] = np.where(
                    self.labels[rows + top, cols] == 0, pid, self.labels[rows + top, cols]
                )
                continue
            small = stats[i, cv2.CC_STAT_AREA] < MIN_RELOOK_PX
            if small and stats[i, cv2.CC_STAT_TOP] == 0 and not last:
                continue  # too small, cut by the frame's top edge: the next frame sees more
            new.append((i, rows, cols))
        for i, rows, cols in new:
            plume = Plume(len(self.plumes) + 1, k, t_k, rows + top, cols)
            self.plumes.append(plume)
            self.labels[rows + top, cols] = plume.pid
            out[comp == i] = plume.pid
        if not new:
            return out
        fresh = [self.plumes[-len(new) + j] for j in range(len(new))]
        if not self.measure:
            for p in fresh:
                self._fallback(p, "")
            return out
        small = [p for p in fresh if len(p.rows) < MIN_RELOOK_PX]
        for p in small:
            self._fallback(p, f"too small for a re-look: {len(p.rows)} WFOV px, fewer than "
                           f"{MIN_RELOOK_PX}")  # fmt: skip
        big = [p for p in fresh if len(p.rows) >= MIN_RELOOK_PX]
        if big:
            self._relook(big, k, t_k, top, mask.shape, image, render)
        return out

    def _relook(
        self,
        plumes: list[Plume],
        k: int,
        t_k: float,
        top: int,
        shape: tuple[int, int],
        image: np.ndarray,
        render: Render,
    ) -> None:
        """Take frame ``k``'s re-looks in order, measure each plume on each, fit at the end.

        Each re-look's window is centred where the plumes will appear, by the height
        known so far: the prior (or :data:`GUESS_HEIGHT_M`) for the first, then the fit of
        the looks taken so far of the largest plume (two looks and the wind prior).
        """
        w = self.where
        hw, gsd = w.wfov_shape[0], w.geometry.wfov_gsd_m
        centre = float(np.mean(np.concatenate([p.rows for p in plumes])))
        along = w.along(centre, t_k)
        guess = self.prior_m if self.prior_m is not None else GUESS_HEIGHT_M
        nx, ny0 = w.nadir(t_k)
        alt, sig = w.geometry.altitude_m, POSITION_SIGMA_PX * gsd
        looks: dict[int, list[Look]] = {}
        failed: dict[int, str] = {}
        for p in plumes:
            cy, cx = float(np.mean(p.rows)), float(np.mean(p.cols))
            looks[p.pid] = [Look(t_k, cx * gsd, -cy * gsd, nx * gsd, -ny0 * gsd, alt, sig)]
        main = max(plumes, key=lambda p: len(p.rows))
        why, last_t, last_compute = "", math.nan, 0.0
        for d, dur in zip(self.distances_m, self.durations_s, strict=True):
            want = t_k + (along - d) / w.geometry.ground_speed
            if want <= t_k:
                why = why or f"already nearer than {d / 1e3:g} km when seen"
                continue
            at = self._free_from(want, dur)
            if at - want > dur:
                why = why or "the look-ahead was busy re-looking at other plumes"
                continue
            shift = w.disparity_rows(centre, t_k, at, guess)
            r0 = int(min(max(round(centre + shift - (shape[0] - 1) / 2.0), 0), hw - shape[0]))
            self.busy.append((at, at + dur))
            f = w.factor
            hr = render(at, r0 * f, (r0 + shape[0]) * f, w.nadir_hr(at))
            second = block_mean(np.asarray(hr, np.float32)[:, :, : shape[1] * f], f)
            t0 = time.perf_counter()
            _, ny = w.nadir(at)
            for p in plumes:
                p.relooks.append(Relook(at, dur, r0))
                if p.pid in failed:
                    continue
                mask = np.zeros(shape, bool)
                mask[p.rows - top, p.cols] = True
                cy, cx = float(np.mean(p.rows)), float(np.mean(p.cols))
                expect = cy + w.disparity_rows(cy, t_k, at, guess) - r0  # in the re-look
                disp, reason = plume_disparity(
                    image, second, mask, guess_px=(0.0, expect - (cy - top)), search_px=shape[0]
                )
                if disp is None:
                    failed[p.pid] = reason.split("; no height")[0]
                    continue
                x, y = cx + disp.dx_px, cy + disp.dy_px + (r0 - top)
                looks[p.pid].append(Look(at, x * gsd, -y * gsd, nx * gsd, -ny * gsd, alt, sig))
            if main.pid not in failed and self.wind is not None:
                fit = fit_height(looks[main.pid], wind_prior=self.wind,
                                 wind_prior_sigma_mps=WIND_PRIOR_SIGMA_MPS)  # fmt: skip
                if fit.ok and 0 < fit.height_m < parallax.MAX_HEIGHT_M:
                    guess = fit.height_m
            last_t, last_compute = at, time.perf_counter() - t0
        for p in plumes:
            t0 = time.perf_counter()
            if not p.relooks:
                self._fallback(p, f"no re-look taken ({why or 'none asked'})")
            elif p.pid in failed:
                self._fallback(p, failed[p.pid])
            else:
                self._fit(p, looks[p.pid])
            if p.source == "estimated":
                p.ready_s = last_t + last_compute + time.perf_counter() - t0

    def _fit(self, p: Plume, looks: list[Look]) -> None:
        """Height and ground position of plume ``p`` from its looks, or the fallback."""
        if self.wind is None and len(looks) < 3:
            self._fallback(p, "two looks and no wind prior: drift and height cannot be separated")
            return
        fit = fit_height(looks, wind_prior=self.wind, wind_prior_sigma_mps=WIND_PRIOR_SIGMA_MPS)
        if not fit.ok or not math.isfinite(fit.height_m) or fit.height_m <= 0:
            self._fallback(p, fit.reason or f"the fit gave no usable height ({fit.height_m:.0f} m)")
            return
        if not fit.height_sigma_m <= MAX_SIGMA_M:
            self._fallback(
                p,
                f"too uncertain: {fit.height_m:.0f} +- {fit.height_sigma_m:.0f} m (the looks "
                f"disagree; more than {MAX_SIGMA_M:g} m)",
            )
            return
        gsd = self.where.geometry.wfov_gsd_m
        p.height_m, p.sigma_m, p.source = fit.height_m, fit.height_sigma_m, "estimated"
        p.ground_xy = (fit.position_m[0] / gsd, -fit.position_m[1] / gsd)

    def _fallback(self, p: Plume, reason: str) -> None:
        """No estimate: the prior, or nothing; say so (``reason`` empty: not measured by design)."""
        p.source = "prior" if self.prior_m is not None else "none"
        p.height_m = self.prior_m
        p.sigma_m = None
        p.reason = reason
        if reason:
            self.log(
                f"plume {p.pid} (frame {p.frame}): no height estimated: {reason}; "
                + (f"using the prior {self.prior_m:g} m" if self.prior_m is not None else
                   "its pointings are not corrected")
            )  # fmt: skip

    # -- what the aim reads ----------------------------------------------------------
    def height_at(self, pid: int, t: float) -> float:
        """The height plume ``pid`` (1-based; 0: none) is aimed with at pass time ``t``.

        The estimate from its ``ready_s`` on; before that (or without one) the prior,
        else NaN (not corrected).
        """
        prior = math.nan if self.prior_m is None else self.prior_m
        if pid <= 0 or pid > len(self.plumes):
            return prior
        p = self.plumes[pid - 1]
        if p.source == "estimated" and t >= p.ready_s and p.height_m is not None:
            return p.height_m
        return prior

    def estimates(self, true_height: Callable[[Plume], float | None]) -> tuple[HeightEstimate, ...]:
        """Every tracked plume's estimate (:class:`HeightEstimate`), in the order first seen.

        Parameters
        ----------
        true_height : callable
            ``true_height(plume) -> metres or None`` (the world's truth, where known).

        Returns
        -------
        tuple of HeightEstimate
        """
        w = self.where
        f = w.factor
        out = []
        for p in self.plumes:
            cy, cx = float(np.mean(p.rows)), float(np.mean(p.cols))
            if p.ground_xy is not None:
                gx, gy = p.ground_xy
            elif p.height_m is not None:  # the prior: the true position under the apparent one
                along = float(
                    parallax.sight_at_height(w.geometry.altitude_m, w.along(cy, p.t_k), p.height_m)
                )
                gx, gy = cx, w.nadir(p.t_k)[1] - along / w.geometry.wfov_gsd_m
            else:
                gx, gy = cx, cy
            out.append(
                HeightEstimate(
                    p.pid,
                    round(gx * f + (f - 1) / 2.0, 3),
                    round(gy * f + (f - 1) / 2.0, 3),
                    None if p.height_m is None else round(float(p.height_m), 1),
                    None if p.sigma_m is None else round(float(p.sigma_m), 1),
                    None,
                    p.source,
                    true_height(p),
                    p.frame,
                    len(p.relooks),
                    None if not math.isfinite(p.ready_s) else round(p.ready_s, 4),
                    p.reason,
                )
            )
        return tuple(out)
