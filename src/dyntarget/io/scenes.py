"""Read and write scenes as GeoTIFFs (rasterio), with GeoJSON or raster labels.

On disk a scene ``<id>`` is

* ``<id>.tif`` — a 4-band GeoTIFF in band order R, G, B, NIR, float reflectance
  or integer digital numbers (scaled on read, default ``1/10000``);
* ``<id>_mask.tif`` — optional single-band label, non-zero = plume; or
* ``<id>.geojson`` — optional label as polygons, in the image's CRS when the
  image is georeferenced (or in the CRS named by a legacy ``"crs"`` member),
  in pixel coordinates ``(column, row)`` when it is not.

A *scene directory* is a folder of such files.
"""

from __future__ import annotations

import contextlib
import json
import os
import sys
import warnings
from pathlib import Path

import numpy as np
import rasterio
import rasterio.errors
import rasterio.features
from affine import Affine
from rasterio.crs import CRS

from dyntarget.errors import DataFileError, InvalidParameterError, InvalidSceneError
from dyntarget.io.atomic import atomic_path
from dyntarget.scene import LABEL_FRACTION, Scene, block_mean, check_factor, check_label

DEFAULT_SCALE = 1e-4
"""Reflectance per digital number for integer images (Sentinel-2/PlanetScope convention)."""

GSD_TAG = "DYNTARGET_GSD"

MAX_PIXELS = 16384 * 16384
"""Largest image read whole (4 bands x float32 = 4 GiB); larger ones are refused with a message."""
MAX_STRIP_PIXELS = 65536 * 65536
"""Largest image read at all, even in strips onto a WFOV grid (``factor > 1``): the read
takes time in proportion to the pixels the header claims, so larger ones are refused
before reading, with this limit stated (a header claiming 200000 x 200000 px in a small,
sparse file would otherwise run for many minutes)."""
UINT8_SCALE = 1 / 255
"""Reflectance per digital number for 8-bit images (0..255 -> 0..1)."""
REFLECTANCE_RANGE = (-0.5, 2.0)
"""Values outside this range cannot be reflectance (e.g. digital numbers stored as float)."""
MASK_SUFFIX = "_mask"
MAX_GEOJSON_BYTES = 256 * 1024 * 1024
"""Largest GeoJSON label read (256 MiB)."""


@contextlib.contextmanager
def _quiet_gdal_log_errors():
    """Silence rasterio's GDAL log handler failing on non-UTF-8 messages from a corrupt file.

    rasterio decodes GDAL's error text as UTF-8 inside a C callback; garbage bytes
    make that raise an "unraisable" exception, which Python prints as a traceback
    although the read itself then fails cleanly (and we report it). Only that
    case is swallowed; anything else goes to the previous hook.
    """
    previous = sys.unraisablehook

    def hook(args):
        if isinstance(args.exc_value, UnicodeDecodeError) and "log_error" in repr(args.object):
            return
        previous(args)

    sys.unraisablehook = hook
    try:
        yield
    finally:
        sys.unraisablehook = previous


def _open(path: Path):
    from dyntarget.io.safeopen import check_regular

    check_regular(path)  # a FIFO or a device would block GDAL or be read forever
    try:
        with warnings.catch_warnings(), _quiet_gdal_log_errors():
            warnings.simplefilter("ignore", rasterio.errors.NotGeoreferencedWarning)
            return rasterio.open(path)
    except (rasterio.errors.RasterioIOError, rasterio.errors.RasterioError) as exc:
        raise DataFileError(f"{path}: not a readable raster ({_first_line(exc)})") from None


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return text[0] if text else type(exc).__name__


def _read_all(src, path: Path) -> np.ndarray:
    try:
        with warnings.catch_warnings(), _quiet_gdal_log_errors():
            warnings.simplefilter("ignore", rasterio.errors.NotGeoreferencedWarning)
            return src.read()
    except (rasterio.errors.RasterioIOError, rasterio.errors.RasterioError) as exc:
        raise DataFileError(f"{path}: corrupt or truncated raster ({_first_line(exc)})") from None


def _georef(src) -> tuple[str | None, Affine | None]:
    crs = src.crs.to_string() if src.crs else None
    transform = src.transform
    if crs is None and transform == Affine.identity():
        return None, None
    return crs, transform


def scale_to_reflectance(data: np.ndarray, *, scale: float | None, path: Path | str) -> np.ndarray:
    """Convert raw raster values to float32 reflectance.

    Integer data are multiplied by ``scale``; by default :data:`UINT8_SCALE`
    (1/255) for 8-bit data and :data:`DEFAULT_SCALE` (1/10000) for wider
    integers. Floating data are taken as reflectance unless a ``scale`` is given.

    Parameters
    ----------
    data : numpy.ndarray
        Raw raster values, integer or floating point.
    scale : float or None
        Reflectance per digital number (positive), or ``None`` for the defaults.
    path : pathlib.Path or str
        Where the data came from, for error messages.

    Returns
    -------
    numpy.ndarray
        Float32 reflectance, same shape.

    Examples
    --------
    >>> scale_to_reflectance(np.array([[[255]]], np.uint8), scale=None, path="x").item()
    1.0
    >>> round(scale_to_reflectance(np.array([[[2500]]], np.uint16), scale=None, path="x").item(), 6)
    0.25
    """
    if scale is not None and (not np.isfinite(scale) or scale <= 0):
        raise InvalidParameterError(f"scale: expected a positive number, got {scale!r}")
    if np.issubdtype(data.dtype, np.integer):
        if scale is None:
            scale = UINT8_SCALE if data.dtype == np.uint8 else DEFAULT_SCALE
        return data.astype(np.float32) * np.float32(scale)
    if np.issubdtype(data.dtype, np.floating):
        out = data.astype(np.float32)
        return out * np.float32(scale) if scale is not None else out
    raise InvalidSceneError(f"{path}: unsupported data type {data.dtype}")


def check_reflectance(
    image: np.ndarray, path: Path | str, invalid: np.ndarray | None = None
) -> None:
    """Refuse images that cannot be reflectance: non-finite, far out of range, or constant.

    Only pixels with data count (``invalid`` marks nodata pixels).

    Parameters
    ----------
    image : numpy.ndarray
        ``(4, H, W)`` reflectance.
    path : pathlib.Path or str
        Where it came from, for error messages.
    invalid : numpy.ndarray or None
        Boolean ``(H, W)``, true on nodata pixels.

    Raises
    ------
    dyntarget.errors.InvalidSceneError
        When no pixel has data, a value is not finite or far outside 0..1
        (:data:`REFLECTANCE_RANGE`), or the image is constant.
    """
    values = image if invalid is None else image[:, ~invalid]
    if values.size == 0:
        raise InvalidSceneError(f"{path}: no valid pixel (everything is nodata)")
    finite = np.isfinite(values)
    if not finite.all():
        raise InvalidSceneError(f"{path}: {int((~finite).sum())} value(s) are NaN or infinite")
    lo, hi = float(values.min()), float(values.max())
    if lo < REFLECTANCE_RANGE[0] or hi > REFLECTANCE_RANGE[1]:
        raise InvalidSceneError(
            f"{path}: values from {lo:g} to {hi:g} are not reflectance (expected about 0..1); "
            "digital numbers stored as float? pass a scale (--scale)"
        )
    if lo == hi:
        raise InvalidSceneError(
            f"{path}: image is constant (every value {lo:g}); a blank or nodata image?"
        )


def _nodata_mask(data: np.ndarray, nodata: float | None) -> np.ndarray | None:
    """``True`` where any band holds the nodata value (or NaN when nodata is NaN); ``None`` if none."""
    if nodata is None:
        return None
    bad = np.isnan(data).any(axis=0) if np.isnan(nodata) else (data == nodata).any(axis=0)
    return bad if bad.any() else None


def _to_reflectance(data: np.ndarray, nodata: float | None, scale: float | None, path: Path):
    """Scale raw values; nodata pixels become 0 and are returned as ``invalid``."""
    invalid = _nodata_mask(data, nodata)
    if invalid is not None:
        data = data.copy()
        data[:, invalid] = 0
    return scale_to_reflectance(data, scale=scale, path=path), invalid


def read_scene(
    path: str | os.PathLike[str],
    *,
    label: str | os.PathLike[str] | None = None,
    scale: float | None = None,
    gsd: float | None = None,
    factor: int = 1,
    auto_label: bool = True,
) -> Scene:
    """Read ``<id>.tif`` (and its label, if one sits beside it) as a :class:`Scene`.

    The file's nodata value marks pixels without data (any band): they become
    ``Scene.valid == False`` and are left out of training, metrics and
    observation.

    Parameters
    ----------
    path : path to a 4-band GeoTIFF (R, G, B, NIR).
    label : explicit label file (``.tif`` mask or ``.geojson``); by default
        ``<id>_mask.tif`` then ``<id>.geojson`` beside the image are tried.
    scale : reflectance per digital number for integer images (default 1e-4).
    gsd : ground sampling distance in metres; by default the ``DYNTARGET_GSD``
        tag, else the pixel size of a projected CRS in metres, else unknown.
    factor : read straight onto the WFOV grid (``Scene.to_wfov(factor)``),
        in strips of rows, so an image too large to hold whole is never held.
    auto_label : look for ``<id>_mask.tif`` / ``<id>.geojson`` when ``label`` is not given.

    Returns
    -------
    Scene
        The scene, id ``<id>``, on the WFOV grid of ``factor``.

    Examples
    --------
    >>> import tempfile, numpy as np
    >>> d = tempfile.mkdtemp()
    >>> img = np.linspace(0, 0.5, 4 * 8 * 8, dtype=np.float32).reshape(4, 8, 8)
    >>> _ = write_scene(Scene(img, label=np.eye(8, dtype=bool), id="a"), d)
    >>> read_scene(f"{d}/a.tif").label.sum()
    np.int64(8)
    >>> read_scene(f"{d}/a.tif", factor=2).shape
    (4, 4)
    """
    path = Path(path)
    label_path = Path(label) if label is not None else (_find_label(path) if auto_label else None)
    with _open(path) as src:
        if src.count != 4:
            hint = (
                "; one file per band? give the four files in the order R G B NIR "
                "(e.g. red.tif green.tif blue.tif nir.tif --preset landsat8)"
                if src.count == 1
                else "; a multi-band product? pick R, G, B, NIR with --preset or --bands"
                if src.count > 4
                else ""
            )
            raise InvalidSceneError(
                f"{path}: expected 4 bands (R, G, B, NIR), got {src.count} band(s){hint}"
            )
        factor = check_factor(factor, (src.height, src.width))
        out_h, out_w = src.height // factor, src.width // factor
        if src.height * src.width > MAX_STRIP_PIXELS:
            raise InvalidSceneError(
                f"{path}: image is {src.width} x {src.height} px, more than the "
                f"{MAX_STRIP_PIXELS:,} px dyntarget reads at any WFOV factor (65536 x 65536); "
                "crop or tile it"
            )
        if out_h * out_w > MAX_PIXELS:
            hint = (
                "pass a WFOV factor (--factor) to read it in strips"
                if factor == 1
                else "use a larger factor"
            )
            raise InvalidSceneError(
                f"{path}: image is {src.width} x {src.height} px, more than the {MAX_PIXELS:,} px held at once "
                f"at factor {factor}; {hint}, or crop or tile it"
            )
        crs, transform = _georef(src)
        tags = src.tags()
        linear_units = src.crs.linear_units if src.crs and src.crs.is_projected else None
        if factor == 1:
            image, invalid = _to_reflectance(_read_all(src, path), src.nodata, scale, path)
            check_reflectance(image, path, invalid)
            label_array = (
                read_label(label_path, shape=image.shape[1:], crs=crs, transform=transform)
                if label_path
                else None
            )
            scene_gsd = gsd
        else:
            image, label_array, invalid = _read_strips(
                src, path, factor, scale, label_path, crs, transform
            )
            check_reflectance(image, path, invalid)
            transform = None if transform is None else transform @ Affine.scale(factor)
            scene_gsd = None if gsd is None else gsd * factor
    if scene_gsd is None and GSD_TAG in tags:
        scene_gsd = float(tags[GSD_TAG]) * factor
    elif scene_gsd is None and transform is not None and linear_units in ("metre", "meter"):
        scene_gsd = abs(transform.a)
    try:
        return Scene(
            image,
            label=label_array,
            gsd=scene_gsd,
            crs=crs,
            transform=transform,
            id=path.stem,
            valid=None if invalid is None else ~invalid,
        )
    except InvalidSceneError as exc:
        raise InvalidSceneError(f"{path}: {exc}") from None


STRIP_PIXELS = 1 << 24
"""About how many high-resolution pixels one strip of a windowed read holds (x 4 bands)."""


def _read_strips(src, path: Path, factor: int, scale, label_path, crs, transform):
    """Windowed read: strips of rows, each averaged onto the WFOV grid as it arrives.

    The rules are those of :meth:`Scene.to_wfov`: image mean, label where at
    least half the block is plume, valid only where the whole block is.
    """
    from rasterio.windows import Window

    out_h, out_w = src.height // factor, src.width // factor
    rows_per_strip = max(1, STRIP_PIXELS // max(src.width * factor, 1)) * factor
    grid = transform if transform is not None else Affine.identity()
    images, labels, invalids = [], [], []
    for r0 in range(0, out_h * factor, rows_per_strip):
        window = Window(0, r0, out_w * factor, min(rows_per_strip, out_h * factor - r0))
        try:
            with warnings.catch_warnings(), _quiet_gdal_log_errors():
                warnings.simplefilter("ignore", rasterio.errors.NotGeoreferencedWarning)
                data = src.read(window=window)
        except rasterio.errors.RasterioError as exc:
            raise DataFileError(
                f"{path}: corrupt or truncated raster ({_first_line(exc)})"
            ) from None
        strip, invalid = _to_reflectance(data, src.nodata, scale, path)
        images.append(block_mean(strip, factor))
        valid = np.ones(strip.shape[1:], bool) if invalid is None else ~invalid
        invalids.append(block_mean(valid[None].astype(np.float32), factor)[0] < 1.0)
        if label_path is not None:
            lab = _label_window(label_path, window, grid, crs)
            labels.append(block_mean(lab[None].astype(np.float32), factor)[0] >= LABEL_FRACTION)
    invalid = np.concatenate(invalids)
    label = np.concatenate(labels) if label_path is not None else None
    return np.concatenate(images, axis=1), label, (invalid if invalid.any() else None)


def _label_window(label_path: Path, window, grid: Affine, crs: str | None) -> np.ndarray:
    """The label on one window of the image grid (a raster read, or GeoJSON rasterised there)."""
    shape = (int(window.height), int(window.width))
    if label_path.suffix.lower() in (".geojson", ".json"):
        return read_geojson_label(
            label_path,
            shape=shape,
            crs=crs,
            transform=grid @ Affine.translation(window.col_off, window.row_off),
            require_overlap=False,
        )
    with _open(label_path) as lsrc:
        if lsrc.count != 1:
            raise InvalidSceneError(f"{label_path}: a label must have 1 band, got {lsrc.count}")
        lcrs, ltransform = _georef(lsrc)
        if _georef_differs(lcrs, ltransform, lsrc.shape, crs, grid, None):
            data = _read_all(lsrc, label_path)[0]
            return _reproject_label(
                data, lcrs, ltransform, label_path, shape, crs,
                grid @ Affine.translation(window.col_off, window.row_off),
            )  # fmt: skip
        data = lsrc.read(1, window=window, boundless=False)
    if data.shape != shape:
        raise InvalidSceneError(
            f"{label_path}: label of another size than the image (window {shape}, got {data.shape})"
        )
    if np.issubdtype(data.dtype, np.floating) and not np.isfinite(data).all():
        raise InvalidSceneError(f"{label_path}: label holds NaN or infinite values")
    return data != 0


def _find_label(image_path: Path) -> Path | None:
    for candidate in (
        image_path.with_name(image_path.stem + MASK_SUFFIX + ".tif"),
        image_path.with_suffix(".geojson"),
    ):
        if candidate.exists():
            return candidate
    return None


def read_label(
    path: str | os.PathLike[str],
    *,
    shape: tuple[int, int],
    crs: str | None = None,
    transform: Affine | None = None,
) -> np.ndarray:
    """Read a label (single-band raster or GeoJSON polygons) onto an image grid.

    A raster mask georeferenced on another grid than a georeferenced image
    (another CRS, or the same CRS elsewhere or at another resolution) is
    reprojected onto the image grid (nearest neighbour; image pixels the mask
    does not cover are "not plume"); a mask that does not overlap the image is
    refused. When either has no georeference the mask is used pixel for pixel
    and must have the image's shape.

    Parameters
    ----------
    path : str or os.PathLike
        A single-band raster mask (non-zero = plume) or a ``.geojson``/``.json`` file.
    shape : tuple of int
        The image's ``(H, W)``.
    crs : str or None
        The image's CRS.
    transform : affine.Affine or None
        The image's geotransform.

    Returns
    -------
    numpy.ndarray
        Boolean ``(H, W)`` label.
    """
    path = Path(path)
    if path.suffix.lower() in (".geojson", ".json"):
        return read_geojson_label(path, shape=shape, crs=crs, transform=transform)
    with _open(path) as src:
        if src.count != 1:
            raise InvalidSceneError(f"{path}: a label must have 1 band, got {src.count}")
        lcrs, ltransform = _georef(src)
        data = _read_all(src, path)[0]
    if np.issubdtype(data.dtype, np.floating):
        if not np.isfinite(data).all():
            raise InvalidSceneError(f"{path}: label holds NaN or infinite values")
        data = data != 0
    if _georef_differs(lcrs, ltransform, data.shape, crs, transform, shape):
        return _reproject_label(data, lcrs, ltransform, path, shape, crs, transform)
    return check_label(data, shape, name=str(path))


def _georef_differs(
    lcrs: str | None,
    ltransform: Affine | None,
    lshape: tuple[int, int],
    crs: str | None,
    transform: Affine | None,
    shape: tuple[int, int] | None,
) -> bool:
    """Whether a georeferenced mask sits on another grid than a georeferenced image.

    When either has no CRS or no transform, the mask is taken pixel for pixel
    (its shape must then match the image's)."""
    if lcrs is None or ltransform is None or crs is None or transform is None:
        return False
    try:
        same_crs = CRS.from_user_input(lcrs) == CRS.from_user_input(crs)
    except rasterio.errors.CRSError:
        return True
    same_grid = ltransform.almost_equals(transform) and (shape is None or tuple(lshape) == shape)
    return not (same_crs and same_grid)


def _reproject_label(
    data: np.ndarray,
    lcrs: str | None,
    ltransform: Affine | None,
    path: Path,
    shape: tuple[int, int] | None,
    crs: str | None,
    transform: Affine | None,
) -> np.ndarray:
    """A mask georeferenced on another grid, reprojected (nearest) onto the image grid.

    Image pixels the mask does not cover are "not plume". A mask that does not
    overlap the image at all is an error (a wrong file or CRS, almost always).
    Called only where :func:`_georef_differs` found both georeferenced.
    """
    assert None not in (lcrs, ltransform, shape, crs, transform)  # _georef_differs
    assert shape is not None and transform is not None
    from rasterio.warp import Resampling, reproject, transform_bounds

    h, w = shape
    iw, is_, ie, in_ = rasterio.transform.array_bounds(h, w, transform)
    try:
        mw, ms, me, mn = transform_bounds(
            CRS.from_user_input(lcrs),
            CRS.from_user_input(crs),
            *rasterio.transform.array_bounds(*data.shape, ltransform),
        )
    except (rasterio.errors.CRSError, rasterio.errors.RasterioError) as exc:
        raise InvalidSceneError(
            f"{path}: mask CRS {lcrs} cannot be mapped onto the image CRS {crs} ({_first_line(exc)})"
        ) from None
    xlo, xhi, ylo, yhi = min(iw, ie), max(iw, ie), min(is_, in_), max(is_, in_)
    if not (mw < xhi and me > xlo and ms < yhi and mn > ylo):
        raise InvalidSceneError(
            f"{path}: the mask does not overlap the image (mask bounds "
            f"{mw:.6g}, {ms:.6g}, {me:.6g}, {mn:.6g}; image bounds {xlo:.6g}, {ylo:.6g}, "
            f"{xhi:.6g}, {yhi:.6g}, in {crs}); expected a mask of this scene"
        )
    out = np.zeros(shape, np.uint8)
    reproject(
        (np.asarray(data) != 0).astype(np.uint8),
        out,
        src_transform=ltransform,
        src_crs=CRS.from_user_input(lcrs),
        dst_transform=transform,
        dst_crs=CRS.from_user_input(crs),
        resampling=Resampling.nearest,
        dst_nodata=0,
    )
    return out.astype(bool)


def read_geojson_label(
    path: str | os.PathLike[str],
    *,
    shape: tuple[int, int],
    crs: str | None = None,
    transform: Affine | None = None,
    require_overlap: bool = True,
) -> np.ndarray:
    """Rasterise GeoJSON polygons onto an image grid of ``shape``; ``True`` inside.

    Coordinates are in the image's CRS when it has one (a GeoJSON ``"crs"``
    member naming another CRS is reprojected; without a member, RFC 7946 WGS 84
    lon/lat is recognised for projected images and reprojected), else in pixels
    ``(column, row)``.
    An empty FeatureCollection gives an all-``False`` label; polygons that fall
    entirely outside the image are an error, since that is almost always a CRS
    mix-up.

    Parameters
    ----------
    path : str or os.PathLike
        The GeoJSON file.
    shape : tuple of int
        The image's ``(H, W)``.
    crs : str or None
        The image's CRS.
    transform : affine.Affine or None
        The image's geotransform.
    require_overlap : bool
        Refuse polygons that all fall outside the image.

    Returns
    -------
    numpy.ndarray
        Boolean ``(H, W)`` label.
    """
    from rasterio.warp import transform_geom
    from shapely.geometry import box
    from shapely.geometry import shape as to_shape

    path = Path(path)
    from dyntarget.io.safeopen import check_regular

    check_regular(path, max_bytes=MAX_GEOJSON_BYTES)
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise DataFileError(f"{path}: not valid JSON ({exc})") from None
    except RecursionError:
        raise DataFileError(
            f"{path}: JSON nested too deeply to be a GeoJSON label (expected a few levels)"
        ) from None
    geoms = _geojson_geometries(doc, path)
    src_crs = _geojson_crs(doc, path)
    if (
        src_crs is None
    ):  # no crs member: RFC 7946 lon/lat (ours) or, in older files, the image's CRS
        from dyntarget.io.geojson import rfc7946_source_crs

        rfc = rfc7946_source_crs(geoms, crs)
        src_crs = CRS.from_user_input(rfc) if rfc is not None else None
    if src_crs is not None and crs is not None:
        try:
            geoms = [transform_geom(src_crs, CRS.from_user_input(crs), g) for g in geoms]
        except (rasterio.errors.RasterioError, ValueError, TypeError, KeyError) as exc:
            raise DataFileError(
                f"{path}: geometry cannot be reprojected from {src_crs} ({_first_line(exc)})"
            ) from None
    grid = transform if transform is not None else Affine.identity()
    shapes = []
    for g in geoms:
        if not _finite_coordinates(g.get("coordinates")):
            raise DataFileError(f"{path}: a polygon has a NaN or infinite vertex")
        try:
            geom = to_shape(g)
        except Exception as exc:  # shapely raises several types for bad geometry
            raise DataFileError(f"{path}: invalid geometry ({_first_line(exc)})") from None
        if geom.geom_type not in ("Polygon", "MultiPolygon"):
            raise DataFileError(f"{path}: expected Polygon or MultiPolygon, got {geom.geom_type}")
        if not geom.is_empty:
            shapes.append(geom)
    h, w = shape
    if not shapes:
        return np.zeros((h, w), dtype=bool)
    west, south, east, north = rasterio.transform.array_bounds(h, w, grid)
    footprint = box(min(west, east), min(south, north), max(west, east), max(south, north))
    if require_overlap and not any(s.intersects(footprint) for s in shapes):
        raise InvalidSceneError(
            f"{path}: no polygon overlaps the image (wrong CRS or coordinates?)"
        )
    return rasterio.features.rasterize(
        [(s, 1) for s in shapes], out_shape=(h, w), transform=grid, fill=0, dtype="uint8"
    ).astype(bool)


def _finite_coordinates(coords: object) -> bool:
    """Whether every number in a (nested) GeoJSON coordinate array is finite."""
    stack = [coords]
    while stack:
        item = stack.pop()
        if isinstance(item, list):
            stack.extend(item)
        elif isinstance(item, float) and not np.isfinite(item):
            return False
    return True


def _geojson_crs(doc: object, path: Path) -> CRS | None:
    """The CRS a legacy GeoJSON ``"crs"`` member names (``None`` without one); refuses a
    malformed member or an unknown CRS."""
    if not isinstance(doc, dict) or "crs" not in doc or doc["crs"] is None:
        return None
    member = doc["crs"]
    props = member.get("properties") if isinstance(member, dict) else None
    name = props.get("name") if isinstance(props, dict) else None
    if not isinstance(name, str) or not name:
        raise DataFileError(
            f"{path}: malformed 'crs' member {str(member)[:80]!r}; expected "
            '{"type": "name", "properties": {"name": "EPSG:..."}} or none (RFC 7946: WGS 84)'
        )
    try:
        return CRS.from_user_input(name)
    except rasterio.errors.CRSError:
        raise DataFileError(f"{path}: unknown CRS {name[:80]!r} in the 'crs' member") from None


def _geojson_geometries(doc: object, path: Path) -> list[dict]:
    if not isinstance(doc, dict) or "type" not in doc:
        raise DataFileError(f"{path}: not a GeoJSON object (no 'type')")
    kind = doc["type"]
    if kind == "FeatureCollection":
        feats = doc.get("features")
        if not isinstance(feats, list):
            raise DataFileError(f"{path}: FeatureCollection without a 'features' list")
        out = []
        for i, f in enumerate(feats):
            if not isinstance(f, dict) or not isinstance(f.get("geometry"), dict):
                raise DataFileError(f"{path}: feature {i} has no geometry")
            out.append(f["geometry"])
        return out
    if kind == "Feature":
        if not isinstance(doc.get("geometry"), dict):
            raise DataFileError(f"{path}: feature has no geometry")
        return [doc["geometry"]]
    if kind in ("Polygon", "MultiPolygon"):
        return [doc]
    raise DataFileError(f"{path}: unsupported GeoJSON type {kind!r}")


def write_scene(
    scene: Scene, directory: str | os.PathLike[str], *, tags: dict[str, str] | None = None
) -> list[Path]:
    """Write ``<id>.tif`` (float32, deflate) and, if labelled, ``<id>_mask.tif``.

    Files are written atomically; the GSD goes into the ``DYNTARGET_GSD`` tag,
    ``tags`` (e.g. acquisition times) into the image's dataset tags.
    Returns the paths written.

    Parameters
    ----------
    scene : Scene
        The scene to write.
    directory : str or os.PathLike
        The scene directory (created if needed).
    tags : dict of str to str or None
        Extra dataset tags of the image.

    Returns
    -------
    list of pathlib.Path
        The image, then the mask if any.
    """
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    h, w = scene.shape
    profile = {
        "driver": "GTiff",
        "height": h,
        "width": w,
        "compress": "deflate",
        "tiled": True,
        "blockxsize": 256,
        "blockysize": 256,
    }
    if scene.transform is not None:
        profile["transform"] = scene.transform
    if scene.crs is not None:
        profile["crs"] = CRS.from_user_input(scene.crs)
    written = []
    image_path = directory / f"{scene.id}.tif"
    with atomic_path(image_path) as tmp, warnings.catch_warnings():
        warnings.simplefilter("ignore", rasterio.errors.NotGeoreferencedWarning)
        nodata = {"nodata": float("nan")} if scene.valid is not None else {}
        with rasterio.open(
            tmp, "w", count=4, dtype="float32", predictor=3, **profile, **nodata
        ) as dst:
            image = scene.image
            if scene.valid is not None:  # nodata is written as NaN (the file's nodata value)
                image = np.where(scene.valid[None], image, np.float32(np.nan))
            dst.write(image)
            for i, band in enumerate(("red", "green", "blue", "nir"), start=1):
                dst.set_band_description(i, band)
            if scene.gsd is not None:
                dst.update_tags(**{GSD_TAG: repr(scene.gsd)})
            if tags:
                dst.update_tags(**tags)
    written.append(image_path)
    if scene.label is not None:
        mask_path = directory / f"{scene.id}{MASK_SUFFIX}.tif"
        with atomic_path(mask_path) as tmp, warnings.catch_warnings():
            warnings.simplefilter("ignore", rasterio.errors.NotGeoreferencedWarning)
            with rasterio.open(tmp, "w", count=1, dtype="uint8", predictor=2, **profile) as dst:
                dst.write(scene.label.astype(np.uint8)[None])
        written.append(mask_path)
    return written


def scene_ids(directory: str | os.PathLike[str]) -> list[str]:
    """Sorted ids of the scenes (``<id>.tif`` not ending in ``_mask``) in ``directory``.

    Parameters
    ----------
    directory : str or os.PathLike
        The scene directory.

    Returns
    -------
    list of str
        The ids (hidden files excluded).
    """
    directory = Path(directory)
    if not directory.is_dir():
        raise DataFileError(f"{directory}: not a directory")
    ids = sorted(
        p.stem
        for p in directory.glob("*.tif")
        if not p.stem.endswith(MASK_SUFFIX) and not p.name.startswith(".")
    )
    return ids


def read_scene_dir(
    directory: str | os.PathLike[str], *, scale: float | None = None, require_labels: bool = False
) -> list[Scene]:
    """Read every scene of a scene directory, sorted by id.

    Parameters
    ----------
    directory : str or os.PathLike
        The scene directory (``<id>.tif`` with ``<id>_mask.tif`` or ``<id>.geojson`` labels).
    scale : float or None
        Reflectance per digital number for integer images (see :func:`read_scene`).
    require_labels : bool
        Refuse the directory when a scene has no label.

    Returns
    -------
    list of Scene
        The scenes.

    Raises
    ------
    dyntarget.errors.DataFileError
        When the directory holds no scene.
    """
    directory = Path(directory)
    ids = scene_ids(directory)
    if not ids:
        raise DataFileError(f"{directory}: no scenes (<id>.tif files) found")
    scenes = [read_scene(directory / f"{i}.tif", scale=scale) for i in ids]
    if require_labels:
        missing = [s.id for s in scenes if s.label is None]
        if missing:
            raise InvalidSceneError(
                f"{directory}: {len(missing)} scene(s) have no label (<id>_mask.tif or <id>.geojson): "
                + ", ".join(missing[:5])
            )
    return scenes
