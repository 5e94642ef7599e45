"""The industrial smoke plume dataset (Mommert et al. 2020), Zenodo record 4250706.

M. Mommert, M. Sigel, M. Neuhausler, L. Scheibenreif, D. Borth, "Characterization
of Industrial Smoke Plumes from Remote Sensing Data", Tackling Climate Change with
Machine Learning workshop, NeurIPS 2020. https://doi.org/10.5281/zenodo.4250706

Published layout (learned from the dataset record and the authors' loader,
github.com/HSG-AIML/IndustrialSmokePlumeDetection, ``segmentation/data.py``):

* ``images.tar.gz``: Sentinel-2 GeoTIFFs, about 120 x 120 px at 10 m, all 13
  bands in the order B1..B8, B8A, B9..B12, digital numbers (reflectance x
  10000), in folders named ``positive`` (smoke present) and ``negative``;
  file names embed an ISO timestamp (with colons);
* ``segmentation_labels.tar.gz``: one Label Studio JSON file per annotated
  image: ``data.image`` is ``"<upload prefix>-<image name>.png"`` and
  ``completions[*].result[*].value.points`` are polygon vertices ``[x, y]`` in
  percent of a 120 px image (the authors scale them by 1.2 to pixels and
  rasterise with ``all_touched=True``).

:func:`fetch` downloads the record's files with the MD5 checksums the Zenodo
API publishes for them, resuming partial downloads. :func:`prepare` converts
the annotated positives (and optionally as many negatives) into a dyntarget
scene directory: ``<id>.tif`` (R, G, B, NIR = B4, B3, B2, B8, reflectance) and
``<id>_mask.tif``; colons in ids become ``-``.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import tarfile
import urllib.error
import urllib.request
import warnings
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path, PurePosixPath

import numpy as np
import rasterio
import rasterio.errors
import rasterio.features
from affine import Affine
from tqdm import tqdm

from dyntarget.errors import DataFileError
from dyntarget.io import scene_ids, write_scene
from dyntarget.scene import Scene

RECORD_ID = 4250706
DOI = "10.5281/zenodo.4250706"
RECORD_API = f"https://zenodo.org/api/records/{RECORD_ID}"
IMAGES, LABELS = "images.tar.gz", "segmentation_labels.tar.gz"
RGBN_BANDS = (4, 3, 2, 8)  # B4, B3, B2, B8 in the 13-band (and the 12-band L2A) stack
DN_SCALE = 1e-4
LABEL_PERCENT_TO_PX = 1.2  # percent of a 120 px image
GSD_M = 10.0
CHUNK = 1 << 20


@dataclass(frozen=True)
class RemoteFile:
    """One file of the Zenodo record.

    Parameters
    ----------
    key : str
        File name in the record.
    size : int
        Size, bytes.
    md5 : str
        MD5 checksum, hexadecimal.
    url : str
        Download URL.
    """

    key: str
    size: int
    md5: str
    url: str


# ------------------------------------------------------------------ fetching


def _network_error(url: str, exc: BaseException) -> DataFileError:
    reason = getattr(exc, "reason", exc)
    return DataFileError(
        f"cannot download {url}: {reason}. Is the network reachable? Download the files of "
        f"https://doi.org/{DOI} by hand into the folder instead, then run 'dyntarget datasets prepare'"
    )


def record_files(api_url: str = RECORD_API, *, timeout: float = 30.0) -> list[RemoteFile]:
    """The record's files with sizes and MD5 checksums, from the Zenodo records API.

    Parameters
    ----------
    api_url : str
        The Zenodo records API URL.
    timeout : float
        Network timeout, seconds.

    Returns
    -------
    list of RemoteFile
        The files of the record.

    Raises
    ------
    dyntarget.errors.DataFileError
        When the answer is not a record, lists no files or a file has no MD5.
    """
    try:
        with urllib.request.urlopen(api_url, timeout=timeout) as resp:
            record = json.load(resp)
    except OSError as exc:  # URLError and TimeoutError are OSErrors
        raise _network_error(api_url, exc) from None
    except json.JSONDecodeError as exc:
        raise DataFileError(f"{api_url}: not a Zenodo record ({exc})") from None
    files = []
    for f in record.get("files", []):
        checksum = str(f.get("checksum", ""))
        if not checksum.startswith("md5:"):
            raise DataFileError(f"{api_url}: file {f.get('key')!r} has no MD5 checksum")
        files.append(RemoteFile(f["key"], int(f["size"]), checksum[4:], f["links"]["self"]))
    if not files:
        raise DataFileError(f"{api_url}: the record lists no files")
    return files


def _md5(path: Path) -> str:
    h = hashlib.md5(usedforsecurity=False)
    with path.open("rb") as fh:
        for chunk in iter(lambda: fh.read(CHUNK), b""):
            h.update(chunk)
    return h.hexdigest()


def download(
    remote: RemoteFile, directory: Path, *, timeout: float = 60.0, progress: bool = True
) -> Path:
    """Download one file, resuming ``<name>.part`` with an HTTP Range request; verify its MD5.

    A complete file already at the target with the right size and checksum is
    not downloaded again.

    Parameters
    ----------
    remote : RemoteFile
        The file to download.
    directory : pathlib.Path
        Where to put it (as ``remote.key``).
    timeout : float
        Network timeout, seconds.
    progress : bool
        Show a progress bar.

    Returns
    -------
    pathlib.Path
        The downloaded file.

    Raises
    ------
    dyntarget.errors.DataFileError
        When the size or MD5 does not match (the partial download is removed).
    """
    target = directory / remote.key
    if target.exists() and target.stat().st_size == remote.size and _md5(target) == remote.md5:
        return target
    part = directory / f"{remote.key}.part"
    have = part.stat().st_size if part.exists() else 0
    if have > remote.size:
        part.unlink()
        have = 0
    request = urllib.request.Request(
        remote.url, headers={"Range": f"bytes={have}-"} if have else {}
    )
    try:
        with urllib.request.urlopen(request, timeout=timeout) as resp:
            if have and resp.status != 206:  # the server ignored the range: start again
                have = 0
            mode = "ab" if have else "wb"
            with (
                part.open(mode) as out,
                tqdm(
                    total=remote.size,
                    initial=have,
                    unit="B",
                    unit_scale=True,
                    desc=remote.key,
                    disable=not progress,
                ) as bar,
            ):
                for chunk in iter(lambda: resp.read(CHUNK), b""):
                    out.write(chunk)
                    bar.update(len(chunk))
    except OSError as exc:  # URLError and TimeoutError are OSErrors
        raise _network_error(remote.url, exc) from None
    if part.stat().st_size != remote.size or _md5(part) != remote.md5:
        part.unlink(missing_ok=True)
        raise DataFileError(
            f"{remote.key}: size or MD5 does not match the record; the partial download was removed"
        )
    os.replace(part, target)
    return target


def fetch(
    to: str | os.PathLike[str], *, api_url: str = RECORD_API, progress: bool = True
) -> list[Path]:
    """Download the dataset's files into ``to`` (resumable, checksummed).

    Parameters
    ----------
    to : str or os.PathLike
        Destination folder (created if needed).
    api_url : str
        The Zenodo records API URL of the dataset.
    progress : bool
        Show progress bars.

    Returns
    -------
    list of pathlib.Path
        The downloaded files.
    """
    directory = Path(to)
    directory.mkdir(parents=True, exist_ok=True)
    return [download(f, directory, progress=progress) for f in record_files(api_url)]


# ------------------------------------------------------------------ preparing


def label_image_name(image_field: str) -> str:
    """The GeoTIFF name a Label Studio ``data.image`` refers to (the authors' rule).

    Parameters
    ----------
    image_field : str
        The ``data.image`` path of the annotation.

    Returns
    -------
    str
        The GeoTIFF's file name.

    Examples
    --------
    >>> label_image_name("/data/upload/17-site_2019-05-09T10:26:31.png")
    'site_2019-05-09T10:26:31.tif'
    """
    name = PurePosixPath(image_field).name
    return "-".join(name.split("-")[1:]).replace(".png", ".tif")


def parse_label(doc: dict, source: str) -> tuple[str, list[np.ndarray]]:
    """``(image name, polygons in percent)`` from one Label Studio JSON document.

    Parameters
    ----------
    doc : dict
        The parsed JSON document.
    source : str
        Where it came from, for error messages.

    Returns
    -------
    name : str
        The GeoTIFF's file name (:func:`label_image_name`).
    polygons : list of numpy.ndarray
        ``(n, 2)`` vertices per polygon (at least 3), percent of the image width
        and height.

    Raises
    ------
    dyntarget.errors.DataFileError
        When the document is not a Label Studio annotation or a vertex is not finite.
    """
    try:
        if not isinstance(doc, dict):
            raise TypeError(f"expected a JSON object, got {type(doc).__name__}")
        name = label_image_name(doc["data"]["image"])
        completions = doc.get("completions", [])
        if not isinstance(completions, list) or not all(isinstance(c, dict) for c in completions):
            raise TypeError(f"completions: expected a list of objects, got {completions!r:.60}")
        results = [r for c in completions for r in _list(c.get("result", []), "result")]
        polygons = [np.asarray(r["value"]["points"], dtype=np.float64) for r in results]
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise DataFileError(f"{source}: not a Label Studio annotation ({exc!r})") from None
    polygons = [p for p in polygons if p.ndim == 2 and p.shape[0] >= 3 and p.shape[1] == 2]
    for p in polygons:
        if not np.isfinite(p).all():
            raise DataFileError(
                f"{source}: a label polygon of {name} has a NaN or infinite vertex; "
                "expected finite percentages (nothing was written)"
            )
    return name, polygons


MAX_MEMBER_BYTES = 1 << 30
"""Largest image or label file read from the archive or its folder (1 GiB)."""


def _list(value: object, name: str) -> list:
    if not isinstance(value, list) or not all(isinstance(v, dict) for v in value):
        raise TypeError(f"{name}: expected a list of objects, got {value!r:.60}")
    return value


def _members(source: Path, suffixes: tuple[str, ...]) -> Iterator[tuple[str, bytes]]:
    """``(path, bytes)`` of the files in a .tar.gz archive or an extracted folder."""
    if source.is_dir():
        for p in sorted(source.rglob("*")):
            if p.is_file() and p.suffix.lower() in suffixes:
                from dyntarget.io.safeopen import read_bytes

                yield p.relative_to(source).as_posix(), read_bytes(p, max_bytes=MAX_MEMBER_BYTES)
        return
    try:
        with tarfile.open(source, "r:*") as tar:
            for m in sorted(tar.getmembers(), key=lambda m: m.name):
                if m.isfile() and PurePosixPath(m.name).suffix.lower() in suffixes:
                    if m.size > MAX_MEMBER_BYTES:
                        raise DataFileError(
                            f"{source}: member {m.name} is {m.size:,} bytes, more than the "
                            f"{MAX_MEMBER_BYTES:,} accepted"
                        )
                    fh = tar.extractfile(m)
                    if fh is not None:
                        yield m.name, fh.read()
    except (tarfile.TarError, OSError, EOFError) as exc:
        raise DataFileError(f"{source}: not a readable archive ({exc})") from None


def _find(src: Path, archive: str) -> Path:
    for candidate in (src / archive, src / archive.removesuffix(".tar.gz")):
        if candidate.exists():
            return candidate
    raise DataFileError(
        f"{src}: neither {archive} nor its extracted folder is there (run 'dyntarget datasets fetch')"
    )


def _read_tif(name: str, data: bytes) -> tuple[np.ndarray, str | None, Affine | None]:
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", rasterio.errors.NotGeoreferencedWarning)
            with rasterio.MemoryFile(data) as mem, mem.open() as ds:
                if ds.count < max(RGBN_BANDS):
                    raise DataFileError(
                        f"{name}: {ds.count} band(s); expected a 12- or 13-band Sentinel-2 stack"
                    )
                planes = ds.read(list(RGBN_BANDS))
                crs = ds.crs.to_string() if ds.crs else None
                transform = ds.transform if ds.crs else None
    except rasterio.errors.RasterioError as exc:
        raise DataFileError(f"{name}: not a readable GeoTIFF ({exc})") from None
    return planes.astype(np.float32) * np.float32(DN_SCALE), crs, transform


def _scene_id(name: str, taken: set[str] | None = None) -> str:
    """A file-safe, visible, unique scene id for the image ``name``.

    Characters other than letters, digits, ``_ . -`` become ``-``; leading dots
    (hidden files, which scene directories skip) become ``_``; an id that would
    read as a mask (``*_mask``) or that is already in ``taken`` gets a suffix
    ``-2``, ``-3``, ... (images are visited in sorted order, so ids are stable).

    Examples
    --------
    >>> taken = set()
    >>> [_scene_id(n, taken) for n in ["a:1.tif", "a-1.tif", ".hidden.tif", "....tif", "x_mask.tif"]]
    ['a-1', 'a-1-2', '_hidden', '___', 'x_mask-2']
    """
    base = re.sub(r"[^A-Za-z0-9_.-]", "-", PurePosixPath(name).stem)
    base = re.sub(r"^\.+", lambda m: "_" * len(m.group(0)), base) or "scene"
    taken = set() if taken is None else taken
    sid, n = base, 1
    while sid in taken or sid.endswith("_mask"):
        n += 1
        sid = f"{base}-{n}"
    taken.add(sid)
    return sid


def prepare(
    src: str | os.PathLike[str],
    out: str | os.PathLike[str],
    *,
    negatives: bool = False,
    progress: bool = True,
) -> list[str]:
    """Convert the downloaded dataset into a scene directory; returns the scene ids written.

    Annotated images in ``positive`` folders become labelled scenes. With
    ``negatives``, as many images from ``negative`` folders are added with empty
    labels (the authors' balancing).

    Parameters
    ----------
    src : str or os.PathLike
        The folder :func:`fetch` downloaded into.
    out : str or os.PathLike
        The scene directory to write.
    negatives : bool
        Also add images from ``negative`` folders, with empty labels, up to as
        many as the labelled ones.
    progress : bool
        Show a progress bar.

    Returns
    -------
    list of str
        The scene ids written.
    """
    src, out = Path(src), Path(out)
    labels: dict[str, list[np.ndarray]] = {}
    for path, data in _members(_find(src, LABELS), (".json",)):
        from dyntarget.io.safeopen import loads_json

        doc = loads_json(data, where=path)  # bounded depth: one line for a hostile label
        name, polygons = parse_label(doc, path)
        if polygons:
            labels[name] = polygons
    if not labels:
        raise DataFileError(f"{src}: no segmentation labels with polygons found")
    written: list[str] = []
    taken: set[str] = set()
    n_neg = 0
    images = _members(_find(src, IMAGES), (".tif", ".tiff"))
    for path, data in tqdm(images, desc="prepare", unit="image", disable=not progress):
        parts = PurePosixPath(path).parts
        name = PurePosixPath(path).name
        positive = "positive" in parts and name in labels
        negative = negatives and "negative" in parts and n_neg < len(labels)
        if not (positive or negative):
            continue
        image, crs, transform = _read_tif(path, data)
        h, w = image.shape[1:]
        mask = np.zeros((h, w), bool)
        if positive:
            from shapely.geometry import Polygon

            shapes = [Polygon(p * LABEL_PERCENT_TO_PX) for p in labels[name]]
            shapes = [s.buffer(0) if not s.is_valid else s for s in shapes]
            mask = rasterio.features.rasterize(
                [(s, 1) for s in shapes if not s.is_empty],
                out_shape=(h, w),
                all_touched=True,
                dtype="uint8",
            ).astype(bool)
        else:
            n_neg += 1
        scene = Scene(
            image, label=mask, gsd=GSD_M, crs=crs, transform=transform, id=_scene_id(name, taken)
        )
        write_scene(scene, out)
        written.append(scene.id)
    if not written:
        raise DataFileError(f"{src}: no annotated image in a 'positive' folder matched a label")
    readable = set(scene_ids(out))
    lost = [sid for sid in written if sid not in readable]
    if lost:  # cannot happen with the ids above; never report scenes that are not there
        raise DataFileError(f"{out}: scenes written but not found again: {', '.join(lost[:5])}")
    return written


__all__ = ["DOI", "RECORD_API", "fetch", "label_image_name", "prepare", "record_files"]
