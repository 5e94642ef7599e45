"""Geostationary foresight for a pass: the settings, and the blueprint and gate of a pass.

Orchestration only; the parts live in their stages:

* the GEO images of a synthetic strip: :class:`dyntarget.synth.geoimager.GeoStream`
  (every simulated input lives in :mod:`dyntarget.synth`);
* detection, nowcast targets and the omniscient reference:
  :mod:`dyntarget.geo.targets` (:func:`~dyntarget.geo.targets.geo_targets`,
  :func:`~dyntarget.geo.targets.omniscient_targets`);
* the blueprint: :func:`dyntarget.geo.plan_blueprint`, computed on the ground before
  the pass from the images usable at pass time 0, and uplinked;
* the onboard refinement and staging: :class:`dyntarget.geo.refine.BlueprintGate`;
* the catalog prior: :func:`dyntarget.geo.catalog.prior_targets`.

:func:`prepare` picks the targets for :class:`GeoSettings` (GEO images, the truth,
a catalog, or none: ``blind``), plans the blueprint and returns the gate the loop
routes its pointings through (the loop sees it as a :class:`Gate`). The GEO streams and the truth targets of a world are
kept per world (:func:`geo_cache`), so a benchmark flying one strip many ways renders
them once.
"""

from __future__ import annotations

import math
import weakref
from dataclasses import asdict, dataclass, field, replace
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from dyntarget.errors import InvalidParameterError, InvalidSceneError
from dyntarget.geo import Target, plan_blueprint
from dyntarget.geo.refine import BlueprintGate
from dyntarget.geo.targets import DETECTIONS, ENDMEMBERS, geo_targets, omniscient_targets
from dyntarget.schedule import OrbitGeometry
from dyntarget.synth.geoimager import GeoStream
from dyntarget.synth.strip_world import MovingStrip

if TYPE_CHECKING:
    from dyntarget.passes.record import FramePlan, PassConfig
    from dyntarget.synth.worlds import World


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
    endmembers : where the unmixing's end-members come from: ``"simulator"`` (the GEO
        imager's stated spectra; for the synthetic stream the simulator's own) or
        ``"estimated"`` (found in the GEO images used, N-FINDR:
        :func:`dyntarget.geo.endmembers.estimate_members`).
    persistence : weight each GEO cell by how steady its plume is over the images (a
        drifting cloud passes, a vent's plume stays; an eruption newer than the oldest image
        is weighted down too); ``False``: an ablation, every detection at full weight.
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
    endmembers: str = "simulator"
    persistence: bool = True

    def __post_init__(self) -> None:
        if self.omniscient and self.blind:
            raise InvalidParameterError("geo: omniscient and blind exclude each other")
        if self.prior is not None and (self.omniscient or self.blind):
            raise InvalidParameterError("geo: a catalog prior excludes omniscient and blind")
        if self.detection not in DETECTIONS:
            raise InvalidParameterError(
                f"geo detection: expected one of {', '.join(DETECTIONS)}, got {self.detection!r}"
            )
        if not isinstance(self.persistence, bool):
            raise InvalidParameterError(
                f"geo persistence: expected true or false, got {self.persistence!r}"
            )
        if self.endmembers not in ENDMEMBERS:
            raise InvalidParameterError(
                f"geo end-members: expected one of {', '.join(ENDMEMBERS)}, got {self.endmembers!r}"
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


@dataclass
class GeoCache:
    """What :func:`prepare` keeps of one world across passes (the same world, flown many ways).

    Parameters
    ----------
    streams : dict
        The world's GEO images, by ``(gsd_m, noise)``.
    truth_targets : dict
        The omniscient targets, by ``(factor, frame_px, step, geometry)``.
    """

    streams: dict[tuple[float, float], GeoStream] = field(default_factory=dict)
    truth_targets: dict[tuple[int, int, int, OrbitGeometry], list[Target]] = field(
        default_factory=dict
    )


_CACHES: weakref.WeakKeyDictionary[object, GeoCache] = weakref.WeakKeyDictionary()


def geo_cache(world: object) -> GeoCache:
    """The :class:`GeoCache` of ``world`` (created empty; dropped with the world).

    Parameters
    ----------
    world : object
        The strip flown.

    Returns
    -------
    GeoCache

    Examples
    --------
    >>> class W: pass
    >>> w = W()
    >>> geo_cache(w) is geo_cache(w), geo_cache(w).streams
    (True, {})
    """
    hit = _CACHES.get(world)
    if hit is None:
        hit = _CACHES[world] = GeoCache()
    return hit


def _geo_motion(stack: np.ndarray) -> np.ndarray:
    """The GEO fields' motion (px per interval): the predict stage's one Lucas-Kanade wrapper."""
    from dyntarget.predict import lucas_kanade

    return lucas_kanade(
        stack, needs="nowcasting GEO images needs pysteps: pip install 'dyntarget[geo]'"
    )


def prepare(
    world: World, frames: FramePlan, config: PassConfig, settings: GeoSettings
) -> tuple[BlueprintGate | None, dict[str, Any], dict[str, float]]:
    """The blueprint and gate of a pass (``None`` gate: no GEO image arrived: look-ahead only).

    Parameters
    ----------
    world : dyntarget.synth.worlds.World
        The strip (a moving strip for GEO images and the omniscient reference).
    frames : dyntarget.passes.record.FramePlan
        Its frame plan.
    config : dyntarget.passes.record.PassConfig
        The pass (agility, factor).
    settings : GeoSettings

    Returns
    -------
    (gate or None, info dict for summary.json, timings dict for
        :data:`dyntarget.view.pass_report.TIMES`)
        The info is deterministic (same inputs, same bytes); the wall-clock times of
        the targets and the blueprint (``targets_s``, ``blueprint_s``) are kept apart.
    """
    import time

    settings.check_against(frames.geometry.wfov_gsd_m)
    agility = config.limits  # the preset, looked up once per pass
    t0 = time.perf_counter()
    targets: list[Target]
    info: dict[str, Any]
    if settings.blind:
        targets, info = [], {"images": "none: no blueprint (the refinement alone)"}
    elif settings.prior is not None:
        from dyntarget.geo.catalog import prior_targets

        targets, info = prior_targets(settings.prior, world, frames, config.factor)
    elif not isinstance(world, MovingStrip):
        raise InvalidSceneError(
            f"strip {world.id!r}: --geo needs a synthetic strip (its world renders the "
            "GEO stream); a GeoTIFF strip has no world to render"
        )
    elif settings.omniscient:
        cache = geo_cache(world).truth_targets  # reused across presets
        tkey = (config.factor, frames.frame_px, frames.step, frames.geometry)
        if tkey not in cache:
            cache[tkey] = omniscient_targets(world, frames, config.factor)
        targets, info = cache[tkey], {"images": "truth"}
    else:
        streams = geo_cache(world).streams  # the same images, reused
        key = (settings.gsd_m, settings.noise)
        if key not in streams:
            streams[key] = GeoStream(world.spec, world.window, settings.gsd_m, settings.noise)
        targets, info = geo_targets(
            streams[key], settings, frames, config.factor, motion=_geo_motion
        )
    t_targets = time.perf_counter() - t0
    kept = asdict(settings)
    for name, default in (("endmembers", "simulator"), ("persistence", True)):
        if kept[name] == default:  # the defaults: summary.json keeps its bytes
            del kept[name]
    doc: dict[str, Any] = {"settings": kept, "computed": "ground", **info}
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
        "target_along_cross_m": [[round(t.along_m, 1), round(t.cross_m, 1)] for t in bp.targets],
        "targets_chosen": len(bp.chosen),
        "blueprint_pointings": int(bp.budget.sum()),
        "reserve_pointings": int(bp.reserve),
        "blueprint_value": round(bp.value, 4),
        "slots": bp.info.get("slots", 0),
    }
    times = {"targets_s": round(t_targets, 4), "blueprint_s": round(t_bp, 4)}
    return BlueprintGate(bp, frames, agility, stage=settings.stage), doc, times


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
