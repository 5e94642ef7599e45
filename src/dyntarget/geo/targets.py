"""GEO targeting: plume detection on GEO images, nowcast targets, the omniscient reference.

* :func:`plume_field` — the plume anomaly of one GEO image (``"unmix"``: the ash and
  steam cover fraction times :data:`CONTRAST`; ``"brightness"``: the band-mean
  brightness above the clear-sky background).
* :func:`geo_targets` — the blueprint's targets from the GEO images usable when it is
  planned, nowcast to when the satellite is over each row (:func:`dyntarget.geo.nowcast`)
  and weighted by their persistence (a vent's plume stays, a drifting cloud does not).
* :func:`omniscient_targets` — the true plumes, each where it is when the satellite is
  over it (no latency, no noise): the reference, not an upper bound.

The pass, the images and the world come in through :mod:`dyntarget.geo.seams`.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import cv2
import numpy as np

from dyntarget.errors import InvalidParameterError
from dyntarget.geo.blueprint import Target
from dyntarget.geo.nowcast import detect, nowcast, unmix
from dyntarget.geo.seams import DetectionSettings, GeoImager, PassFrames, PlumeTruth

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
DETECTIONS = ("unmix", "brightness")
"""How GEO cells are tested for plume (:attr:`DetectionSettings.detection`)."""
ENDMEMBERS = ("simulator", "estimated")
"""Where the unmixing's end-members come from: the imager's stated spectra
(``GeoImager.members``; for the synthetic stream, the simulator's own), or estimated from
the GEO images used (:func:`dyntarget.geo.endmembers.estimate_members`)."""


def image_times(settings: DetectionSettings, t_plan: float) -> list[float]:
    """Acquisition times of the GEO images usable at ``t_plan`` (oldest first, at most three).

    Parameters
    ----------
    settings : DetectionSettings
        ``cadence_s``, ``latency_s`` and ``history_s``.
    t_plan : float
        When the blueprint is planned, pass seconds.

    Returns
    -------
    list of float

    Examples
    --------
    >>> from types import SimpleNamespace as S
    >>> image_times(S(cadence_s=600.0, latency_s=300.0, history_s=3600.0), 0.0)
    [-1800.0, -1200.0, -600.0]
    >>> image_times(S(cadence_s=600.0, latency_s=900.0, history_s=1000.0), 0.0)
    []
    """
    c = settings.cadence_s
    last = math.floor((t_plan - settings.latency_s) / c + 1e-9) * c
    times = [float(last - k * c) for k in range(3)]
    return sorted(t for t in times if t >= -settings.history_s - 1e-9)


def along_of_row(frames: PassFrames, row_w: np.ndarray) -> np.ndarray:
    """Pass ground coordinate (ahead of nadir at t = 0, m) of strip WFOV rows.

    Parameters
    ----------
    frames : PassFrames
        The pass's frame plan.
    row_w : numpy.ndarray
        Strip WFOV rows.

    Returns
    -------
    numpy.ndarray
        Metres ahead of nadir at pass time 0.

    Examples
    --------
    >>> from types import SimpleNamespace
    >>> from dyntarget.schedule import OrbitGeometry
    >>> f = SimpleNamespace(geometry=OrbitGeometry(wfov_gsd_m=64.0), wfov_shape=(100, 8), frame_px=10)
    >>> float(along_of_row(f, np.array([90.0]))[0] - along_of_row(f, np.array([91.0]))[0])
    64.0
    """
    g = frames.geometry
    hw = frames.wfov_shape[0]
    top = hw - frames.frame_px
    return g.look_ahead_m + ((frames.frame_px - 1) / 2.0 - (np.asarray(row_w) - top)) * g.wfov_gsd_m


def _targets_from_mask(
    mask: np.ndarray,
    value_map: np.ndarray,
    row_w: np.ndarray,
    frames: PassFrames,
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
        along = float(np.mean(along_of_row(frames, rows)))
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


def plume_field(
    image: np.ndarray,
    background: np.ndarray,
    settings: DetectionSettings,
    members: np.ndarray | None = None,
    names: list[str] | None = None,
) -> np.ndarray:
    """The plume anomaly of one GEO image (reflectance units; ``threshold`` applies to it).

    ``"unmix"``: the ash + steam cover fraction (:func:`dyntarget.geo.unmix` against
    meteorological cloud, ash and steam) times :data:`CONTRAST`; ``"brightness"``:
    the band-mean brightness above the background (:func:`dyntarget.geo.detect`).

    Parameters
    ----------
    image, background : numpy.ndarray
        ``(bands, rows, cols)`` GEO reflectance, and the clear-sky one.
    settings : DetectionSettings
        ``detection`` and ``threshold``.
    members : numpy.ndarray, optional
        ``(K, bands)`` end-member spectra, needed by ``"unmix"`` (:attr:`GeoImager.members`:
        meteorological cloud, ash, steam).
    names : list of str, optional
        The class of each member (``"cloud"``, ``"ash"``, ``"steam"``; default those three
        in that order): every member but ``"cloud"`` counts as plume.

    Returns
    -------
    numpy.ndarray
        ``(rows, cols)`` anomaly, ``>= 0``.
    """
    if settings.detection == "brightness":
        return detect(image.mean(axis=0), settings.threshold, background.mean(axis=0))[1]
    if members is None:
        raise InvalidParameterError("geo detection 'unmix': needs the end-member spectra")
    m = np.asarray(members, np.float64)
    if len(m) == 0:  # no end-member found (estimated, nothing bright in the images)
        return np.zeros(image.shape[1:])
    f = unmix(image, background, m)
    plume = [i for i, n in enumerate(names or ("cloud", "ash", "steam")) if n != "cloud"]
    field: np.ndarray = CONTRAST * f[plume].sum(axis=0)
    return field


def geo_targets(
    stream: GeoImager,
    settings: DetectionSettings,
    frames: PassFrames,
    factor: int,
    t_plan: float = 0.0,
    *,
    motion: Callable[[np.ndarray], np.ndarray],
) -> tuple[list[Target], dict[str, object]]:
    """Targets for the blueprint from the GEO images usable at ``t_plan``, nowcast to overpass.

    Parameters
    ----------
    stream : GeoImager
        The GEO images of the strip.
    settings : DetectionSettings
        Cadence, latency, archive, detection and threshold.
    frames : the pass's frame plan.
    factor : high-res -> WFOV factor.
    t_plan : when the blueprint is planned, pass seconds.
    motion : callable
        The motion field of the GEO fields, ``motion(stack (T, H, W)) -> (2, H, W)`` pixels
        per interval (:func:`dyntarget.geo.nowcast.nowcast`'s input; the pass passes the
        predict stage's Lucas-Kanade).

    Returns
    -------
    (targets, info): the targets, and what was used (image times, motion).
    """
    s = settings
    times = image_times(s, t_plan)
    info: dict[str, object] = {"images": times}
    if not times:
        return [], {**info, "note": "no GEO image usable before the pass: look-ahead only"}
    bg = stream.background()
    images = [stream.image(t) for t in times]
    members, names = stream.members, None
    if s.detection == "unmix" and getattr(s, "endmembers", "simulator") == "estimated":
        from dyntarget.geo.endmembers import estimate_members

        members, names, found = estimate_members(images, bg)
        info["endmembers"] = found
    fields = [plume_field(im, bg, s, members, names) for im in images]
    nrow = stream.cells[0]
    row_w = stream.strip_rows(np.arange(nrow)) / factor
    v = frames.geometry.ground_speed
    t_obs = np.maximum(along_of_row(frames, row_w) / v - OBSERVE_BEFORE_NADIR_S, 0.0)
    leads_all = np.maximum(t_obs - times[-1], 0.0)
    lo, hi = float(leads_all.min()), float(leads_all.max())
    leads = list(np.linspace(lo, hi, LEAD_STEPS)) if hi > lo else [lo]
    out, vel = nowcast(fields, s.cadence_s, leads, motion)
    pick = np.abs(leads_all[:, None] - np.asarray(leads)[None, :]).argmin(axis=1)
    composite = out[pick, np.arange(nrow)]  # (nrow, ncol): each row at its own lead
    # persistence: a vent's plume stays where it is from image to image, a drifting
    # cloud does not: weight each cell by its smallest anomaly over the images
    # relative to the last one (1: steady; about 0: something passing through)
    # (an eruption that started between the images is weighted down as well: it is new in
    # the last one; ``persistence=False`` drops the weight, see docs/results.md)
    last = np.maximum(fields[-1], 1e-6)
    persist = getattr(s, "persistence", True) and len(fields) > 1
    steady = np.clip(np.minimum.reduce(fields) / last, 0.0, 1.0) if persist else 1.0
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
    gsd, (c0, _, w, _) = stream.strip_gsd, stream.window
    cx = (stream.cell0[0] + np.arange(a1, b1) + 0.5) * s.gsd_m
    lo_x, hi_x = c0 * gsd, (c0 + w) * gsd
    cross = np.clip(cx, lo_x, hi_x) - (lo_x + hi_x) / 2.0
    # the row range of a target, widened (its position is that coarse)
    margin = SPAN_CELLS * s.gsd_m / (gsd * factor)
    frac = np.clip(sub / CONTRAST, 0.0, 1.0)
    targets = _targets_from_mask(
        mask, sub * weight[:, a1:b1], row_w, frames, s.gsd_m, cross, margin, frac
    )
    speed = float(np.hypot(*np.median(vel.reshape(2, -1), axis=1)) * s.gsd_m)
    return targets, {**info, "motion_mps": round(speed, 3)}


def omniscient_targets(world: PlumeTruth, frames: PassFrames, factor: int) -> list[Target]:
    """The true plumes as targets: each band of the strip at the time the satellite is over it.

    Rendered on the WFOV grid (the true label, no noise, no latency), so each
    target's rows, area and need are the true ones.

    Parameters
    ----------
    world : PlumeTruth
        A moving strip.
    frames : PassFrames
        The pass's frame plan.
    factor : int
        High-res -> WFOV factor.

    Returns
    -------
    list of Target
    """
    c0, r0, w, h = world.window
    gw = world.gsd * factor
    coarse = world.wfov_renderer(factor)
    hw, ww = h // factor, w // factor
    label = np.zeros((hw, ww), bool)
    value = np.zeros((hw, ww), np.float32)
    v = frames.geometry.ground_speed
    band = 1024
    reach = OMNISCIENT_REACH_M / gw
    for a in range(0, hw, band):
        b = min(hw, a + band)
        t_mid = (along_of_row(frames, np.array([(a + b) / 2.0]))[0]) / v
        near = [y for y in world.source_rows(t_mid, factor) if a - reach <= y <= b + reach]
        if not near:
            continue
        mid = np.array([(a + b) / 2.0])
        t = float(max(along_of_row(frames, mid)[0] / v - OBSERVE_BEFORE_NADIR_S, 0.0))
        mk, tau = coarse.truth(t, (c0 // factor, r0 // factor + a, ww, b - a))
        label[a:b], value[a:b] = mk, 1.0 - np.exp(-tau)
    cross = (np.arange(ww) - (ww - 1) / 2.0) * gw
    return _targets_from_mask(
        label, value, np.arange(hw, dtype=float), frames, gw, cross, 2.0, curve=True
    )
