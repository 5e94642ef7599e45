"""Strips to fly over: synthetic moving strips (several plumes) and users' large GeoTIFFs.

:class:`MovingStrip` and :class:`LongStrip` render a synthetic strip's world
(:mod:`dyntarget.synth.strip` makes and writes them) frame by frame;
:func:`load_world` reads a strip file: moving when its ``.world.json`` sidecar is
there, otherwise a static world (:class:`~dyntarget.synth.worlds.StaticWorld`). All
three implement :class:`dyntarget.synth.worlds.World`.
"""

from __future__ import annotations

import math
import os
from collections import OrderedDict
from pathlib import Path
from typing import Any

import numpy as np

from dyntarget.errors import DataFileError, InvalidParameterError
from dyntarget.synth.dynamic import Wind, WorldFrame, WorldSpec
from dyntarget.synth.dynamic import World as MovingWorld
from dyntarget.synth.strip import (
    LONG_VERSION,
    MAX_LENGTH_KM,
    MAX_LONG_ROWS,
    SIDECAR,
    STRIP_FORMAT,
    resampled_spec,
)
from dyntarget.synth.worlds import StaticWorld, Truth, World, WorldBase
from dyntarget.utility import UtilityMaps


def _check_truth_step(truth_step_s: float) -> None:
    if not (math.isfinite(truth_step_s) and truth_step_s >= 0):
        raise InvalidParameterError(f"truth_step_s: expected seconds >= 0, got {truth_step_s!r}")


class MovingStrip(WorldBase):
    """A :class:`~dyntarget.synth.worlds.World` rendered from a moving world, frame by frame.

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
    >>> from dyntarget.synth.strip import strip_spec
    >>> spec, window = strip_spec(0, width=64, length=256, plumes=2, wind_mps=5.0)
    >>> s = MovingStrip(spec, window)
    >>> s.shape, s.image_at(10.0, 0, 32).shape
    ((256, 64), (4, 32, 64))
    """

    spec: WorldSpec
    wind: Wind
    truth_step_s: float
    acquired: str

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
        self.is_3d = spec.is_3d
        """Whether the world's plumes or clouds have heights (``spec.is_3d``)."""

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

    def look_at(
        self,
        t: float,
        top: int,
        bottom: int,
        *,
        nadir_xy: tuple[float, float],
        altitude_m: float,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Rows ``top:bottom`` as the look-ahead sees them at ``t`` from over ``nadir_xy``.

        A 3D world is rendered obliquely (:meth:`dyntarget.synth.dynamic.World.render_look`
        on the strip's window of the world grid): each plume at its column's height and
        each cloud at its height appears displaced away from the nadir by its parallax;
        the mask is the displaced plume's (optical depth above the label threshold, as
        the truth's label), of the same rendering at exactly ``t``. A flat world returns
        exactly :meth:`image_at` and :meth:`label_rows`.

        Parameters
        ----------
        t : float
            Seconds into the pass.
        top, bottom : int
            Rows of the strip, high resolution.
        nadir_xy : tuple of float
            The spacecraft's nadir ``(x, y)`` in strip high-resolution pixels.
        altitude_m : float
            The spacecraft's altitude, metres.

        Returns
        -------
        image : numpy.ndarray
            ``(4, bottom - top, W)`` reflectance.
        mask : numpy.ndarray
            Boolean ``(bottom - top, W)``: the plume the frame shows.

        Examples
        --------
        >>> from dataclasses import replace
        >>> from dyntarget.synth.strip import strip_spec
        >>> spec, window = strip_spec(0, width=64, length=256, plumes=1, wind_mps=5.0)
        >>> flat = MovingStrip(spec, window)
        >>> im, m = flat.look_at(0.0, 0, 32, nadir_xy=(32.0, 9e4), altitude_m=500e3)
        >>> bool((im == flat.image_at(0.0, 0, 32)).all()), flat.is_3d
        (True, False)
        >>> v = replace(spec.vents[0], top_height_m=10e3)
        >>> s3 = MovingStrip(replace(spec, vents=(v,)), window)
        >>> s3.is_3d, s3.look_at(0.0, 0, 32, nadir_xy=(32.0, 9e4), altitude_m=500e3)[1].shape
        (True, (32, 64))
        """
        if not self.is_3d:
            return self.image_at(t, top, bottom), self.label_rows(t, top, bottom)
        c0, r0, w, _ = self.window
        nx, ny = (float(v) for v in nadir_xy)
        frame = self.world.render_look(
            t, (c0, r0 + top, w, bottom - top), nadir_px=(c0 + nx, r0 + ny), altitude_m=altitude_m
        )
        return frame.image, frame.mask

    def heights_at(self, t: float) -> np.ndarray | None:
        """Top height of each truth plume at ``t``: the vents' columns, then volcanic clouds.

        Indexed by plume id as :meth:`truth_at` numbers them (index 0, no plume: 0.0);
        a vent's column rises from its onset (:meth:`dyntarget.synth.dynamic.World.column_height`,
        at exactly ``t``); a feature without a height lies on the ground (0.0).

        Parameters
        ----------
        t : float
            Seconds into the pass.

        Returns
        -------
        numpy.ndarray or None
            float64 metres above sea level, ``1 + vents + volcanic clouds`` long;
            ``None`` for a flat world.

        Examples
        --------
        >>> from dataclasses import replace
        >>> from dyntarget.synth.strip import strip_spec
        >>> spec, window = strip_spec(0, width=64, length=256, plumes=1, wind_mps=5.0)
        >>> v = replace(spec.vents[0], top_height_m=9000.0, rise_mps=30.0, eruption_age_s=100.0)
        >>> MovingStrip(replace(spec, vents=(v,)), window).heights_at(0.0).tolist()
        [0.0, 3000.0]
        >>> MovingStrip(spec, window).heights_at(0.0) is None
        True
        """
        if not self.is_3d:
            return None
        try:
            tf = float(t)
        except (TypeError, ValueError):
            tf = math.nan
        if not math.isfinite(tf):
            raise InvalidParameterError(f"t: expected finite seconds, got {t!r:.40}")
        s = self.spec
        heights = [0.0] + [self.world.column_height(vi, tf) for vi in range(len(s.vents))]
        heights += [float(c.height_m or 0.0) for c in s.clouds if c.volcanic]
        return np.asarray(heights, np.float64)

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
        dyntarget.synth.worlds.Truth
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

    def source_rows(self, t: float, factor: int) -> list[float]:
        """Strip WFOV rows of the plume sources at ``t``: the vents, then the volcanic clouds.

        Parameters
        ----------
        t : float
            Seconds into the pass.
        factor : int
            High-res -> WFOV factor.

        Returns
        -------
        list of float
        """
        s = self.spec
        _, uy = s.wind.velocity_px(s.gsd)
        r0 = self.window[1]
        rows = [v.y / factor - r0 / factor for v in s.vents]
        rows += [(c.y + uy * t) / factor - r0 / factor for c in s.clouds if c.volcanic]
        return rows

    def vent_pixels(self) -> np.ndarray:
        """``(n, 2)`` strip ``(col, row)`` of the world's vents, high resolution.

        Returns
        -------
        numpy.ndarray
        """
        c0, r0 = self.window[:2]
        cols = np.array([v.x - c0 for v in self.spec.vents], np.float64)
        rows = np.array([v.y - r0 for v in self.spec.vents], np.float64)
        return np.stack([cols, rows], axis=1).reshape(-1, 2)

    def wfov_renderer(self, factor: int) -> MovingWorld:
        """The strip's world on a grid ``factor`` times coarser (its WFOV grid).

        Parameters
        ----------
        factor : int
            High-res -> WFOV factor.

        Returns
        -------
        dyntarget.synth.dynamic.World
        """
        return MovingWorld(resampled_spec(self.spec, self.spec.gsd * factor, lambda c: c / factor))


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
    >>> from dyntarget.synth.strip import long_strip_spec
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
        self._frames: OrderedDict[tuple[float, int, int], WorldFrame] = OrderedDict()
        self._frame_capacity = frame_capacity
        self.is_3d = spec.is_3d

    is_long = True

    def _render(self, t: float, top: int, bottom: int) -> WorldFrame:
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
        dyntarget.synth.worlds.Truth
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
