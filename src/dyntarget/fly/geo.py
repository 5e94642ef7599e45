"""Geostationary foresight for a pass: the GEO stream of the strip's world, its blueprint, the gate.

* **GEO stream.** The same world (:class:`~dyntarget.synth.dynamic.WorldSpec`)
  seen by a geostationary imager: rendered at ``gsd_m / 8`` (area-averaged: narrow plumes count by the fraction
  of the cell they cover) over the strip and
  an 8 km margin around it, averaged onto ``gsd_m`` cells (brightness: the mean
  of the four bands), plus the imager's own Gaussian noise (``noise``,
  reflectance). Images are taken every ``cadence_s`` (at multiples of it, pass
  time 0 being one) and an image taken at ``t`` is usable from ``t + latency_s``.
* **Detection** (``detection``), on GEO cells — not the look-ahead's classifiers:
  ``"unmix"`` (default, :func:`dyntarget.geo.unmix`): each cell's four-band
  anomaly over the clear-sky background (the same ground without plume or cloud:
  a clear-day composite) is split by non-negative least squares into cover
  fractions of meteorological cloud, ash and steam, on the synthetic world's own
  end-member spectra (what a real GEO ash product does with its split-window and
  visible tests); the plume fraction times :data:`CONTRAST` above ``threshold``
  counts. ``"brightness"`` (:func:`dyntarget.geo.detect`): the band-mean
  brightness above the background by ``threshold``; it takes meteorological
  clouds for plumes too.
* **Nowcast** (:func:`dyntarget.geo.nowcast`, pysteps): the anomaly of the last
  usable images (up to three) carried to when the satellite will be over each
  GEO row, then thresholded again; each connected detection over the strip is
  a :class:`~dyntarget.geo.Target`. Its value per pointing is its nowcast
  anomaly times its *persistence* (the cell's smallest anomaly over the images
  over its last one): a vent's plume stays put, a drifting cloud does not, so
  clouds weigh little (and so do detached volcanic clouds: a known cost).
* **Blueprint** (:func:`dyntarget.geo.plan_blueprint`), computed on the ground
  before the pass from the images usable at pass time 0, and uplinked.
* **Refinement** (:class:`BlueprintGate`): onboard, every plume pixel the
  look-ahead finds is pooled under the blueprint target holding it (or a target
  of the look-ahead's own) and, once the target is seen whole or its window
  opens, its most valuable pixels are flown, as many as the window holds; the
  blueprint's budgets cap a target only where the next chosen target needs the
  time (lifted when the look-ahead finds nothing there).
* **Staging** (:meth:`BlueprintGate.route`): the idle sensor is sent ahead, just in
  time, to the next chosen blueprint target the look-ahead would see too late
  (``stage``); the staged target then holds the sensor until released or refuted.
* **Omniscient reference** (:func:`omniscient_targets`): the blueprint planned on
  the true plumes, each where it is when the satellite is over it, no latency,
  no noise (not an upper bound).
* **Blind** (``GeoSettings(blind=True)``): the refinement with no blueprint, an
  ablation.
* **Catalog prior** (``GeoSettings(prior=CATALOG)``): the blueprint planned on the known
  volcanoes of a catalog, no GEO image (:mod:`dyntarget.geo.catalog`): the baseline.
"""

from __future__ import annotations

import math
import os
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from dyntarget.errors import InvalidParameterError, InvalidSceneError
from dyntarget.geo import Blueprint, Target, detect, nowcast, plan_blueprint, unmix
from dyntarget.scene import block_mean
from dyntarget.schedule import get_agility

MARGIN_M = 8_000.0
"""GEO coverage beyond the strip on every side, metres (context for the motion)."""
SUBSAMPLE = 8
"""Render pixels per GEO cell side."""
NEED_FILL = 2.0
"""Pointings a plume is worth per WFOV pixel of its area (about what the look-ahead's
lawnmower flies over a plume it has time for)."""
CONTRAST = 0.3
"""Brightness of a plume over the ground (reflectance): a GEO cell's anomaly over it
is the fraction of the cell the plume covers."""
SPAN_CELLS = 3
"""A GEO target's rows, widened by this many GEO cells each way (the narrow plume near
the vent is below the threshold on 2 km cells; what GEO sees is the spread plume downwind)."""
OMNISCIENT_REACH_M = 30_000.0
"""The omniscient truth is rendered only within this distance of a vent or volcanic cloud."""
NEED_MAX = 400
LEAD_STEPS = 8
"""Lead times the nowcast is computed at, spread over the pass (each GEO row takes the nearest)."""
OBSERVE_BEFORE_NADIR_S = 20.0
"""A target is taken to be observed this long before the satellite is over it (mid-window)."""
MAX_RENDER_ROWS = 8192
MERGE_ROWS = 16
"""Pooled pointings closer than this many WFOV rows (1 km at 64 m) make one look-ahead target."""
DETECTIONS = ("unmix", "brightness")
"""How GEO cells are tested for plume (:class:`GeoSettings` ``detection``)."""
RELEASE_LEAD_S = 2.0
"""A target not yet seen whole is released this long before its window opens."""
STAGE_SLACK_S = 5.0
"""The idle sensor is sent ahead to a blueprint target only when waiting for the look-ahead
to see it would lose more than this much of its window, seconds."""


@dataclass(frozen=True)
class GeoSettings:
    """Settings of the geostationary stream and of the blueprint.

    Parameters
    ----------
    gsd_m : GEO cell size, m (coarser than the look-ahead's WFOV pixels).
    cadence_s : seconds between GEO images (> 0).
    latency_s : an image taken at ``t`` is usable from ``t + latency_s`` (>= 0).
    noise : std of the GEO brightness noise, reflectance.
    threshold : detection threshold above the background, reflectance.
    reserve : fraction of sensor time the blueprint leaves for the look-ahead's own finds.
    history_s : how far before the pass the GEO archive goes, s.
    omniscient : plan the blueprint on the true plumes instead (the omniscient reference).
    blind : no blueprint at all (no GEO image): the onboard refinement alone, an ablation
        that tells what the GEO blueprint adds to it.
    prior : the catalog baseline instead of GEO images: a blueprint target per known
        volcano over the strip (a catalog CSV with the GVP's columns, or ``"vents"``: a
        synthetic strip's own vents), :func:`dyntarget.geo.catalog.prior_targets`.
    detection : ``"unmix"`` (plume fraction from four-band spectral unmixing) or
        ``"brightness"`` (band-mean brightness above the background).
    stage : let the idle sensor slew ahead to the next chosen blueprint target the
        look-ahead has not seen yet (:meth:`BlueprintGate.route`); ``False``: an ablation.
    """

    gsd_m: float = 2000.0
    cadence_s: float = 600.0
    latency_s: float = 300.0
    noise: float = 0.005
    threshold: float = 0.03
    reserve: float = 0.1
    history_s: float = 3600.0
    omniscient: bool = False
    blind: bool = False
    prior: str | None = None
    stage: bool = True
    detection: str = "unmix"

    def __post_init__(self) -> None:
        if self.omniscient and self.blind:
            raise InvalidParameterError("geo: omniscient and blind exclude each other")
        if self.prior is not None and (self.omniscient or self.blind):
            raise InvalidParameterError("geo: a catalog prior excludes omniscient and blind")
        if self.detection not in DETECTIONS:
            raise InvalidParameterError(
                f"geo detection: expected one of {', '.join(DETECTIONS)}, got {self.detection!r}"
            )
        for name, lo, hi in (
            ("gsd_m", 1.0, 50_000.0),
            ("cadence_s", 1e-9, 86_400.0),
            ("latency_s", 0.0, 86_400.0),
            ("noise", 0.0, 1.0),
            ("threshold", 1e-6, 1.0),
            ("reserve", 0.0, 0.9),
            ("history_s", 0.0, 86_400.0),
        ):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
                raise InvalidParameterError(f"geo {name}: expected a number, got {v!r}")
            if not lo <= v <= hi:
                what = "> 0" if name == "cadence_s" else f"in [{lo:g}, {hi:g}]"
                raise InvalidParameterError(f"geo {name}: expected {what}, got {v!r}")

    def check_against(self, wfov_gsd_m: float) -> None:
        """Refuse a GEO grid finer than the look-ahead's WFOV pixels.

        Parameters
        ----------
        wfov_gsd_m : float
            The look-ahead's WFOV ground sampling distance, m.
        """
        if self.gsd_m <= wfov_gsd_m:
            raise InvalidParameterError(
                f"geo gsd_m: {self.gsd_m:g} m is not coarser than the look-ahead's "
                f"{wfov_gsd_m:g} m WFOV pixels"
            )


def image_times(settings: GeoSettings, t_plan: float) -> list[float]:
    """Acquisition times of the GEO images usable at ``t_plan`` (oldest first, at most three).

    Parameters
    ----------
    settings : GeoSettings
    t_plan : when the blueprint is planned, pass seconds.

    Returns
    -------
    list of float

    Examples
    --------
    >>> image_times(GeoSettings(cadence_s=600, latency_s=300), 0.0)
    [-1800.0, -1200.0, -600.0]
    >>> image_times(GeoSettings(latency_s=900, history_s=1000), 0.0)
    []
    """
    c = settings.cadence_s
    last = math.floor((t_plan - settings.latency_s) / c + 1e-9) * c
    times = [float(last - k * c) for k in range(3)]
    return sorted(t for t in times if t >= -settings.history_s - 1e-9)


class GeoStream:
    """The GEO images of a synthetic strip's world (see the module docstring).

    Parameters
    ----------
    world : a moving strip (:class:`~dyntarget.fly.strip.MovingStrip` or ``LongStrip``).
    settings : GeoSettings
    """

    def __init__(self, world: Any, settings: GeoSettings) -> None:
        from dyntarget.synth.dynamic import World as MovingWorld

        spec = getattr(world, "spec", None)
        if spec is None:
            raise InvalidSceneError(
                f"strip {world.id!r}: --geo needs a synthetic strip (its world renders the "
                "GEO stream); a GeoTIFF strip has no world to render"
            )
        self.settings, self.strip = settings, world
        g = settings.gsd_m / SUBSAMPLE
        g = max(g, spec.gsd)
        self.m = max(1, round(settings.gsd_m / g))  # render px per GEO cell
        g = settings.gsd_m / self.m
        scale = spec.gsd / g
        self.render_gsd = g
        coarse = replace(
            spec,
            gsd=g,
            size=max(16, round(spec.size * scale)),
            vents=tuple(replace(v, x=v.x * scale, y=v.y * scale) for v in spec.vents),
            clouds=tuple(replace(c, x=c.x * scale, y=c.y * scale) for c in spec.clouds),
            noise_sigma=0.0,
        )
        self.coarse = MovingWorld(coarse)
        # the clear-sky background: the same ground, no plume, no cloud
        self._clear = MovingWorld(
            replace(
                coarse,
                vents=tuple(replace(v, emission_optical_depth=1e-9) for v in coarse.vents),
                clouds=(),
            )
        )
        self._background: np.ndarray | None = None
        c0, r0, w, h = world.window
        G = settings.gsd_m
        x0, x1 = c0 * spec.gsd - MARGIN_M, (c0 + w) * spec.gsd + MARGIN_M
        y0, y1 = r0 * spec.gsd - MARGIN_M, (r0 + h) * spec.gsd + MARGIN_M
        self.cell0 = (math.floor(x0 / G), math.floor(y0 / G))  # GEO cell of the grid's corner
        self.cells = (math.ceil(y1 / G) - self.cell0[1], math.ceil(x1 / G) - self.cell0[0])
        self._images: dict[float, np.ndarray] = {}

    def background(self) -> np.ndarray:
        """The clear-sky reflectance of every GEO cell (no plume, no cloud, no noise).

        Returns
        -------
        numpy.ndarray
            ``(bands, rows, cols)`` reflectance.
        """
        if self._background is None:
            self._background = self._render(self._clear, 0.0)
        return self._background

    def _render(self, world: Any, t: float) -> np.ndarray:
        m = self.m
        nrow, ncol = self.cells
        cx, cy = self.cell0
        out: np.ndarray | None = None
        step = max(1, MAX_RENDER_ROWS // m)
        for a in range(0, nrow, step):
            b = min(nrow, a + step)
            f = world.render(t, (cx * m, (cy + a) * m, ncol * m, (b - a) * m), noise=False)
            if out is None:
                out = np.empty((f.image.shape[0], nrow, ncol), np.float32)
            out[:, a:b] = block_mean(f.image, m)
        assert out is not None  # at least one GEO row
        return out

    def image(self, t: float) -> np.ndarray:
        """The GEO image taken at ``t`` (pass seconds), noise included (every band).

        Parameters
        ----------
        t : float
            Acquisition time.

        Returns
        -------
        numpy.ndarray
            ``(bands, rows, cols)`` reflectance on GEO cells (row 0: the strip's top, as
            the strip).
        """
        hit = self._images.get(t)
        if hit is not None:
            return hit
        out = self._render(self.coarse, t)
        if self.settings.noise > 0:
            rng = np.random.default_rng([self.strip.spec.seed, 0x6E0, round(t * 1000) & 0xFFFFFFFF])
            out += rng.normal(0.0, self.settings.noise, out.shape).astype(np.float32)
        self._images[t] = out
        return out

    def strip_rows(self, gy: np.ndarray) -> np.ndarray:
        """High-resolution strip rows of the centres of GEO rows ``gy``.

        Parameters
        ----------
        gy : numpy.ndarray
            GEO rows.

        Returns
        -------
        numpy.ndarray
            Strip rows (high resolution, may lie outside the strip).
        """
        s = self.strip.spec
        return (self.cell0[1] + np.asarray(gy) + 0.5) * self.settings.gsd_m / s.gsd - (
            self.strip.window[1]
        )

    def strip_cols(self) -> tuple[int, int]:
        """GEO columns overlapping the strip.

        Returns
        -------
        tuple of int
            ``(first, last + 1)``.
        """
        s, G = self.strip.spec, self.settings.gsd_m
        c0, _, w, _ = self.strip.window
        a = math.floor(c0 * s.gsd / G) - self.cell0[0]
        b = math.ceil((c0 + w) * s.gsd / G) - self.cell0[0]
        return a, b


def _along_of_row(frames: Any, row_w: np.ndarray) -> np.ndarray:
    """Pass ground coordinate (ahead of nadir at t = 0, m) of strip WFOV rows."""
    g = frames.geometry
    hw = frames.wfov_shape[0]
    top = hw - frames.frame_px
    return g.look_ahead_m + ((frames.frame_px - 1) / 2.0 - (np.asarray(row_w) - top)) * g.wfov_gsd_m


def _targets_from_mask(
    mask: np.ndarray,
    value_map: np.ndarray,
    row_w: np.ndarray,
    frames: Any,
    cell_m: float,
    cross_m: np.ndarray,
    margin_rows: float,
    fraction: np.ndarray | None = None,
    curve: bool = False,
) -> list[Target]:
    """One target per 8-connected component of ``mask`` (rows: along-track).

    ``curve``: each target's gains are its pixels' values, best first (one pointing a pixel).
    """
    n, comp = cv2.connectedComponents(mask.astype(np.uint8), connectivity=8)
    out = []
    gsd_w = frames.geometry.wfov_gsd_m
    for i in range(1, n):
        rr, cc = np.nonzero(comp == i)
        rows = row_w[rr]
        cover = len(rr) if fraction is None else float(np.sum(fraction[rr, cc]))
        area_px = cover * (cell_m / gsd_w) ** 2
        need = int(np.clip(round(area_px * NEED_FILL), 1, NEED_MAX))
        along = float(np.mean(_along_of_row(frames, rows)))
        value = float(np.mean(value_map[rr, cc]))
        gains = np.sort(value_map[rr, cc].astype(np.float64))[::-1][:NEED_MAX]
        out.append(
            Target(
                along,
                float(np.mean(cross_m[cc])),
                value,
                len(gains) if curve else need,
                (float(rows.min() - margin_rows), float(rows.max() + margin_rows)),
                tuple(float(g) for g in gains) if curve else (),
            )
        )
    return out


def plume_field(image: np.ndarray, background: np.ndarray, settings: GeoSettings) -> np.ndarray:
    """The plume anomaly of one GEO image (reflectance units; ``threshold`` applies to it).

    ``"unmix"``: the ash + steam cover fraction (:func:`dyntarget.geo.unmix` against
    meteorological cloud, ash and steam) times :data:`CONTRAST`; ``"brightness"``:
    the band-mean brightness above the background (:func:`dyntarget.geo.detect`).

    Parameters
    ----------
    image, background : numpy.ndarray
        ``(bands, rows, cols)`` GEO reflectance, and the clear-sky one.
    settings : GeoSettings

    Returns
    -------
    numpy.ndarray
        ``(rows, cols)`` anomaly, ``>= 0``.
    """
    if settings.detection == "brightness":
        return detect(image.mean(axis=0), settings.threshold, background.mean(axis=0))[1]
    from dyntarget.synth.volcano import ASH_PLUME, CLOUD, STEAM

    f = unmix(image, background, np.array([CLOUD, ASH_PLUME, STEAM], np.float64))
    return CONTRAST * (f[1] + f[2])


def geo_targets(
    stream: GeoStream, frames: Any, factor: int, t_plan: float = 0.0
) -> tuple[list[Target], dict[str, Any]]:
    """Targets for the blueprint from the GEO images usable at ``t_plan``, nowcast to overpass.

    Parameters
    ----------
    stream : GeoStream
    frames : the pass's :class:`~dyntarget.fly.loop.FramePlan`.
    factor : high-res -> WFOV factor.
    t_plan : when the blueprint is planned, pass seconds.

    Returns
    -------
    (targets, info): the targets, and what was used (image times, motion).
    """
    s = stream.settings
    times = image_times(s, t_plan)
    info: dict[str, Any] = {"images": times}
    if not times:
        return [], {**info, "note": "no GEO image usable before the pass: look-ahead only"}
    bg = stream.background()
    fields = [plume_field(stream.image(t), bg, s) for t in times]
    nrow = stream.cells[0]
    row_w = stream.strip_rows(np.arange(nrow)) / factor
    v = frames.geometry.ground_speed
    t_obs = np.maximum(_along_of_row(frames, row_w) / v - OBSERVE_BEFORE_NADIR_S, 0.0)
    leads_all = np.maximum(t_obs - times[-1], 0.0)
    lo, hi = float(leads_all.min()), float(leads_all.max())
    leads = list(np.linspace(lo, hi, LEAD_STEPS)) if hi > lo else [lo]
    out, vel = nowcast(fields, s.cadence_s, leads)
    pick = np.abs(leads_all[:, None] - np.asarray(leads)[None, :]).argmin(axis=1)
    composite = out[pick, np.arange(nrow)]  # (nrow, ncol): each row at its own lead
    # persistence: a vent's plume stays where it is from image to image, a drifting
    # cloud does not: weight each cell by its smallest anomaly over the images
    # relative to the last one (1: steady; about 0: something passing through)
    last = np.maximum(fields[-1], 1e-6)
    steady = np.clip(np.minimum.reduce(fields) / last, 0.0, 1.0) if len(fields) > 1 else 1.0
    a, b = stream.strip_cols()
    weight = np.ones_like(composite) * steady
    full = composite * weight > s.threshold
    # components on the whole GEO grid (a plume blown across the track spreads beside
    # the strip), kept where they reach the strip's columns or the next ones
    a1, b1 = max(0, a - 1), min(composite.shape[1], b + 1)
    _, comp = cv2.connectedComponents(full.astype(np.uint8), connectivity=8)
    near = np.zeros_like(full)
    near[:, a1:b1] = True
    keep_ids = np.unique(comp[near & full])
    mask = np.isin(comp, keep_ids[keep_ids > 0])[:, a1:b1]
    sub = composite[:, a1:b1]
    # cross-track: centre of each GEO column's overlap with the strip, metres from its centre
    spec, (c0, _, w, _) = stream.strip.spec, stream.strip.window
    cx = (stream.cell0[0] + np.arange(a1, b1) + 0.5) * s.gsd_m
    lo_x, hi_x = c0 * spec.gsd, (c0 + w) * spec.gsd
    cross = np.clip(cx, lo_x, hi_x) - (lo_x + hi_x) / 2.0
    # the row range of a target, widened (its position is that coarse)
    margin = SPAN_CELLS * s.gsd_m / (spec.gsd * factor)
    frac = np.clip(sub / CONTRAST, 0.0, 1.0)
    targets = _targets_from_mask(
        mask, sub * weight[:, a1:b1], row_w, frames, s.gsd_m, cross, margin, frac
    )
    speed = float(np.hypot(*np.median(vel.reshape(2, -1), axis=1)) * s.gsd_m)
    return targets, {**info, "motion_mps": round(speed, 3)}


def omniscient_targets(world: Any, frames: Any, factor: int) -> list[Target]:
    """The true plumes as targets: each band of the strip at the time the satellite is over it.

    Rendered on the WFOV grid (the true label, no noise, no latency), so each
    target's rows, area and need are the true ones.

    Parameters
    ----------
    world : a moving strip.
    frames : the pass's FramePlan.
    factor : high-res -> WFOV factor.

    Returns
    -------
    list of Target
    """
    from dyntarget.synth.dynamic import World as MovingWorld

    spec = world.spec
    c0, r0, w, h = world.window
    gw = spec.gsd * factor
    coarse = MovingWorld(
        replace(
            spec,
            gsd=gw,
            size=max(16, round(spec.size / factor)),
            vents=tuple(replace(v, x=v.x / factor, y=v.y / factor) for v in spec.vents),
            clouds=tuple(replace(c, x=c.x / factor, y=c.y / factor) for c in spec.clouds),
        )
    )
    hw, ww = h // factor, w // factor
    label = np.zeros((hw, ww), bool)
    value = np.zeros((hw, ww), np.float32)
    v = frames.geometry.ground_speed
    band = 1024
    reach = OMNISCIENT_REACH_M / gw
    _, uy = spec.wind.velocity_px(spec.gsd)
    sources = [v_.y / factor - r0 / factor for v_ in spec.vents]
    for a in range(0, hw, band):
        b = min(hw, a + band)
        t_mid = (_along_of_row(frames, np.array([(a + b) / 2.0]))[0]) / v
        near = [y for y in sources if a - reach <= y <= b + reach]
        near += [
            (c.y + uy * t_mid) / factor - r0 / factor
            for c in spec.clouds
            if c.volcanic and a - reach <= (c.y + uy * t_mid) / factor - r0 / factor <= b + reach
        ]
        if not near:
            continue
        mid = np.array([(a + b) / 2.0])
        t = float(max(_along_of_row(frames, mid)[0] / v - OBSERVE_BEFORE_NADIR_S, 0.0))
        mk, tau = coarse.truth(t, (c0 // factor, r0 // factor + a, ww, b - a))
        label[a:b], value[a:b] = mk, 1.0 - np.exp(-tau)
    cross = (np.arange(ww) - (ww - 1) / 2.0) * gw
    return _targets_from_mask(
        label, value, np.arange(hw, dtype=float), frames, gw, cross, 2.0, curve=True
    )


class BlueprintGate:
    """Onboard refinement within a blueprint: pool each target's pointings, fly its best ones.

    Every pointing the look-ahead plans on a plume is *pooled* with its value
    (the look-ahead's red reflectance at the pixel: the intensity utility's own
    proxy) under the blueprint target holding its row, or under a target of the
    look-ahead's own (rows within :data:`MERGE_ROWS` of each other) when no
    chosen blueprint target holds it. A target is *released* once the
    look-ahead has seen all of it (the frame's top row has passed its first
    row) or its field-of-regard window opens within :data:`RELEASE_LEAD_S`,
    whichever is first: its ``k`` most valuable pooled pointings are flown, in
    along-track serpentine order (short slews). ``k`` fills the time from when
    the sensor is free (or the window opens) to the window's end, at the
    target's :func:`~dyntarget.geo.blueprint.step_s`; the blueprint's budgets
    bind only as caps where the next chosen target's planned start needs the
    time (a chosen target keeps at least its budget), and a released target
    gets at least one pointing (the plume is observed). Pointings pooled
    after a release join it at once when at least as valuable as its worst
    released one.

    Parameters
    ----------
    blueprint : dyntarget.geo.Blueprint
        Its targets' ``span`` are strip WFOV rows.
    frames : the pass's FramePlan (rows -> ground, windows).
    agility : the preset.
    stage : send the idle sensor ahead to blueprint targets the look-ahead would see too
        late (:meth:`route`; ``GeoSettings.stage``).
    """

    def __init__(self, blueprint: Blueprint, frames: Any, agility: Any, stage: bool = True) -> None:
        from dyntarget.geo.blueprint import step_s
        from dyntarget.schedule import Timer, visibility_windows

        self.blueprint, self.frames, self.agility = blueprint, frames, agility
        self.geometry = replace(frames.geometry, start_s=0.0)
        n = len(blueprint.targets)
        spans = np.array([t.span for t in blueprint.targets], np.float64).reshape(-1, 2)
        self.lo, self.hi = spans[:, 0], spans[:, 1]
        self.mid = spans.mean(axis=1) if n else np.zeros(0)
        self.chosen = blueprint.budget > 0
        self._step = step_s
        self._windows = visibility_windows
        self._timer = Timer
        # targets: the blueprint's, then the look-ahead's own, appended as found
        self.t_lo: list[float] = [float(v) for v in self.lo]
        self.t_hi: list[float] = [float(v) for v in self.hi]
        self.budget: list[int] = [int(b) for b in blueprint.budget]
        self.planned_start: list[float] = [
            float(s) if b > 0 else math.inf
            for s, b in zip(blueprint.start_s, blueprint.budget, strict=True)
        ]
        self.pool: list[dict[tuple[int, int], float]] = [{} for _ in range(n)]
        self.released: list[float | None] = [None] * n  # the worst value released
        self.done_keys: set[tuple[int, int]] = set()
        self.booked_s = 0.0
        self.booked_at: tuple[float, float] | None = None  # what the sensor tracks then
        self.top = frames.wfov_shape[0]
        self.stats = {
            "targets_released": 0,
            "targets_released_blueprint": 0,
            "look_ahead_targets": 0,
            "pointings_released": 0,
            "pointings_pooled": 0,
            "releases_capped_by_blueprint": 0,
            "caps_lifted": 0,
        }
        self.cap_by: dict[int, int] = {}
        self.stage = stage
        self.staged = np.zeros(n, bool)
        self.frame_tops = np.asarray(frames.tops)  # each frame's top row (when a row is seen)
        self.staged_at = np.full(n, math.inf)  # when the sensor is at a staged target's anchor
        self.stats["staged"] = 0

    def target_of(self, rows: np.ndarray) -> np.ndarray:
        """The chosen blueprint target holding each strip WFOV row (nearest centre; -1: none).

        Parameters
        ----------
        rows : numpy.ndarray
            Strip WFOV rows.

        Returns
        -------
        numpy.ndarray
            Target index per row, -1 outside every chosen target.
        """
        rows = np.asarray(rows, np.float64)
        if not self.chosen.any():
            return np.full(len(rows), -1, np.int64)
        inside = (rows[:, None] >= self.lo[None]) & (rows[:, None] <= self.hi[None])
        inside &= self.chosen[None]
        d = np.where(inside, np.abs(rows[:, None] - self.mid[None]), np.inf)
        best = d.argmin(axis=1)
        return np.where(np.isfinite(d.min(axis=1)), best, -1)

    def _own_target(self, r: int) -> int:
        """The look-ahead's own target for row ``r`` (merged when close), created if none."""
        nb = len(self.blueprint.targets)
        for i in range(len(self.t_lo) - 1, nb - 1, -1):
            if self.t_lo[i] - MERGE_ROWS <= r <= self.t_hi[i] + MERGE_ROWS:
                self.t_lo[i], self.t_hi[i] = min(self.t_lo[i], r), max(self.t_hi[i], r)
                return i
        self.t_lo.append(float(r))
        self.t_hi.append(float(r))
        self.budget.append(0)
        self.planned_start.append(math.inf)
        self.pool.append({})
        self.released.append(None)
        self.stats["look_ahead_targets"] += 1
        return len(self.t_lo) - 1

    def route(
        self,
        t_k: float,
        top: int,
        rows: np.ndarray,
        cols: np.ndarray,
        values: np.ndarray,
        free_s: float,
    ) -> np.ndarray:
        """Pool a frame's pointings and return those to fly now (strip rows and columns).

        Parameters
        ----------
        t_k : the frame's acquisition time, pass seconds.
        top : its top strip WFOV row.
        rows, cols : strip WFOV row and column of each planned pointing (not covered).
        values : each one's value (the look-ahead's red reflectance there).
        free_s : when the sensor is free of what it has committed, pass seconds.

        Returns
        -------
        numpy.ndarray
            ``(m, 2)`` strip ``(row, col)`` of the pointings to fly, in order.
        """
        out: list[tuple[int, int]] = []
        self.top = top
        tgt = self.target_of(rows)
        for r, c, v, i in zip(
            rows.tolist(), cols.tolist(), values.tolist(), tgt.tolist(), strict=True
        ):
            key = (int(r), int(c))
            if key in self.done_keys:
                continue
            j = i if i >= 0 else self._own_target(int(r))
            if key not in self.pool[j]:
                self.stats["pointings_pooled"] += 1
            self.pool[j][key] = float(v)
            worst = self.released[j]
            if worst is not None and v >= worst:  # a late find on a released target
                out.append(key)
                self.done_keys.add(key)
                del self.pool[j][key]
        self.booked_s = max(self.booked_s, free_s)
        out.extend(self._uncap())
        for j in self._due(t_k, top):
            out.extend(self._release(j))
        out.extend(self._stage(t_k))
        return np.array(out, np.int64).reshape(-1, 2)

    def _stage(self, t_k: float) -> list[tuple[int, int]]:  # noqa: PLR0911  (one test a return)
        """Send the idle sensor ahead to the next chosen target the look-ahead has not seen.

        The sensor is idle when nothing pooled waits for release. The next chosen
        blueprint target (earliest planned start) the look-ahead has found nothing on
        yet, and not refuted, gets one pointing at its centre, queued at the last
        frame from which the sensor would still be there when its window opens
        (waiting one more frame would make it late): the slew starts before the
        look-ahead can see the plume, and the pointing holds the sensor there.
        """
        if not self.stage or not self.chosen.any():
            return []
        if any(p and self.released[j] is None for j, p in enumerate(self.pool)):
            return []  # pooled pointings wait for their release: not idle
        t_next = t_k + self.frames.cadence_s
        if self.booked_s > t_next:
            return []  # busy beyond the next frame: decide then
        nb = len(self.blueprint.targets)
        open_ = [(self.planned_start[i], i) for i in range(nb)
                 if self.chosen[i] and self.released[i] is None and not self._refuted(i)]  # fmt: skip
        if not open_:
            return []
        i = min(open_)[1]  # the next one the blueprint visits, not yet observed nor refuted
        if self.staged[i] or self.pool[i]:
            return []  # already staged, or the look-ahead has found it: its release comes
        hw, ww = self.frames.wfov_shape
        row = int(np.clip(round((self.t_lo[i] + self.t_hi[i]) / 2.0), 0, hw - 1))
        t = self.blueprint.targets[i]
        col = int(np.clip(round(t.cross_m / self.geometry.wfov_gsd_m + (ww - 1) / 2.0), 0, ww - 1))
        t_in, t_out, along, cross = self._window(i, np.array([[row, col]], np.float64))
        if not t_in < t_out or t_out <= t_next:
            self.staged[i] = True  # never or no longer reachable: not staged
            return []
        timer = self._timer(self.geometry, self.agility)
        timer.t, timer.target = max(self.booked_s, t_next), self.booked_at
        if timer.arrival_one(along, cross, t_in) <= t_in:
            return []  # still in time from the next frame: wait
        # would the look-ahead itself be in time? its release comes when it has seen the
        # target whole, or its window opens: if the sensor can still be there then with
        # no more than STAGE_SLACK_S of the window lost, wait for the look-ahead's word
        whole = np.flatnonzero(self.frame_tops <= self.t_lo[i] - MERGE_ROWS)
        first = np.flatnonzero(self.frame_tops <= self.t_hi[i])
        if len(whole) and len(first):
            t_whole = self.frames.acquired_s(int(whole[0]))
            t_first = self.frames.acquired_s(int(first[0]))
            t_rel = min(t_whole, max(t_first, t_in - RELEASE_LEAD_S))
            timer.t = max(self.booked_s, t_rel + self.frames.cadence_s)
            if timer.arrival_one(along, cross, t_in) <= t_in + STAGE_SLACK_S:
                return []
        timer.t = self.booked_s
        start = timer.arrival_one(along, cross, t_in)
        self.staged[i] = True
        key = (row, col)
        if key in self.done_keys or start >= t_out:
            return []
        self.done_keys.add(key)
        self.staged_at[i] = start
        self.booked_s = start + self.agility.dwell_s
        self.booked_at = (along, cross)
        self.stats["staged"] += 1
        return [key]

    def _window(self, j: int, keys: np.ndarray | None = None) -> tuple[float, float, float, float]:
        """``(t_in, t_out, along, cross)`` of target ``j``'s pooled pointings' centre.

        ``keys``: these strip ``(row, col)`` instead of the pooled ones.
        """
        if keys is None:
            keys = np.array(list(self.pool[j].keys()), np.float64).reshape(-1, 2)
        if len(keys) == 0:
            r = (self.t_lo[j] + self.t_hi[j]) / 2.0
            keys = np.array([[r, (self.frames.wfov_shape[1] - 1) / 2.0]])
        along = _along_of_row(self.frames, keys[:, 0])
        cross = (keys[:, 1] - (self.frames.wfov_shape[1] - 1) / 2.0) * self.geometry.wfov_gsd_m
        t_in, t_out = self._windows(self.geometry, self.agility, along, cross)
        return float(t_in.max()), float(t_out.min()), float(along.mean()), float(cross.mean())

    def _due(self, t_k: float, top: int) -> list[int]:
        due = []
        for j in range(len(self.t_lo)):
            if self.released[j] is not None or not self.pool[j]:
                continue
            # the look-ahead is past its first row, or this is the pass's last frame
            seen = top <= self.t_lo[j] - MERGE_ROWS or top <= int(self.frame_tops[-1])
            if seen or self._window(j)[0] - t_k <= RELEASE_LEAD_S:
                due.append(j)
        return sorted(due, key=lambda j: -self.t_hi[j])  # nearest to nadir first

    def _refuted(self, i: int) -> bool:
        """Whether the look-ahead has seen all of target ``i`` and found nothing on it."""
        return (
            self.released[i] is None and not self.pool[i] and self.top <= self.t_lo[i] - MERGE_ROWS
        )

    def _release(self, j: int, more: bool = False) -> list[tuple[int, int]]:
        t_in, t_out, along, cross = self._window(j)
        timer = self._timer(self.geometry, self.agility)  # the loop's kinematics
        timer.t, timer.target = self.booked_s, self.booked_at
        start = timer.arrival_one(along, cross, t_in)  # the slew there included
        step = float(self._step(self.geometry, self.agility, np.array([along]),
                                np.array([cross]), np.array([start]), 1.0)[0])  # fmt: skip
        limit = t_out
        # the next chosen blueprint target (not this one) that needs the time: not yet
        # started, and not seen whole by the look-ahead with nothing on it
        # a target the sensor was sent ahead to (staged) needs it from its anchor on, and
        # keeps it: nothing else is flown that would make the sensor leave it
        nxt = [(s, i) for i, s in enumerate(self.planned_start)
               if i != j and self.released[i] is None and not self._refuted(i)
               and (start < s < limit or self._anchor(i) < limit)]  # fmt: skip
        held = False
        if nxt:
            own = start + (0 if more else self.budget[j]) * step  # a chosen target keeps its budget
            s_next, i_next = min((min(s, self._anchor(i)), i) for s, i in nxt)
            held = math.isfinite(self._anchor(i_next))
            capped = max(s_next, own)
            if capped < limit:
                limit = capped
                self.cap_by[j] = i_next
                self.stats["releases_capped_by_blueprint"] += 1
        k = int((limit - start) / step) if limit > start else 0
        k = k if more or held else max(1, k)  # a new target gets at least one pointing
        pool = self.pool[j]
        best = sorted(pool.items(), key=lambda kv: -kv[1])[:k]
        if not more or best:
            self.released[j] = best[-1][1] if best else -math.inf
        keys = sorted(
            (kv[0] for kv in best), key=lambda rc: (-rc[0], rc[1] if rc[0] % 2 else -rc[1])
        )
        for key in keys:
            del pool[key]
            self.done_keys.add(key)
        if keys:
            self.booked_s = start + len(keys) * step
            self.booked_at = (along, cross)
        self.stats["targets_released"] += int(not more)
        self.stats["targets_released_blueprint"] += int(
            not more and j < len(self.blueprint.targets)
        )
        self.stats["pointings_released"] += len(keys)
        return keys

    def _anchor(self, i: int) -> float:
        """When the sensor is at target ``i``'s anchor (``inf``: not staged)."""
        return float(self.staged_at[i]) if i < len(self.staged_at) else math.inf

    def _uncap(self) -> list[tuple[int, int]]:
        """More pointings for targets capped by a blueprint target the look-ahead refuted since."""
        out: list[tuple[int, int]] = []
        for j, i in list(self.cap_by.items()):
            if self._refuted(i):
                del self.cap_by[j]
                self.stats["caps_lifted"] += 1
                out.extend(self._release(j, more=True))
        return out

    def report(self) -> dict[str, Any]:
        """What the refinement did (for summary.json).

        Returns
        -------
        dict
            Targets released (all, the blueprint's), the look-ahead's own targets,
            pointings pooled and released, releases capped by the blueprint.
        """
        return dict(self.stats)


def prepare(world: Any, frames: Any, config: Any, settings: GeoSettings):
    """The blueprint and gate of a pass (``None`` gate: no GEO image arrived: look-ahead only).

    Parameters
    ----------
    world : a moving strip.
    frames : its FramePlan.
    config : the PassConfig (agility, factor).
    settings : GeoSettings

    Returns
    -------
    (gate or None, info dict for summary.json, timings dict for :data:`TIMES`)
        The info is deterministic (same inputs, same bytes); the wall-clock times of
        the targets and the blueprint (``targets_s``, ``blueprint_s``) are kept apart.
    """
    import time

    settings.check_against(frames.geometry.wfov_gsd_m)
    agility = get_agility(config.agility)
    t0 = time.perf_counter()
    targets: list[Target]
    if settings.blind:
        targets, info = [], {"images": "none: no blueprint (the refinement alone)"}
    elif settings.prior is not None:
        from dyntarget.geo.catalog import prior_targets

        targets, info = prior_targets(settings.prior, world, frames, config.factor)
    elif settings.omniscient:
        cache = world.__dict__.setdefault("_geo_truth_targets", {})  # reused across presets
        tkey = (config.factor, frames.frame_px, frames.step, frames.geometry)
        if tkey not in cache:
            cache[tkey] = omniscient_targets(world, frames, config.factor)
        targets, info = cache[tkey], {"images": "truth"}
    else:
        streams = world.__dict__.setdefault("_geo_streams", {})  # the same images, reused
        key = (settings.gsd_m, settings.noise)
        if key not in streams:
            streams[key] = GeoStream(world, settings)
        stream = streams[key]
        stream.settings = settings
        targets, info = geo_targets(stream, frames, config.factor)
    t_targets = time.perf_counter() - t0
    doc: dict[str, Any] = {"settings": asdict(settings), "computed": "ground", **info}
    if not targets and not info.get("images"):
        return None, {**doc, "targets": 0}, {"targets_s": round(t_targets, 4)}
    horizon = frames.n_frames * frames.cadence_s + frames.geometry.look_ahead_m / (
        frames.geometry.ground_speed
    )
    t0 = time.perf_counter()
    bp = plan_blueprint(
        targets, replace(frames.geometry, start_s=0.0), agility, horizon_s=horizon,
        reserve=settings.reserve,
    )  # fmt: skip
    t_bp = time.perf_counter() - t0
    doc |= {
        "targets": len(bp.targets),
        "targets_chosen": len(bp.chosen),
        "blueprint_pointings": int(bp.budget.sum()),
        "reserve_pointings": int(bp.reserve),
        "blueprint_value": round(bp.value, 4),
        "slots": bp.info.get("slots", 0),
    }
    times = {"targets_s": round(t_targets, 4), "blueprint_s": round(t_bp, 4)}
    return BlueprintGate(bp, frames, agility, stage=settings.stage), doc, times


TIMES = "geo.timing.json"
"""File of a pass's GEO wall-clock times (``targets_s``, ``blueprint_s``), beside ``summary.json``."""


def write_times(result: Any, out: str | os.PathLike[str]) -> Path | None:
    """Write the GEO wall-clock times of a pass to ``out/geo.timing.json`` (none: nothing).

    ``summary.json`` holds only what a rerun reproduces byte for byte; the measured times
    of the ground segment go here, as ``stage_times.csv`` holds the frames'.

    Parameters
    ----------
    result : dyntarget.fly.loop.PassResult
        The pass (its ``geo_times``).
    out : str or os.PathLike
        The pass's output folder.

    Returns
    -------
    pathlib.Path or None
        The file written, or ``None`` for a pass without GEO.
    """
    import json

    from dyntarget.io.atomic import write_text

    times = getattr(result, "geo_times", None)
    if times is None:
        return None
    return write_text(Path(out) / TIMES, json.dumps(times, sort_keys=True, indent=1) + "\n")
