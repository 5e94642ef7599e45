"""Sensor presets and flexible ingest: band selection, one file per band, ``.npz``.

A preset fixes where R, G, B and NIR sit in a product's multi-band file and how
digital numbers become reflectance (``reflectance = DN * scale + offset``):

==================  ====================  ==================  ===========================================
preset              bands (1-based)       scale, offset       notes
==================  ====================  ==================  ===========================================
``planetscope``     3, 2, 1, 4            1e-4, 0             4-band analytic SR/TOA: B, G, R, NIR on disk
``skysat``          3, 2, 1, 4            1e-4, 0             4-band analytic: B, G, R, NIR on disk
``sentinel2-l1c``   4, 3, 2, 8            1e-4, 0             13-band stack B1..B8, B8A, B9..B12
``sentinel2-l2a``   4, 3, 2, 8            1e-4, 0             12-band stack (no B10); baseline >= 04.00
                                                              products need ``offset=-0.1``
``landsat8/9``      4, 3, 2, 5            2e-5, -0.1          Collection 1/2 Level-1 TOA reflectance
                                                              (REFLECTANCE_MULT/ADD), no sun-angle term
==================  ====================  ==================  ===========================================

Band names (``B4,B3,B2,B8``) resolve through the preset's band list, or
through the file's own band descriptions.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from dyntarget.errors import (
    DataFileError,
    InvalidParameterError,
    InvalidSceneError,
)
from dyntarget.io import scenes as scene_io
from dyntarget.io.presets import PRESETS, Preset, get_preset  # noqa: F401  (re-exported)
from dyntarget.scene import Scene

if TYPE_CHECKING:
    from affine import Affine


def parse_bands(
    text: str | Sequence[int | str], names: Sequence[str] = ()
) -> tuple[int, int, int, int]:
    """Parse a band selection for R, G, B, NIR: ``"3,2,1,7"`` (1-based) or names like ``"B4,B3,B2,B8"``.

    Parameters
    ----------
    text : str or sequence of int or str
        Four comma-separated selectors, or a sequence of four.
    names : sequence of str
        The file's band names in order, for selection by name (case-insensitive).

    Returns
    -------
    tuple of int
        1-based band numbers of R, G, B and NIR.

    Raises
    ------
    dyntarget.errors.InvalidParameterError
        For anything but four different, existing bands.

    Examples
    --------
    >>> parse_bands("3,2,1,7")
    (3, 2, 1, 7)
    >>> parse_bands("B4,B3,B2,B8", names=["B1", "B2", "B3", "B4", "B5", "B6", "B7", "B8"])
    (4, 3, 2, 8)
    """
    tokens = (
        [t.strip() for t in text.split(",")] if isinstance(text, str) else [str(t) for t in text]
    )
    if len(tokens) != 4:
        raise InvalidParameterError(
            f"bands: expected 4 bands for R, G, B, NIR, got {len(tokens)} in {text!r}"
        )
    lookup = {n.upper(): i + 1 for i, n in enumerate(names)}
    out = []
    for position, t in enumerate(tokens):
        if not t:
            raise InvalidParameterError(
                f"bands: selector {position + 1} of {text!r} is empty; expected a band number "
                "or name for each of R, G, B, NIR"
            )
        if t.isascii() and t.isdigit():
            idx = int(t)
        elif t.upper() in lookup:
            idx = lookup[t.upper()]
        else:
            known = f"; known names: {', '.join(names)}" if names else ""
            raise InvalidParameterError(
                f"bands: {t!r} is neither a 1-based band number nor a band name{known}"
            )
        if idx < 1:
            raise InvalidParameterError(f"bands: band numbers are 1-based, got {idx}")
        if idx in out:
            raise InvalidParameterError(
                f"bands: band {idx} is selected twice in {text!r}; expected four different bands"
            )
        out.append(idx)
    return tuple(out)  # type: ignore[return-value]


def _scale(data: np.ndarray, scale: float | None, offset: float, path: object) -> np.ndarray:
    image = scene_io.scale_to_reflectance(data, scale=scale, path=str(path))
    return image + np.float32(offset) if offset else image


def read_multiband(
    path: str | os.PathLike[str],
    *,
    bands: str | Sequence[int | str] | None = None,
    preset: str | None = None,
    scale: float | None = None,
    offset: float | None = None,
) -> Scene:
    """Read R, G, B, NIR from one multi-band raster (selected by ``bands`` or a ``preset``).

    Parameters
    ----------
    path : str or os.PathLike
        The raster.
    bands : str or sequence of int or str or None
        R, G, B, NIR selection (:func:`parse_bands`); default the preset's, else
        bands 1-4 of a 4-band file.
    preset : str or None
        Sensor preset (:mod:`dyntarget.io.presets`).
    scale : float or None
        Reflectance per digital number (default: the preset's, else by dtype).
    offset : float or None
        Reflectance added after scaling (default: the preset's, else 0).

    Returns
    -------
    Scene
        The unlabelled scene, id the file's stem; GSD from a projected CRS's pixel size.
    """
    path = Path(path)
    p = get_preset(preset) if preset else None
    with scene_io._open(path) as src:
        names = p.band_names if p and p.band_names else tuple(d or "" for d in src.descriptions)
        if bands is not None:
            sel = parse_bands(bands, names)
        elif p is not None:
            sel = p.bands
        else:
            sel = (1, 2, 3, 4)
            if src.count != 4:
                raise InvalidSceneError(
                    f"{path}: {src.count} band(s); choose R, G, B, NIR with --bands or a --preset"
                )
        if max(sel) > src.count:
            raise InvalidSceneError(
                f"{path}: band {max(sel)} requested but the file has {src.count} band(s)"
            )
        if src.width * src.height > scene_io.MAX_PIXELS:
            raise InvalidSceneError(
                f"{path}: image is {src.width} x {src.height} px, too large to read whole"
            )
        try:
            data = src.read(list(sel))
        except Exception as exc:  # rasterio raises several types on corrupt data
            raise DataFileError(
                f"{path}: corrupt or truncated raster ({scene_io._first_line(exc)})"
            ) from None
        crs, transform = scene_io._georef(src)
        gsd = (
            abs(transform.a) if transform is not None and src.crs and src.crs.is_projected else None
        )
    image = _scale(
        data,
        scale if scale is not None else (p.scale if p else None),
        offset if offset is not None else (p.offset if p else 0.0),
        path,
    )
    scene_io.check_reflectance(image, path)
    return Scene(image, gsd=gsd, crs=crs, transform=transform, id=path.stem)


def read_band_files(
    paths: Sequence[str | os.PathLike[str]],
    *,
    preset: str | None = None,
    scale: float | None = None,
    offset: float | None = None,
    scene_id: str | None = None,
) -> Scene:
    """Read one single-band file per band, given in the order R, G, B, NIR (the Landsat/38-Cloud layout).

    Parameters
    ----------
    paths : sequence of str or os.PathLike
        Four single-band rasters of the same shape: R, G, B, NIR.
    preset : str or None
        Sensor preset for the default scale and offset.
    scale : float or None
        Reflectance per digital number (default: the preset's, else by dtype).
    offset : float or None
        Reflectance added after scaling (default: the preset's, else 0).
    scene_id : str or None
        The scene's id (default: the first file's folder name).

    Returns
    -------
    Scene
        The unlabelled 4-band scene.
    """
    if len(paths) != 4:
        raise InvalidParameterError(
            f"band files: expected 4 files (R, G, B, NIR), got {len(paths)}"
        )
    p = get_preset(preset) if preset else None
    planes: list[np.ndarray] = []
    georef: tuple[str | None, Affine | None] = (None, None)
    shape: tuple[int, ...] | None = None
    for path in map(Path, paths):
        with scene_io._open(path) as src:
            if src.count != 1:
                raise InvalidSceneError(f"{path}: a band file must hold 1 band, got {src.count}")
            plane = scene_io._read_all(src, path)[0]
            ref = scene_io._georef(src)
        if shape is None:
            shape, georef = plane.shape, ref
        elif plane.shape != shape:
            raise InvalidSceneError(
                f"{path}: shape {plane.shape} differs from the first band's {shape}"
            )
        elif ref != georef:
            raise InvalidSceneError(f"{path}: georeferencing differs from the first band's")
        planes.append(plane)
    data = np.stack(planes)
    image = _scale(
        data,
        scale if scale is not None else (p.scale if p else None),
        offset if offset is not None else (p.offset if p else 0.0),
        paths[0],
    )
    scene_io.check_reflectance(image, str(paths[0]))
    crs, transform = georef
    return Scene(
        image, crs=crs, transform=transform, id=scene_id or Path(paths[0]).parent.name or "scene"
    )


NPZ_ARRAYS = ("image", "red", "green", "blue", "nir", "label")
"""The arrays of a scene ``.npz`` that are read (any others are ignored, unread)."""

MAX_NPZ_MEMBERS = 64
"""Most members a scene ``.npz`` may list."""

MAX_NPZ_BYTES = 4 * 4 * scene_io.MAX_PIXELS
"""Largest array of a scene ``.npz`` (4 GiB, four float32 bands of the largest image), as its
header declares it, checked before anything is decompressed."""


def npz_headers(path: str | os.PathLike[str]) -> dict[str, tuple[tuple[int, ...], np.dtype]]:
    """The shape and dtype of each array :func:`read_npz` reads, from the headers alone.

    Checks the member count (:data:`MAX_NPZ_MEMBERS`), each array's declared size
    (:data:`MAX_NPZ_BYTES`), dtype (numbers only) and pixels per band (``MAX_PIXELS``)
    before any array is decompressed or allocated.

    Parameters
    ----------
    path : str or os.PathLike
        The ``.npz`` file.

    Returns
    -------
    dict
        ``name -> (shape, dtype)`` for the members of :data:`NPZ_ARRAYS` present.

    Raises
    ------
    DataFileError
        An unreadable archive or header, or an array beyond a limit (the limit named).

    Examples
    --------
    >>> import tempfile
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     np.savez(f"{tmp}/s.npz", image=np.zeros((4, 2, 3), np.float32))
    ...     npz_headers(f"{tmp}/s.npz")["image"][0]
    (4, 2, 3)
    """
    import zipfile

    path = Path(path)
    out: dict[str, tuple[tuple[int, ...], np.dtype]] = {}
    total = 0
    try:
        with zipfile.ZipFile(path) as archive:
            infos = archive.infolist()
            if len(infos) > MAX_NPZ_MEMBERS:
                raise DataFileError(
                    f"{path}: {len(infos):,} members, more than the {MAX_NPZ_MEMBERS} a "
                    "scene .npz may hold"
                )
            for info in infos:
                name = info.filename.removesuffix(".npy")
                if name not in NPZ_ARRAYS:
                    continue
                with archive.open(info) as member:
                    version = np.lib.format.read_magic(member)
                    read_header = (
                        np.lib.format.read_array_header_1_0
                        if version == (1, 0)
                        else np.lib.format.read_array_header_2_0
                    )
                    shape, _, dtype = read_header(member, max_header_size=4096)
                if dtype.kind not in "biuf" or dtype.hasobject:
                    raise DataFileError(
                        f"{path}: not a readable .npz file ({name} holds {dtype}, not numbers)"
                    )
                size = int(np.prod(shape, dtype=object)) * dtype.itemsize
                band = int(np.prod(shape[-2:], dtype=object)) if len(shape) >= 2 else 0
                if len(shape) > 3 or band > scene_io.MAX_PIXELS or size > MAX_NPZ_BYTES:
                    raise DataFileError(
                        f"{path}: {name} declares shape {shape} of {dtype} ({size:,} bytes), "
                        f"beyond the limits of a scene .npz ({scene_io.MAX_PIXELS:,} px per "
                        f"band, {MAX_NPZ_BYTES:,} bytes per array, 3 dimensions)"
                    )
                out[name] = (tuple(shape), dtype)
                total += size
                if total > MAX_NPZ_BYTES + 8 * scene_io.MAX_PIXELS:  # four bands and a label
                    raise DataFileError(
                        f"{path}: its arrays declare {total:,} bytes, more than the "
                        f"{MAX_NPZ_BYTES + 8 * scene_io.MAX_PIXELS:,} a scene .npz may hold"
                    )
    except DataFileError:
        raise
    except (zipfile.BadZipFile, ValueError, OSError, EOFError) as exc:
        raise DataFileError(
            f"{path}: not a readable .npz file ({scene_io._first_line(exc)})"
        ) from None
    return out


def read_npz(
    path: str | os.PathLike[str], *, scale: float | None = None, offset: float = 0.0
) -> Scene:
    """Read ``image`` (4, H, W) or ``red``, ``green``, ``blue``, ``nir`` arrays (and an optional ``label``).

    Parameters
    ----------
    path : str or os.PathLike
        The ``.npz`` file (read without pickles).
    scale : float or None
        Reflectance per digital number (default by dtype).
    offset : float
        Reflectance added after scaling.

    Returns
    -------
    Scene
        The scene, labelled when the file has a ``label``.
    """
    path = Path(path)
    from dyntarget.io.safeopen import check_regular

    check_regular(path)  # a FIFO would block np.load
    wanted = npz_headers(path)  # sizes from the headers, before anything is allocated
    try:
        with np.load(path, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files if k in wanted}
    except (ValueError, OSError, EOFError) as exc:
        raise DataFileError(
            f"{path}: not a readable .npz file ({scene_io._first_line(exc)})"
        ) from None
    if "image" in arrays:
        data = arrays["image"]
    elif {"red", "green", "blue", "nir"} <= arrays.keys():
        data = np.stack([arrays[k] for k in ("red", "green", "blue", "nir")])
    else:
        raise InvalidSceneError(
            f"{path}: expected an 'image' array or 'red', 'green', 'blue', 'nir'; found {sorted(arrays)}"
        )
    label = arrays.get("label")
    if data.ndim != 3 or data.shape[0] != 4:
        raise InvalidSceneError(
            f"{path}: expected 4 bands (R, G, B, NIR) of shape (4, H, W), got {data.shape}"
        )
    image = _scale(data, scale, offset, path)
    scene_io.check_reflectance(image, path)
    try:
        return Scene(image, label=label, id=path.stem)
    except InvalidSceneError as exc:
        raise InvalidSceneError(f"{path}: {exc}") from None


def read_any(
    paths: Sequence[str | os.PathLike[str]],
    *,
    label: str | os.PathLike[str] | None = None,
    bands: str | None = None,
    preset: str | None = None,
    scale: float | None = None,
    offset: float | None = None,
    factor: int = 1,
) -> Scene:
    """One path (GeoTIFF or .npz) or four band files (R, G, B, NIR), on the WFOV grid of ``factor``.

    ``label`` (a mask raster or GeoJSON on the full-resolution grid) is read
    only when given; no sibling file is picked up. A plain 4-band GeoTIFF is
    read in strips straight onto the WFOV grid (:func:`dyntarget.io.read_scene`
    with ``factor``); the other forms are read whole, then downsampled.

    Parameters
    ----------
    paths : sequence of str or os.PathLike
        One file, or four band files in the order R, G, B, NIR.
    label : str or os.PathLike or None
        Label file (mask raster or GeoJSON).
    bands : str or None
        R, G, B, NIR selection in a multi-band file (:func:`parse_bands`).
    preset : str or None
        Sensor preset (:mod:`dyntarget.io.presets`).
    scale : float or None
        Reflectance per digital number (default: the preset's, else by dtype).
    offset : float or None
        Reflectance added after scaling (default: the preset's, else 0).
    factor : int
        High-resolution pixels per WFOV pixel.

    Returns
    -------
    Scene
        The scene on the WFOV grid.
    """
    if len(paths) == 4:
        if bands:
            raise InvalidParameterError(
                "bands: not used with four band files (they are R, G, B, NIR in order)"
            )
        scene = read_band_files(paths, preset=preset, scale=scale, offset=offset)
    elif len(paths) != 1:
        raise InvalidParameterError(
            f"image: expected 1 file or 4 band files (R, G, B, NIR), got {len(paths)}"
        )
    elif Path(paths[0]).suffix.lower() == ".npz":
        scene = replace(read_npz(paths[0], scale=scale, offset=offset or 0.0), label=None)
    elif bands is None and preset is None and offset is None:
        return scene_io.read_scene(
            paths[0], label=label, scale=scale, factor=factor, auto_label=False
        )
    else:
        scene = read_multiband(paths[0], bands=bands, preset=preset, scale=scale, offset=offset)
    if label is not None:
        lab = scene_io.read_label(
            label, shape=scene.shape, crs=scene.crs, transform=scene.transform
        )
        scene = replace(scene, label=lab)
    return scene.to_wfov(factor)
