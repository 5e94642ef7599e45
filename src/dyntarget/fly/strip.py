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
from typing import Any

import numpy as np

from dyntarget.errors import DataFileError, InvalidParameterError
from dyntarget.fly.world import StaticWorld, Truth, World
from dyntarget.io.atomic import write_text
from dyntarget.observe.nfov import UtilityMaps
from dyntarget.synth.dynamic import World as MovingWorld
from dyntarget.synth.dynamic import WorldSpec, sample_strip

STRIP_FORMAT = "dyntarget-strip"
SIDECAR = ".world.json"
LONG_VERSION = 2
"""Sidecar version of a long strip (rendered lazily, :class:`LongStrip`)."""
MIN_LENGTH_KM, MAX_LENGTH_KM = 10.0, 10_000.0
MAX_LONG_ROWS = 2_000_000
"""Most rows of a long strip's window (10,000 km at 5 m; the default 8 m gives 1,250,000)."""
PREVIEW_ROWS = 1152
"""Rows of a long strip written as its ``<id>.tif`` preview (the start of the pass)."""
LONG_ERUPTION_AGE_S = 7200.0
"""Vents of a long strip have erupted this long at t = 0 (steady plumes in every GEO image)."""


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


def long_strip_spec(
    seed: int,
    length_km: float,
    *,
    width: int = 256,
    gsd: float = 8.0,
    plumes: int | None = None,
    plumes_per_100km: float | None = None,
    clouds_per_100km: float = 2.0,
    wind_mps: float | None = None,
    wind_from_deg: float | None = None,
) -> tuple[WorldSpec, tuple[int, int, int, int]]:
    """A pass-length moving world: vents and drifting clouds spread along ``length_km``.

    ``plumes`` vents (or ``plumes_per_100km`` per 100 km, at least one), one per
    equal segment of the strip at a random place inside it (30-70 % of the
    segment, 25-75 % across); each vent has the plume draws of
    :func:`dyntarget.synth.dynamic.sample_world` (world ``k`` of ``seed``) and has
    erupted :data:`LONG_ERUPTION_AGE_S` at t = 0, so its plume is steady in every
    geostationary image before the pass. Meteorological clouds (not plume: they
    hide the ground and the plumes from both sensors) are placed uniformly,
    ``clouds_per_100km`` per 100 km, 0.3-1.5 km in radius.

    Parameters
    ----------
    seed : the strip's seed.
    length_km : strip length along track, km (10 .. 10 000).
    width : strip width, high-resolution pixels.
    gsd : high-resolution ground sampling distance, m.
    plumes, plumes_per_100km : the vents: a count, or a density (one of them; default 1 / 100 km).
    clouds_per_100km : meteorological cloud density (the clouds drawn must not exceed
        :data:`~dyntarget.synth.dynamic.MAX_CLOUDS`; more are refused, not capped).
    wind_mps, wind_from_deg : the wind (drawn if not given).

    Returns
    -------
    (WorldSpec, window): the world and the strip's window ``(0, 0, width, rows)``.

    Examples
    --------
    >>> spec, window = long_strip_spec(0, 500.0, plumes_per_100km=0.4)
    >>> len(spec.vents), window, spec.id
    (2, (0, 0, 256, 62500), 'strip-0000')
    """
    from dyntarget.synth.dynamic import MAX_CLOUDS, MAX_VENTS, CloudSpec, VentSpec, sample_world

    if not (isinstance(length_km, int | float) and MIN_LENGTH_KM <= length_km <= MAX_LENGTH_KM):
        raise InvalidParameterError(
            f"length_km: expected {MIN_LENGTH_KM:g} to {MAX_LENGTH_KM:g} km, got {length_km!r}"
        )
    if isinstance(width, bool) or not isinstance(width, int) or not 32 <= width <= 4096:
        raise InvalidParameterError(f"width: expected an integer in 32..4096, got {width!r}")
    if plumes is not None and plumes_per_100km is not None:
        raise InvalidParameterError("give plumes or plumes_per_100km, not both")
    if plumes_per_100km is not None and not (
        math.isfinite(plumes_per_100km) and plumes_per_100km > 0
    ):
        raise InvalidParameterError(
            f"plumes_per_100km: expected a density > 0, got {plumes_per_100km!r}"
        )
    if not (math.isfinite(clouds_per_100km) and clouds_per_100km >= 0):
        raise InvalidParameterError(
            f"clouds_per_100km: expected a density >= 0, got {clouds_per_100km!r}"
        )
    rows = round(length_km * 1e3 / gsd)
    if rows < 4 * width:
        raise InvalidParameterError(
            f"length_km: {length_km:g} km is {rows} px at {gsd:g} m, shorter than 4 x the width"
        )
    n = (
        plumes
        if plumes is not None
        else max(1, round(length_km / 100.0 * (plumes_per_100km or 1.0)))
    )
    if isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= MAX_VENTS:
        raise InvalidParameterError(
            f"plumes: expected 1 to {MAX_VENTS} vents along the strip, got {n!r}"
        )
    base = sample_world(
        seed, 0, size=width, gsd=gsd, wind_mps=wind_mps, wind_from_deg=wind_from_deg
    )
    rng = np.random.default_rng([int(seed), 0xD7])
    seg = rows / n
    vents = []
    for k in range(n):
        v = sample_world(
            seed, k, size=width, gsd=gsd, wind_mps=base.wind.speed_mps,
            wind_from_deg=base.wind.from_deg,
        ).vents[0]  # fmt: skip
        y = seg * (k + float(rng.uniform(0.3, 0.7)))
        x = width * float(rng.uniform(0.25, 0.75))
        vents.append(
            VentSpec(**{**v.__dict__, "x": x, "y": y, "eruption_age_s": LONG_ERUPTION_AGE_S})
        )
    n_clouds = int(rng.poisson(length_km / 100.0 * clouds_per_100km))
    if n_clouds > MAX_CLOUDS:  # refused, not silently capped
        raise InvalidParameterError(
            f"clouds_per_100km: {n_clouds} clouds drawn over {length_km:g} km, more than the "
            f"{MAX_CLOUDS} a strip may hold (--clouds-per-100km); give a lower density"
        )
    clouds = [
        CloudSpec(
            x=float(rng.uniform(-0.2, 1.2) * width),
            y=float(rng.uniform(0.0, rows)),
            radius_m=float(rng.uniform(300.0, 1500.0)),
            optical_depth=float(rng.uniform(2.0, 6.0)),
            volcanic=False,
            ash_fraction=0.0,
        )
        for _ in range(n_clouds)
    ]
    spec = replace(
        base, vents=tuple(vents), clouds=tuple(clouds), tile=2048, id=f"strip-{int(seed):04d}"
    )
    return spec, (0, 0, int(width), rows)


def _check_truth_step(truth_step_s: float) -> None:
    if not (math.isfinite(truth_step_s) and truth_step_s >= 0):
        raise InvalidParameterError(f"truth_step_s: expected seconds >= 0, got {truth_step_s!r}")


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
        _check_truth_step(truth_step_s)
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
        self._cache: OrderedDict[Any, Truth] = OrderedDict()  # keyed by time (and rows)
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
        rows, cols = np.nonzero(scene.truth)
        src = self._sources(t)
        if len(rows) and len(src):
            d2 = (cols[:, None] - src[None, :, 0]) ** 2 + (rows[:, None] - src[None, :, 1]) ** 2
            ids[rows, cols] = np.argmin(d2, axis=1).astype(np.int32) + 1
        truth = Truth(UtilityMaps.from_scene(scene), ids)
        self._cache[t] = truth
        if len(self._cache) > self._capacity:
            self._cache.popitem(last=False)
        return truth


class LongStrip(MovingStrip):
    """A pass-length moving strip, rendered lazily: only the rows a frame or a score needs.

    The truth of the whole strip is never built: :meth:`truth_rows` renders
    the rows asked for (cached, recent bands). Utility is absolute here: the
    intensity utility is the label times the red reflectance (0..1) and the
    gradient utility the 5x5 Sobel magnitude of it over 48 (its largest value
    on a 0..1 image), not normalised by the strip's peak as on a short strip
    (which needs the whole strip). Memory does not grow with the length.

    Parameters
    ----------
    spec, window : from :func:`long_strip_spec`.
    truth_step_s : time grid of the truth, s.
    capacity : most truth bands kept.
    frame_capacity : most renderings kept (a benchmark flying one strip many ways
        keeps them all; a pass needs 4).

    Examples
    --------
    >>> spec, window = long_strip_spec(0, 100.0, plumes=2, wind_mps=5.0)
    >>> s = LongStrip(spec, window)
    >>> s.shape, s.truth_rows(0.0, 100, 164).ids.shape, sorted(s.plumes_at_start())
    ((12500, 256), (64, 256), [1, 2])
    """

    def __init__(
        self,
        spec: WorldSpec,
        window: tuple[int, int, int, int],
        *,
        truth_step_s: float = 1.0,
        capacity: int = 48,
        frame_capacity: int = 4,
    ) -> None:
        from dyntarget.synth.dynamic import MAX_COORD_PX

        _check_truth_step(truth_step_s)
        c0, r0, w, h = (int(v) for v in window)
        if not (32 <= w <= 4096 and 64 <= h <= MAX_COORD_PX and abs(c0) + abs(r0) <= MAX_COORD_PX):
            raise InvalidParameterError(f"window: {window!r} is not a long strip's window")
        most = min(math.ceil(MAX_LENGTH_KM * 1e3 / float(spec.gsd)), MAX_LONG_ROWS)
        if h > most:  # the longest strip long_strip_spec makes: its work grows with the rows
            raise InvalidParameterError(
                f"window: {h:,} rows of {float(spec.gsd):g} m, more than the {most:,} of the "
                f"longest strip ({MAX_LENGTH_KM:g} km, at most {MAX_LONG_ROWS:,} rows)"
            )
        self.spec, self.window = spec, (c0, r0, w, h)
        self.world = MovingWorld(spec)
        self.shape = (h, w)
        self.gsd = float(spec.gsd)
        self.crs = spec.crs
        self.transform = self.world.transform((c0, r0, w, 1))
        self.valid = None
        self.id = spec.id
        self.acquired = spec.epoch
        self.wind = spec.wind
        self.truth_step_s = truth_step_s
        self._cache: OrderedDict[tuple[float, int, int], Truth] = OrderedDict()
        self._capacity = capacity
        self._frames: OrderedDict[tuple[float, int, int], Any] = OrderedDict()
        self._frame_capacity = frame_capacity

    def _render(self, t: float, top: int, bottom: int):
        """The world's rendering of rows ``top:bottom`` at ``t`` (the last few kept)."""
        key = (float(t), int(top), int(bottom))
        hit = self._frames.get(key)
        if hit is None:
            c0, r0, w, _ = self.window
            hit = self._frames[key] = self.world.render(t, (c0, r0 + top, w, bottom - top))
            if len(self._frames) > self._frame_capacity:
                self._frames.popitem(last=False)
        return hit

    def image_at(self, t: float, top: int, bottom: int) -> np.ndarray:
        """Rows ``top:bottom`` as the look-ahead sensor sees them at ``t`` (rendered on demand).

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
        return self._render(t, top, bottom).image

    def label_rows(self, t: float, top: int, bottom: int) -> np.ndarray:
        """The true label of rows ``top:bottom`` at exactly ``t`` (the frame's own rendering).

        Parameters
        ----------
        t : float
            Seconds into the pass.
        top, bottom : int
            Rows of the strip, high resolution.

        Returns
        -------
        numpy.ndarray
            Boolean ``(bottom - top, W)``.
        """
        return self._render(t, top, bottom).mask

    def quantize(self, t: float) -> float:
        """``t`` on the truth's time grid.

        Parameters
        ----------
        t : float
            Seconds into the pass.

        Returns
        -------
        float
            ``t`` rounded to ``truth_step_s``.
        """
        return round(t / self.truth_step_s) * self.truth_step_s if self.truth_step_s > 0 else t

    def truth_at(self, t: float) -> Truth:
        """Not available on a long strip (the whole truth is never built): see :meth:`truth_rows`.

        Parameters
        ----------
        t : float
            Seconds into the pass.

        Returns
        -------
        Truth
            Never: raises :class:`~dyntarget.errors.InvalidParameterError`.
        """
        raise InvalidParameterError(
            f"strip {self.id!r}: a long strip renders its truth by rows (truth_rows)"
        )

    def plumes_at_start(self) -> frozenset[int]:
        """Plume ids present at t = 0: every vent erupting by then, volcanic clouds over the strip.

        Returns
        -------
        frozenset of int
            Ids as :meth:`truth_rows` numbers them (vents first, then volcanic clouds).
        """
        s = self.spec
        c0, r0, w, h = self.window
        ids = [i + 1 for i, v in enumerate(s.vents) if v.eruption_age_s > 0]
        n = len(s.vents)
        j = 0
        for c in s.clouds:
            if c.volcanic:
                j += 1
                if c0 <= c.x < c0 + w and r0 <= c.y < r0 + h:
                    ids.append(n + j)
        return frozenset(ids)

    def truth_rows(self, t: float, top: int, bottom: int) -> Truth:
        """The truth of rows ``top:bottom`` at ``t`` (rounded to ``truth_step_s``).

        Parameters
        ----------
        t : float
            Seconds into the pass.
        top, bottom : int
            Rows of the strip, high resolution.

        Returns
        -------
        dyntarget.fly.world.Truth
            Utility maps (absolute, see the class docstring) and plume ids of the rows.
        """
        import cv2

        t = self.quantize(t)
        key = (t, int(top), int(bottom))
        hit = self._cache.get(key)
        if hit is not None:
            self._cache.move_to_end(key)
            return hit
        f = self._render(t, top, bottom)
        label = f.mask
        intensity = (label * f.image[2]).astype(np.float32)
        gx = cv2.Sobel(intensity, cv2.CV_32F, 1, 0, ksize=5)
        gy = cv2.Sobel(intensity, cv2.CV_32F, 0, 1, ksize=5)
        gradient = np.clip(np.hypot(gx, gy) / 48.0, 0.0, 1.0).astype(np.float32)
        ids = np.zeros(label.shape, np.int32)
        rows, cols = np.nonzero(label)
        src = self._sources(t)
        if len(rows) and len(src):
            d2 = (cols[:, None] - src[None, :, 0]) ** 2 + (
                rows[:, None] + top - src[None, :, 1]
            ) ** 2
            ids[rows, cols] = np.argmin(d2, axis=1).astype(np.int32) + 1
        truth = Truth(UtilityMaps(label, intensity, gradient, None), ids)
        self._cache[key] = truth
        if len(self._cache) > self._capacity:
            self._cache.popitem(last=False)
        return truth


def write_long_strip(
    spec: WorldSpec, window: tuple[int, int, int, int], directory: str | os.PathLike[str]
) -> list[Path]:
    """Write a long strip: its world sidecar (version 2) and a preview of its start.

    ``<id>.tif`` / ``<id>_mask.tif`` hold only the first :data:`PREVIEW_ROWS`
    rows flown (the bottom of the strip) at t = 0; ``fly`` renders the whole
    strip from ``<id>.world.json``, frame by frame.

    Parameters
    ----------
    spec, window : from :func:`long_strip_spec`.
    directory : output directory (created).

    Returns
    -------
    list of the paths written (each atomically).
    """
    from dyntarget.io import write_scene

    directory = Path(directory)
    c0, r0, w, h = window
    n = min(PREVIEW_ROWS, h)
    scene = MovingWorld(spec).scene(0.0, (c0, r0 + h - n, w, n), id=spec.id)
    written = write_scene(scene, directory)
    doc = {
        "format": STRIP_FORMAT,
        "version": LONG_VERSION,
        "world": spec.to_dict(),
        "window": list(window),
        "length_km": h * spec.gsd / 1e3,
        "preview_rows": n,
    }
    written.append(write_text(directory / f"{spec.id}{SIDECAR}", json.dumps(doc, sort_keys=True)))
    return written


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
            world = doc.get("world")
            if not isinstance(world, dict):
                raise InvalidParameterError(f"world: expected an object, got {world!r:.60}")
            spec = WorldSpec.from_dict(world)
            win = doc.get("window")
            if not (
                isinstance(win, list)
                and len(win) == 4
                and all(isinstance(v, int) and not isinstance(v, bool) for v in win)
            ):
                raise InvalidParameterError(
                    f"window: expected [col0, row0, width, length] integers, got {win!r:.60}"
                )
            if doc.get("version") == LONG_VERSION:
                return LongStrip(spec, tuple(win), truth_step_s=truth_step_s)
            window = check_window(win, spec.size)
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
