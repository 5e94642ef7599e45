"""Strips to fly over: synthetic moving strips (several plumes) and users' large GeoTIFFs.

A synthetic strip is one :class:`dyntarget.synth.dynamic.World` (the moving
world of ``synth --frames``) with several vents placed along a long window,
``width`` pixels across and ``length`` along the flight direction (north, up).
On disk (``dyntarget synth --strip``)::

    <id>.tif             the strip at t = 0 (4-band GeoTIFF, to look at or fly as static)
    <id>_mask.tif        its truth at t = 0
    <id>.world.json      {"format": "dyntarget-strip", "version": 1,
                          "world": <WorldSpec>, "window": [col0, row0, width, length]}

``fly`` reads the sidecar when it is there and renders every look-ahead frame
and the truth at the time it is needed; any other GeoTIFF with a label is
flown as a static world (:class:`~dyntarget.fly.world.StaticWorld`).
"""

from __future__ import annotations

import json
import math
import os
from collections import OrderedDict
from dataclasses import replace
from pathlib import Path

import numpy as np

from dyntarget.errors import DataFileError, InvalidParameterError
from dyntarget.fly.world import StaticWorld, Truth, World
from dyntarget.io.atomic import write_text
from dyntarget.observe.nfov import UtilityMaps
from dyntarget.synth.dynamic import World as MovingWorld
from dyntarget.synth.dynamic import WorldSpec, sample_strip

STRIP_FORMAT = "dyntarget-strip"
SIDECAR = ".world.json"


def strip_spec(
    seed: int,
    *,
    width: int = 256,
    length: int = 1152,
    plumes: int = 4,
    gsd: float = 8.0,
    wind_mps: float | None = None,
    wind_from_deg: float | None = None,
) -> tuple[WorldSpec, tuple[int, int, int, int]]:
    """A moving world with ``plumes`` vents along a ``width`` x ``length`` px strip.

    The world is :func:`dyntarget.synth.dynamic.sample_strip`'s (one wind for
    the whole strip, one vent per ``length / plumes`` rows), named ``strip-<seed>``.

    Parameters
    ----------
    seed : the strip's seed (same seed, same strip).
    width, length : strip size in high-resolution pixels.
    plumes : number of vents (>= 1).
    gsd : high-resolution ground sampling distance, m.
    wind_mps, wind_from_deg : the wind (meteorological convention); drawn if not given.

    Returns
    -------
    (WorldSpec, window): the world and the strip's window ``(col0, row0, width, length)``.

    Examples
    --------
    >>> spec, window = strip_spec(0, width=64, length=256, plumes=2, wind_mps=5.0)
    >>> len(spec.vents), window, spec.id
    (2, (0, 0, 64, 256), 'strip-0000')
    """
    for name, v, lo in (("width", width, 32), ("length", length, 64), ("plumes", plumes, 1)):
        if isinstance(v, bool) or not isinstance(v, int) or v < lo:
            raise InvalidParameterError(f"{name}: expected an integer >= {lo}, got {v!r}")
    spec, window = sample_strip(
        seed,
        length=length,
        width=width,
        plumes=plumes,
        gsd=gsd,
        wind_mps=wind_mps,
        wind_from_deg=wind_from_deg,
    )
    return replace(spec, id=f"strip-{seed:04d}"), window


class MovingStrip:
    """A :class:`~dyntarget.fly.world.World` rendered from a moving world, frame by frame.

    The truth at time ``t`` is rendered on the whole strip, ``t`` rounded to
    ``truth_step_s`` (recent times cached). Plume identities: every truth
    pixel belongs to the nearest source at that time (a vent, or a detached
    volcanic cloud where the wind has carried it), so a plume keeps its id as it moves.

    Parameters
    ----------
    spec : dyntarget.synth.dynamic.WorldSpec
        The moving world.
    window : tuple of int
        ``(col0, row0, width, height)`` of the strip on the world grid.
    truth_step_s : float
        Time grid of the truth, seconds (0: exact times).
    capacity : int
        Most truths kept in the cache.

    Examples
    --------
    >>> spec, window = strip_spec(0, width=64, length=256, plumes=2, wind_mps=5.0)
    >>> s = MovingStrip(spec, window)
    >>> s.shape, s.image_at(10.0, 0, 32).shape
    ((256, 64), (4, 32, 64))
    """

    def __init__(
        self,
        spec: WorldSpec,
        window: tuple[int, int, int, int],
        *,
        truth_step_s: float = 1.0,
        capacity: int = 8,
    ) -> None:
        if not (math.isfinite(truth_step_s) and truth_step_s >= 0):
            raise InvalidParameterError(
                f"truth_step_s: expected seconds >= 0, got {truth_step_s!r}"
            )
        from dyntarget.synth.dynamic import check_window

        self.spec, self.window = spec, check_window(window, spec.size)
        self.world = MovingWorld(spec)
        _, _, w, h = self.window
        self.shape = (h, w)
        self.gsd = float(spec.gsd)
        self.crs = spec.crs
        self.transform = self.world.transform(self.window)
        self.valid = None
        self.id = spec.id
        self.acquired = spec.epoch
        self.wind = spec.wind
        """The strip's true wind (what ``predict="wind"`` uses unless a wind is given)."""
        """ISO-8601 UTC of t = 0 (the first frame's acquisition)."""
        self.truth_step_s = truth_step_s
        self._cache: OrderedDict[float, Truth] = OrderedDict()
        self._capacity = capacity

    def image_at(self, t: float, top: int, bottom: int) -> np.ndarray:
        """Rows ``top:bottom`` of the strip as the look-ahead sensor sees them at ``t``.

        Parameters
        ----------
        t : float
            Seconds into the pass.
        top, bottom : int
            Rows of the strip, high resolution.

        Returns
        -------
        numpy.ndarray
            ``(4, bottom - top, W)`` image.
        """
        c0, r0, w, _ = self.window
        return self.world.render(t, (c0, r0 + top, w, bottom - top)).image

    def _sources(self, t: float) -> np.ndarray:
        """``(n, 2)`` source positions (x, y) in strip pixels at ``t``: vents, then volcanic clouds."""
        s = self.spec
        ux, uy = s.wind.velocity_px(s.gsd)
        c0, r0 = self.window[:2]
        pts = [(v.x - c0, v.y - r0) for v in s.vents]
        pts += [(c.x + ux * t - c0, c.y + uy * t - r0) for c in s.clouds if c.volcanic]
        return np.asarray(pts, np.float64).reshape(-1, 2)

    def truth_at(self, t: float) -> Truth:
        """The truth over the whole strip at ``t`` (rounded to ``truth_step_s``).

        Parameters
        ----------
        t : float
            Seconds into the pass.

        Returns
        -------
        dyntarget.fly.world.Truth
            Utility maps and plume ids of the whole strip.
        """
        if self.truth_step_s > 0:
            t = round(t / self.truth_step_s) * self.truth_step_s
        hit = self._cache.get(t)
        if hit is not None:
            self._cache.move_to_end(t)
            return hit
        scene = self.world.scene(t, self.window, id=self.id)
        ids = np.zeros(self.shape, np.int32)
        rows, cols = np.nonzero(scene.label)
        src = self._sources(t)
        if len(rows) and len(src):
            d2 = (cols[:, None] - src[None, :, 0]) ** 2 + (rows[:, None] - src[None, :, 1]) ** 2
            ids[rows, cols] = np.argmin(d2, axis=1).astype(np.int32) + 1
        truth = Truth(UtilityMaps.from_scene(scene), ids)
        self._cache[t] = truth
        if len(self._cache) > self._capacity:
            self._cache.popitem(last=False)
        return truth


def write_strip(
    spec: WorldSpec, window: tuple[int, int, int, int], directory: str | os.PathLike[str]
) -> list[Path]:
    """Write a synthetic strip (image and truth at t = 0, and the world sidecar).

    Parameters
    ----------
    spec, window : from :func:`strip_spec`.
    directory : output directory (created).

    Returns
    -------
    list of the paths written (each atomically).
    """
    from dyntarget.io import write_scene

    directory = Path(directory)
    scene = MovingWorld(spec).scene(0.0, window, id=spec.id)
    written = write_scene(scene, directory)
    doc = {"format": STRIP_FORMAT, "version": 1, "world": spec.to_dict(), "window": list(window)}
    written.append(write_text(directory / f"{spec.id}{SIDECAR}", json.dumps(doc, sort_keys=True)))
    return written


def load_world(path: str | os.PathLike[str], *, truth_step_s: float = 1.0) -> World:
    """The world of a strip file: moving (with its ``.world.json`` sidecar) or static.

    Parameters
    ----------
    path : a strip GeoTIFF (``<id>.tif``); its label beside it for a static strip.
    truth_step_s : time quantum of a moving strip's truth.

    Returns
    -------
    World
    """
    from dyntarget.io.safeopen import check_regular, read_json
    from dyntarget.synth.dynamic import check_window

    path = Path(path)
    sidecar = path.with_name(path.stem + SIDECAR)
    if sidecar.exists() or sidecar.is_symlink():
        doc = read_json(sidecar, what="strip sidecar")
        if not isinstance(doc, dict) or doc.get("format") != STRIP_FORMAT:
            raise DataFileError(f"{sidecar}: not a {STRIP_FORMAT} sidecar")
        try:
            spec = WorldSpec.from_dict(doc.get("world"))
            if not isinstance(doc.get("window"), list):
                raise InvalidParameterError(
                    f"window: expected [col0, row0, width, length] integers, got {doc.get('window')!r:.60}"
                )
            window = check_window(doc["window"], spec.size)
        except InvalidParameterError as exc:
            raise DataFileError(f"{sidecar}: {exc}") from None
        return MovingStrip(spec, window, truth_step_s=truth_step_s)
    from dyntarget.io import read_scene
    from dyntarget.io.acquisition import read_acquired

    check_regular(path, what="--scene")
    world = StaticWorld(read_scene(path))
    try:
        world.acquired = read_acquired(path)
    except OverflowError:
        raise DataFileError(
            f"--scene {path}: acquisition time outside the years 1900..2200"
        ) from None
    if world.acquired is not None and not 1900 <= world.acquired.year <= 2200:
        raise DataFileError(
            f"--scene {path}: acquired {world.acquired.isoformat()}, outside the years 1900..2200"
        )
    return world
