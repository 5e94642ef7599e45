"""A geostationary imager over a synthetic strip: the GEO images ``fly --geo`` plans on.

The strip's world (:class:`~dyntarget.synth.dynamic.WorldSpec`) seen by a
geostationary imager: rendered at ``gsd_m / 8`` (area-averaged: narrow plumes count
by the fraction of the cell they cover) over the strip and an 8 km margin around it,
averaged onto ``gsd_m`` cells, plus the imager's own Gaussian noise (``noise``,
reflectance). :class:`GeoStream` implements :class:`dyntarget.geo.seams.GeoImager`.

**Seen from the GEO, with parallax** (``view=``, a :class:`GeoView`): in a 3D world
(plumes and clouds with heights) every raised layer is drawn where the line of sight from
the geostationary satellite through it meets the ground, as a GEO L1 image on its
fixed grid shows it: displaced *away* from the satellite's sub-satellite point by its
parallax, exact on the sphere (:meth:`dyntarget.synth.dynamic.World.render_look` with
the satellite :data:`GEO_ALTITUDE_M` up, :mod:`dyntarget.parallax`). Synthetic strips
carry no geolocation, so the view is stated: :class:`GeoView` places the strip's centre at
a latitude and a longitude from the GEO's sub-satellite longitude (default
:data:`DEFAULT_VIEW`: 35 deg N under the GEO's own longitude; the GEO is then due south,
view zenith 40.6 deg, and a 10 km top appears 8.6 km north of its ground point). Not
modelled: the GEO pixel footprint's stretch with the view angle (cells stay square on the
ground), the Earth's rotation, refraction. Without ``view`` (the default, what ``fly
--geo`` uses) and for a flat world the images are rendered from straight above, byte for
byte as before.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass, replace

import numpy as np

from dyntarget import parallax
from dyntarget.errors import InvalidParameterError
from dyntarget.scene import block_mean
from dyntarget.synth.dynamic import World as MovingWorld
from dyntarget.synth.dynamic import WorldSpec
from dyntarget.synth.strip import resampled_spec
from dyntarget.synth.volcano import ASH_PLUME, CLOUD, STEAM

MARGIN_M = 8_000.0
"""GEO coverage beyond the strip on every side, metres (context for the motion)."""
SUBSAMPLE = 8
"""Render pixels per GEO cell side."""
MAX_RENDER_ROWS = 8192
"""Most render rows in one call (a long strip's GEO grid is rendered band by band)."""
GEO_ALTITUDE_M = 35_786_000.0
"""Altitude of a geostationary satellite above the sphere, metres (42,164 km from the
centre less the mean radius, rounded as usually quoted)."""


@dataclass(frozen=True)
class GeoView:
    """Where a synthetic strip lies under a geostationary satellite (its view geometry).

    The strip's centre is placed at ``lat_deg`` and ``dlon_deg`` east of the GEO's
    sub-satellite longitude (on the equator). On the sphere the ground (arc) distance from
    the sub-satellite point is ``R * g`` with ``cos g = cos(lat) cos(dlon)``, the view
    zenith angle is :func:`dyntarget.parallax.view_zenith` at that distance and the
    azimuth of the line of sight towards the GEO (clockwise from north) that of the great
    circle to the sub-satellite point, ``atan2(sin(-dlon), -sin(lat) cos(dlon))``. The
    strip's grid is taken north up (row 0 north, columns east).

    Parameters
    ----------
    lat_deg : float
        Latitude of the strip's centre, degrees (``|lat| < 80``).
    dlon_deg : float
        Longitude of the strip's centre east of the sub-satellite longitude, degrees
        (``|dlon| < 80``; together with ``lat`` the GEO above the horizon by 10 deg at
        least).

    Examples
    --------
    The default, 35 deg N under the GEO's longitude: the GEO is due south.

    >>> v = GeoView()
    >>> round(v.zenith_deg, 2), v.azimuth_deg, round(v.distance_m / 1e3, 1)
    (40.65, 180.0, 3891.8)
    >>> round(GeoView(0.0, 0.0).zenith_deg, 6)  # under the satellite
    0.0
    """

    lat_deg: float = 35.0
    dlon_deg: float = 0.0

    def __post_init__(self) -> None:
        for name in ("lat_deg", "dlon_deg"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and abs(v) < 80.0):
                raise InvalidParameterError(
                    f"GeoView {name}: expected degrees in (-80, 80), got {v!r}"
                )
        if not self.zenith_deg <= 80.0:
            raise InvalidParameterError(
                f"GeoView: the GEO is {90 - self.zenith_deg:.1f} deg above the horizon "
                f"at lat {self.lat_deg:g}, dlon {self.dlon_deg:g} (expected >= 10 deg)"
            )

    @property
    def central_angle(self) -> float:
        """Angle at the Earth's centre between the strip and the sub-satellite point, rad."""
        lat, dlon = math.radians(self.lat_deg), math.radians(self.dlon_deg)
        return math.acos(max(-1.0, min(1.0, math.cos(lat) * math.cos(dlon))))

    @property
    def distance_m(self) -> float:
        """Ground (arc) distance from the sub-satellite point to the strip, metres."""
        return parallax.EARTH_RADIUS_M * self.central_angle

    @property
    def zenith_deg(self) -> float:
        """View zenith angle of the GEO at the strip, degrees."""
        z = parallax.view_zenith(GEO_ALTITUDE_M, self.distance_m)
        return math.degrees(float(z)) if math.isfinite(float(z)) else 90.0

    @property
    def azimuth_deg(self) -> float:
        """Azimuth of the line of sight towards the GEO at the strip, degrees clockwise
        from north, in ``[0, 360)`` (0 where the GEO is overhead)."""
        lat, dlon = math.radians(self.lat_deg), math.radians(self.dlon_deg)
        if self.central_angle == 0.0:
            return 0.0
        az = math.degrees(math.atan2(math.sin(-dlon), -math.sin(lat) * math.cos(dlon)))
        return az % 360.0 + 0.0

    def nadir_px(self, centre_px: tuple[float, float], gsd: float) -> tuple[float, float]:
        """The sub-satellite point on a north-up grid of ``gsd`` m pixels, ``(x, y)`` px.

        ``distance_m`` from ``centre_px`` along the azimuth (x east, y south).

        Parameters
        ----------
        centre_px : tuple of float
            The strip's centre on the grid, pixels.
        gsd : float
            The grid's pixel size, metres.

        Returns
        -------
        tuple of float
            ``(x, y)`` pixels.

        Examples
        --------
        >>> x, y = GeoView().nadir_px((0.0, 0.0), 1000.0)
        >>> round(x, 6) + 0.0, round(y, 1)  # 3,891.8 km south
        (0.0, 3891.8)
        """
        a = math.radians(self.azimuth_deg)
        d = self.distance_m / gsd
        return centre_px[0] + d * math.sin(a), centre_px[1] - d * math.cos(a)


DEFAULT_VIEW = GeoView()
"""The stated default view of a synthetic strip: 35 deg N under the GEO's longitude."""


class GeoStream:
    """The GEO images of a synthetic strip's world (see the module docstring).

    Parameters
    ----------
    spec : WorldSpec
        The strip's world.
    window : tuple of int
        ``(col0, row0, width, height)`` of the strip on the world's grid.
    gsd_m : float
        GEO cell size, m.
    noise : float
        Std of the GEO brightness noise, reflectance.
    view : GeoView or None
        The GEO's view of the strip: raised plumes and clouds are drawn displaced by
        their parallax (see the module docstring; e.g. :data:`DEFAULT_VIEW`). ``None``
        (default): rendered from straight above, as before; a flat world is rendered
        that way whatever the view.

    Examples
    --------
    >>> from dyntarget.synth.strip import strip_spec
    >>> spec, window = strip_spec(0, width=64, length=256, plumes=2, wind_mps=5.0)
    >>> s = GeoStream(spec, window, 1000.0, 0.0)
    >>> s.image(0.0).shape == (4, *s.cells), s.m
    (True, 8)
    """

    def __init__(
        self,
        spec: WorldSpec,
        window: tuple[int, int, int, int],
        gsd_m: float,
        noise: float,
        *,
        view: GeoView | None = None,
    ) -> None:
        self.spec, self.window, self.gsd_m, self.noise = spec, window, gsd_m, noise
        if view is not None and not isinstance(view, GeoView):
            raise InvalidParameterError(f"view: expected a GeoView or None, got {view!r:.60}")
        self.view = view
        g = gsd_m / SUBSAMPLE
        g = max(g, spec.gsd)
        self.m = max(1, round(gsd_m / g))  # render px per GEO cell
        g = gsd_m / self.m
        scale = spec.gsd / g
        self.render_gsd = g
        coarse = resampled_spec(spec, g, lambda c: c * scale, noise_sigma=0.0)
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
        c0, r0, w, h = window
        G = gsd_m
        x0, x1 = c0 * spec.gsd - MARGIN_M, (c0 + w) * spec.gsd + MARGIN_M
        y0, y1 = r0 * spec.gsd - MARGIN_M, (r0 + h) * spec.gsd + MARGIN_M
        self.cell0 = (math.floor(x0 / G), math.floor(y0 / G))  # GEO cell of the grid's corner
        self.cells = (math.ceil(y1 / G) - self.cell0[1], math.ceil(x1 / G) - self.cell0[0])
        self._images: dict[float, np.ndarray] = {}
        self._nadir: tuple[float, float] | None = None
        if view is not None and spec.is_3d:
            self._nadir = self._nadir_of(view)

    def seen_from(self, view: GeoView | None) -> GeoStream:
        """The same imager over the same world seen from ``view`` (rendered worlds shared).

        Building a stream renders the world's noise tiles (seconds); this copy shares
        them, and the clear-sky background, with ``self``, and starts its own images.

        Parameters
        ----------
        view : GeoView or None
            The view (``None``: from straight above).

        Returns
        -------
        GeoStream

        Examples
        --------
        >>> from dyntarget.synth.strip import strip_spec
        >>> spec, window = strip_spec(0, width=64, length=256, plumes=2, wind_mps=5.0)
        >>> s = GeoStream(spec, window, 1000.0, 0.0)
        >>> south = s.seen_from(GeoView(-35.0, 0.0))
        >>> south.view.azimuth_deg, south.coarse is s.coarse, s.view is None
        (0.0, True, True)
        """
        if view is not None and not isinstance(view, GeoView):
            raise InvalidParameterError(f"view: expected a GeoView or None, got {view!r:.60}")
        out = copy.copy(self)
        out.view, out._images, out._nadir = view, {}, None
        if view is not None and self.spec.is_3d:
            out._nadir = self._nadir_of(view)
        return out

    def _nadir_of(self, view: GeoView) -> tuple[float, float]:
        """The sub-satellite point on the render grid, placed from the strip's centre."""
        c0, r0, w, h = self.window
        scale = self.spec.gsd / self.render_gsd
        return view.nadir_px(((c0 + w / 2.0) * scale, (r0 + h / 2.0) * scale), self.render_gsd)

    @property
    def strip_gsd(self) -> float:
        """The strip's high-resolution pixel size, m."""
        return self.spec.gsd

    @property
    def members(self) -> np.ndarray:
        """``(3, bands)`` end-member spectra of the world: meteorological cloud, ash, steam."""
        return np.array([CLOUD, ASH_PLUME, STEAM], np.float64)

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

    def _render(self, world: MovingWorld, t: float, *, oblique: bool = False) -> np.ndarray:
        m = self.m
        nrow, ncol = self.cells
        cx, cy = self.cell0
        out: np.ndarray | None = None
        step = max(1, MAX_RENDER_ROWS // m)
        for a in range(0, nrow, step):
            b = min(nrow, a + step)
            win = (cx * m, (cy + a) * m, ncol * m, (b - a) * m)
            if oblique and self._nadir is not None:
                f = world.render_look(
                    t, win, nadir_px=self._nadir, altitude_m=GEO_ALTITUDE_M, noise=False
                )
            else:
                f = world.render(t, win, noise=False)
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
        out = self._render(self.coarse, t, oblique=True)
        if self.noise > 0:
            rng = np.random.default_rng([self.spec.seed, 0x6E0, round(t * 1000) & 0xFFFFFFFF])
            out += rng.normal(0.0, self.noise, out.shape).astype(np.float32)
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
        s = self.spec
        return (self.cell0[1] + np.asarray(gy) + 0.5) * self.gsd_m / s.gsd - (self.window[1])

    def strip_cols(self) -> tuple[int, int]:
        """GEO columns overlapping the strip.

        Returns
        -------
        tuple of int
            ``(first, last + 1)``.
        """
        s, G = self.spec, self.gsd_m
        c0, _, w, _ = self.window
        a = math.floor(c0 * s.gsd / G) - self.cell0[0]
        b = math.ceil((c0 + w) * s.gsd / G) - self.cell0[0]
        return a, b
