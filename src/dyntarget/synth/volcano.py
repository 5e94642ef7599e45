"""Procedural volcanic scenes: terrain, a wind-bent plume, clouds, haze, noise.

The model and the origin of every number are documented in
``docs/synthetic-scenes.md``. In short, per scene:

1. terrain elevation from fractal noise plus a volcanic cone; land cover
   (water, basaltic lava, ash field, vegetation, bare soil) from thresholded
   noise fields, each class with its own 4-band reflectance and texture;
   hillshading from the elevation and a sampled sun position;
2. a plume from a vent: a straight or circular-arc centreline along the wind
   (arc = wind shear), Gaussian cross-section whose width grows linearly
   downwind, optical depth falling with distance, multiplicative multi-octave
   "puff" noise and ragged edges; composition from ash-laden (grey-brown) near
   the vent to steam (white, lower NIR than cloud) downwind;
3. cumulus and cirrus clouds with shadows, haze, sensor noise, saturation;
4. the label: plume optical depth above a per-scene threshold, like a hand
   label that stops where the plume becomes too thin to see.

All parameters are drawn per scene from documented ranges by
:func:`sample_params`; the same seed and index give the same bytes.
"""

from __future__ import annotations

import json
import os
from dataclasses import asdict, dataclass

import cv2
import numpy as np
from affine import Affine

from dyntarget.errors import InvalidParameterError
from dyntarget.scene import Scene
from dyntarget.synth.noise import fractal_noise

# Broad-band reflectances (R, G, B, NIR), approximate band averages of library
# spectra (USGS splib07, ECOSTRESS) over SkySat-like bands; see the docs.
SURFACE_SPECTRA: dict[str, tuple[float, float, float, float]] = {
    "water": (0.030, 0.045, 0.060, 0.015),
    "basalt": (0.060, 0.060, 0.055, 0.070),
    "ash": (0.120, 0.110, 0.100, 0.150),
    "vegetation": (0.050, 0.090, 0.040, 0.450),
    "soil": (0.250, 0.190, 0.130, 0.320),
}
STEAM = (0.74, 0.76, 0.80, 0.58)  # small droplets/sulfate: reflectance falls toward NIR
ASH_PLUME = (0.30, 0.26, 0.22, 0.27)  # grey-brown volcanic ash
CLOUD = (0.80, 0.81, 0.83, 0.79)  # large droplets: nearly flat spectrum
CIRRUS = (0.78, 0.80, 0.83, 0.74)
HAZE = (0.10, 0.12, 0.16, 0.06)  # blue-heavy path radiance

UTM_5N = "EPSG:32605"  # Kilauea, Hawaii
ORIGIN_EASTING, ORIGIN_NORTHING = 240_000.0, 2_160_000.0


@dataclass(frozen=True)
class SceneParams:
    """Parameters of one synthetic scene (lengths in pixels, angles in radians).

    Parameters
    ----------
    size : int
        Side of the square scene, pixels.
    gsd : float
        Ground sample distance, metres per pixel.
    water_fraction : float
        Share of the scene that is water (the lowest terrain).
    lava_fraction : float
        Share of the land that is lava (basalt or ash field).
    vegetation_fraction : float
        Share of the remaining land that is vegetated (the rest is bare soil).
    sun_azimuth, sun_elevation : float
        Sun position for the hillshade, radians.
    vent_x, vent_y : float
        Vent position, pixels.
    wind_direction : float
        Direction the plume leaves the vent, radians from the image x axis.
    wind_speed : float
        Wind speed, m/s (sets the plume's length and spread).
    curvature : float
        Curvature of the centreline, 1/pixels (0: straight; the sign turns it).
    source_width : float
        Plume sigma at the vent, pixels.
    spread : float
        Growth of the sigma per pixel downwind.
    decay_length : float
        E-folding distance of the optical depth along the plume, pixels.
    optical_depth : float
        Plume optical depth at the source.
    ash_fraction : float
        Share of ash (against steam) at the vent.
    label_optical_depth : float
        Optical depth above which a pixel is labelled plume.
    cloud_cover : float
        Share of the scene under cumulus (0: none).
    cloud_optical_depth : float
        Scale of the cumulus optical depth.
    cirrus_optical_depth : float
        Peak cirrus optical depth (0: none).
    cloud_shadow_dx, cloud_shadow_dy : float
        Offset of the cloud shadows, pixels.
    haze : float
        Strength of the haze (blend weight of the haze colour).
    noise_sigma : float
        Std of the Gaussian sensor noise, reflectance units.
    """

    size: int
    gsd: float
    water_fraction: float
    lava_fraction: float
    vegetation_fraction: float
    sun_azimuth: float
    sun_elevation: float
    vent_x: float
    vent_y: float
    wind_direction: float
    wind_speed: float
    curvature: float
    source_width: float
    spread: float
    decay_length: float
    optical_depth: float
    ash_fraction: float
    label_optical_depth: float
    cloud_cover: float
    cloud_optical_depth: float
    cirrus_optical_depth: float
    cloud_shadow_dx: float
    cloud_shadow_dy: float
    haze: float
    noise_sigma: float

    def to_json(self) -> str:
        """Canonical JSON of the parameters (sorted keys).

        Returns
        -------
        str
            The JSON text.
        """
        return json.dumps(asdict(self), sort_keys=True)


def sample_params(rng: np.random.Generator, *, size: int, gsd: float) -> SceneParams:
    """Draw one scene's parameters from the documented ranges.

    Parameters
    ----------
    rng : numpy.random.Generator
        Source of the draws.
    size : int
        Side of the scene, pixels.
    gsd : float
        Ground sample distance, metres per pixel.

    Returns
    -------
    SceneParams
        The parameters.
    """
    u = rng.uniform
    wind_speed = u(2.0, 15.0)  # m/s, near-surface to low-troposphere winds
    curved = u() < 0.35
    turn = u(np.radians(35), np.radians(110)) * rng.choice([-1.0, 1.0])
    decay = u(0.5, 1.4) * size * (wind_speed / 6.0) ** 0.3
    shadow_len = u(0.02, 0.07) * size
    shadow_dir = u(0, 2 * np.pi)
    return SceneParams(
        size=size,
        gsd=gsd,
        water_fraction=u(0.0, 0.3) if u() < 0.6 else 0.0,
        lava_fraction=u(0.1, 0.4),
        vegetation_fraction=u(0.2, 0.7),
        sun_azimuth=u(0, 2 * np.pi),
        sun_elevation=u(np.radians(25), np.radians(70)),
        vent_x=u(0.2, 0.8) * size,
        vent_y=u(0.2, 0.8) * size,
        wind_direction=u(0, 2 * np.pi),
        wind_speed=wind_speed,
        curvature=(turn / decay) if curved else 0.0,
        source_width=u(0.015, 0.035) * size,
        spread=float(np.clip(u(0.10, 0.28) * np.sqrt(6.0 / wind_speed), 0.05, 0.4)),
        decay_length=decay,
        optical_depth=u(2.0, 5.0),
        ash_fraction=u(0.0, 1.0),
        label_optical_depth=u(0.25, 0.5),
        cloud_cover=u(0.03, 0.3) if u() < 0.7 else 0.0,
        cloud_optical_depth=u(3.0, 8.0),
        cirrus_optical_depth=u(0.1, 0.5) if u() < 0.4 else 0.0,
        cloud_shadow_dx=shadow_len * np.cos(shadow_dir),
        cloud_shadow_dy=shadow_len * np.sin(shadow_dir),
        haze=u(0.0, 0.15),
        noise_sigma=u(0.002, 0.01),
    )


def _shift(field: np.ndarray, dx: float, dy: float) -> np.ndarray:
    """Translate a field by (dx, dy) pixels, zeros coming in from outside."""
    m = np.array([[1, 0, dx], [0, 1, dy]], np.float32)
    h, w = field.shape
    return cv2.warpAffine(field, m, (w, h), flags=cv2.INTER_LINEAR, borderValue=0.0)


def _spectra(weights: dict[str, np.ndarray], spectra: dict[str, tuple]) -> np.ndarray:
    out = np.zeros((4, *next(iter(weights.values())).shape), np.float32)
    for name, wgt in weights.items():
        out += np.asarray(spectra[name], np.float32)[:, None, None] * wgt
    return out


def plume_coordinates(
    p: SceneParams, xx: np.ndarray, yy: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Along-plume distance ``s`` and signed cross distance ``d`` of every pixel.

    Straight plume: projections on the wind direction and its normal. Curved
    plume: the centreline is a circular arc of curvature ``p.curvature`` that
    leaves the vent along the wind; ``s`` is arc length, ``d`` radial offset.

    Parameters
    ----------
    p : SceneParams
        The vent, wind direction and curvature.
    xx, yy : numpy.ndarray
        Pixel column and row coordinates.

    Returns
    -------
    s : numpy.ndarray
        Distance along the plume from the vent, pixels (negative upwind).
    d : numpy.ndarray
        Signed distance across the centreline, pixels.
    """
    tx, ty = np.cos(p.wind_direction), np.sin(p.wind_direction)
    nx, ny = -ty, tx
    rx, ry = xx - p.vent_x, yy - p.vent_y
    if p.curvature == 0.0:
        return rx * tx + ry * ty, rx * nx + ry * ny
    sign = np.sign(p.curvature)
    radius = 1.0 / abs(p.curvature)
    cx, cy = p.vent_x + sign * radius * nx, p.vent_y + sign * radius * ny
    a0x, a0y = p.vent_x - cx, p.vent_y - cy
    ax, ay = xx - cx, yy - cy
    ang = np.arctan2(a0x * ay - a0y * ax, a0x * ax + a0y * ay) * sign
    return radius * ang, sign * (radius - np.hypot(ax, ay))


def render(
    params: SceneParams, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Render a scene; returns ``(image (4,H,W) float32, label bool, plume optical depth)``.

    Parameters
    ----------
    params : SceneParams
        The scene's parameters.
    rng : numpy.random.Generator
        Source of the noise fields.

    Returns
    -------
    image : numpy.ndarray
        ``(4, size, size)`` float32 reflectance, clipped to 0..1.
    label : numpy.ndarray
        Boolean ``(size, size)`` plume label.
    tau : numpy.ndarray
        ``(size, size)`` float32 plume optical depth.
    """
    p = params
    n = p.size
    shape = (n, n)
    yy, xx = np.mgrid[0:n, 0:n].astype(np.float32)
    r_vent = np.hypot(xx - p.vent_x, yy - p.vent_y) / n

    # 1. terrain and land cover
    elev = fractal_noise(rng, shape, beta=3.6) + 2.5 * np.exp(-r_vent / 0.2)
    water = (
        elev < np.quantile(elev, p.water_fraction)
        if p.water_fraction > 0
        else np.zeros(shape, bool)
    )
    lava_score = fractal_noise(rng, shape, beta=2.6) + 2.0 * np.exp(-r_vent / 0.15)
    land = ~water
    lava = land & (lava_score > np.quantile(lava_score[land], 1 - p.lava_fraction))
    basalt_vs_ash = fractal_noise(rng, shape, beta=2.4) > 0.0
    veg_score = fractal_noise(rng, shape, beta=2.6)
    rest = land & ~lava
    veg_thr = np.quantile(veg_score[rest], 1 - p.vegetation_fraction) if rest.any() else 0.0
    vegetation = rest & (veg_score > veg_thr)
    classes = {
        "water": water,
        "basalt": lava & basalt_vs_ash,
        "ash": lava & ~basalt_vs_ash,
        "vegetation": vegetation,
        "soil": rest & ~vegetation,
    }
    weights = {k: cv2.GaussianBlur(v.astype(np.float32), (0, 0), 1.0) for k, v in classes.items()}
    surface = _spectra(weights, SURFACE_SPECTRA)
    texture = 1.0 + 0.12 * fractal_noise(rng, shape, beta=1.6)
    surface *= texture[None]

    gy, gx = np.gradient(elev * (0.015 * n))
    sx = np.cos(p.sun_elevation) * np.sin(p.sun_azimuth)
    sy = -np.cos(p.sun_elevation) * np.cos(p.sun_azimuth)
    sz = np.sin(p.sun_elevation)
    shade = (-gx * sx - gy * sy + sz) / np.sqrt(1.0 + gx**2 + gy**2) / sz
    shade = np.where(water, 1.0, np.clip(shade, 0.15, 1.6)).astype(np.float32)
    surface *= shade[None]

    # 2. plume optical depth
    s, d = plume_coordinates(p, xx, yy)
    sd = np.maximum(s, 0.0)
    sigma = p.source_width + sd * p.spread
    d_ragged = d + 0.35 * sigma * fractal_noise(rng, shape, beta=2.2)
    core = p.optical_depth * (p.source_width / sigma) ** 0.6 * np.exp(-sd / p.decay_length)
    upwind = np.exp(-0.5 * (np.minimum(s, 0.0) / p.source_width) ** 2)
    puffs = np.exp(0.55 * fractal_noise(rng, shape, beta=2.0) - 0.15)
    tau = (core * upwind * np.exp(-0.5 * (d_ragged / sigma) ** 2) * puffs).astype(np.float32)
    ash_map = p.ash_fraction * np.exp(-sd / (1.5 * p.decay_length))
    plume_colour = np.asarray(ASH_PLUME, np.float32)[:, None, None] * ash_map[None] + np.asarray(
        STEAM, np.float32
    )[:, None, None] * (1.0 - ash_map[None])

    # 3. clouds (cumulus, cirrus), shadows
    tau_cloud = np.zeros(shape, np.float32)
    if p.cloud_cover > 0:
        cn = fractal_noise(rng, shape, beta=2.8)
        thr = np.quantile(cn, 1 - p.cloud_cover)
        tau_cloud = (p.cloud_optical_depth * np.maximum(cn - thr, 0.0)).astype(np.float32)
    tau_cirrus = np.zeros(shape, np.float32)
    if p.cirrus_optical_depth > 0:
        ci = fractal_noise(rng, shape, beta=2.4, stretch=6.0, angle=p.wind_direction + 0.5)
        patches = np.clip(fractal_noise(rng, shape, beta=3.5) + 0.3, 0.0, 1.0)
        tau_cirrus = (p.cirrus_optical_depth * np.clip(ci, 0.0, 2.0) / 2.0 * patches).astype(
            np.float32
        )
    shadow_tau = _shift(tau_cloud, p.cloud_shadow_dx, p.cloud_shadow_dy) + 0.5 * _shift(
        tau, 0.4 * p.cloud_shadow_dx, 0.4 * p.cloud_shadow_dy
    )
    surface *= np.exp(-0.6 * shadow_tau)[None]

    # composite: surface -> plume -> cloud -> cirrus -> haze
    image = surface
    for layer_tau, colour in ((tau, plume_colour), (tau_cloud, CLOUD), (tau_cirrus, CIRRUS)):
        trans = np.exp(-layer_tau)[None]
        col = (
            colour
            if isinstance(colour, np.ndarray)
            else np.asarray(colour, np.float32)[:, None, None]
        )
        image = image * trans + col * (1.0 - trans)
    haze_field = p.haze * (0.6 + 0.4 * np.tanh(fractal_noise(rng, shape, beta=3.5)))
    image = (
        image * (1.0 - haze_field[None])
        + np.asarray(HAZE, np.float32)[:, None, None] * haze_field[None]
    )
    image = image + rng.normal(0.0, p.noise_sigma, size=image.shape).astype(np.float32)
    image = np.clip(image, 0.0, 1.0).astype(np.float32)

    label = tau > p.label_optical_depth
    return image, label, tau


def generate_scene(
    seed: int, index: int, *, size: int = 512, gsd: float = 8.0
) -> tuple[Scene, SceneParams]:
    """Generate scene ``index`` of the set with ``seed``.

    Scene ``i`` depends only on ``(seed, i)``, so a set can be generated in any
    order or in part. Scenes are georeferenced in UTM zone 5N near Kilauea,
    each on its own tile, so GeoJSON exports are real coordinates.

    Parameters
    ----------
    seed : int
        The set's seed (>= 0).
    index : int
        The scene's index in the set (>= 0).
    size : int
        Side of the square scene, pixels (at least 16).
    gsd : float
        Ground sample distance, metres per pixel.

    Returns
    -------
    scene : dyntarget.scene.Scene
        The labelled, georeferenced scene, id ``synth-SSSS-IIII``.
    params : SceneParams
        The parameters drawn for it.

    Examples
    --------
    >>> scene, params = generate_scene(0, 0, size=64)
    >>> scene.image.shape, scene.label.dtype, scene.id
    ((4, 64, 64), dtype('bool'), 'synth-0000-0000')
    """
    _check_positive_int("size", size, minimum=16)
    _check_positive_int("seed", seed, minimum=0)
    _check_positive_int("index", index, minimum=0)
    check_memory("size", size, bytes_per_pixel=SYNTH_BYTES_PER_PIXEL)
    if not np.isfinite(gsd) or gsd <= 0:
        raise InvalidParameterError(f"gsd: expected a positive number of metres, got {gsd!r}")
    rng = np.random.default_rng([int(seed), int(index)])
    params = sample_params(rng, size=size, gsd=gsd)
    image, label, _ = render(params, rng)
    tile = size * gsd
    transform = Affine.translation(
        ORIGIN_EASTING + (index % 20) * tile * 1.5, ORIGIN_NORTHING - (index // 20) * tile * 1.5
    ) @ Affine.scale(gsd, -gsd)
    scene = Scene(
        image,
        label=label,
        gsd=gsd,
        crs=UTM_5N,
        transform=transform,
        id=f"synth-{seed:04d}-{index:04d}",
    )
    return scene, params


def generate_scenes(n: int, *, size: int = 512, seed: int = 0, gsd: float = 8.0):
    """Yield ``(scene, params)`` for scenes ``0`` to ``n - 1`` of the set with ``seed``.

    Parameters
    ----------
    n : int
        Number of scenes (at least 1).
    size : int
        Side of each scene, pixels.
    seed : int
        The set's seed.
    gsd : float
        Ground sample distance, metres per pixel.

    Yields
    ------
    scene : dyntarget.scene.Scene
        Scene ``i``.
    params : SceneParams
        Its parameters.
    """
    _check_positive_int("scenes", n, minimum=1)
    for i in range(n):
        yield generate_scene(seed, i, size=size, gsd=gsd)


SYNTH_BYTES_PER_PIXEL = 320
"""Peak memory of :func:`generate_scene` per pixel (measured with tracemalloc: about
295 B/px at 256 and 512 px, the float64 optical-depth and noise fields dominate)."""


def available_memory() -> int:
    """Bytes of memory available now (``MemAvailable`` on Linux, else physical memory).

    Returns
    -------
    int
        Bytes (a huge number when unknown, so that nothing is refused).
    """
    try:
        with open("/proc/meminfo", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, AttributeError):
        return 1 << 62  # unknown: do not refuse


def check_memory(argument: str, size: int, *, bytes_per_pixel: int) -> None:
    """Refuse a ``size`` x ``size`` px job whose estimated peak memory exceeds what is available.

    Parameters
    ----------
    argument : str
        The argument's name, for the error message.
    size : int
        Side of the job, pixels.
    bytes_per_pixel : int
        Estimated peak memory per pixel, bytes.

    Raises
    ------
    dyntarget.errors.InvalidParameterError
        When ``size ** 2 * bytes_per_pixel`` exceeds :func:`available_memory`.

    Examples
    --------
    >>> check_memory("size", 64, bytes_per_pixel=320)  # 1.3 MB: fine
    >>> check_memory("size", 10**7, bytes_per_pixel=320)  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    dyntarget.errors.InvalidParameterError: size: 10000000 x 10000000 px needs about 32000000.0 GB of memory...
    """
    need = int(size) ** 2 * bytes_per_pixel
    have = available_memory()
    if need > have:
        raise InvalidParameterError(
            f"{argument}: {size} x {size} px needs about {need / 1e9:.1f} GB of memory "
            f"(estimate: {bytes_per_pixel} bytes per pixel), {have / 1e9:.1f} GB are available; "
            "choose a smaller size"
        )


def _check_positive_int(name: str, value: object, *, minimum: int) -> None:
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < minimum:
        raise InvalidParameterError(f"{name}: expected an integer >= {minimum}, got {value!r}")
