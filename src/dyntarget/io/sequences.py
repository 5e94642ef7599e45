"""Read and write time-aware scene directories (frame sequences with acquisition times).

On disk a sequence ``<id>`` is a folder::

    <id>/
      sequence.json        sidecar (optional for your own data, see below)
      f000.tif             frame 0: a 4-band GeoTIFF, as for a scene
      f000_mask.tif        its label (optional; or f000.geojson)
      f001.tif ...

``sequence.json``::

    {"format": "dyntarget-sequence", "version": 1, "id": "<id>",
     "epoch": "2026-01-01T00:00:00Z",                 # ISO-8601 UTC of t = 0
     "frames": [{"file": "f000.tif", "time_s": 0.0},  # seconds after the epoch
                {"file": "f001.tif", "time": "2026-01-01T00:00:20Z"}],  # or ISO time
     "meta": {"world": {...}, "window": [...]}}       # optional; see below

Each frame's GeoTIFF also carries its time in the tags ``DYNTARGET_TIME``
(ISO-8601 UTC) and ``DYNTARGET_TIME_S`` (seconds after the epoch). A folder
of GeoTIFFs **without** the sidecar is read too: each frame's time is read by
:func:`dyntarget.io.acquisition.read_acquisition` (a ``.meta.json`` sidecar,
then ``DYNTARGET_TIME``, ``DYNTARGET_ACQUIRED``, ``ACQUISITIONDATETIME``,
``TIFFTAG_DATETIME`` read as UTC), the earliest frame is ``t = 0``, frames are
sorted by time.

``meta.world`` is the generator spec of a synthetic sequence
(:class:`dyntarget.synth.dynamic.WorldSpec`): the truth at any time is rebuilt
from it (:func:`dyntarget.synth.dynamic.truth_provider`). Without it the
truth at ``t`` is the labelled frame last acquired at or before ``t``.

A *sequence directory* is a folder of such sequence folders.
"""

from __future__ import annotations

import json
import os
import warnings
from pathlib import Path
from typing import Any

import rasterio
import rasterio.errors

from dyntarget.errors import DataFileError, InvalidParameterError, InvalidSceneError
from dyntarget.io.atomic import write_text
from dyntarget.io.scenes import MASK_SUFFIX, read_scene, write_scene
from dyntarget.sequence import FrameSequence, format_time, parse_time, seconds_between

SEQUENCE_FILE = "sequence.json"
FORMAT = "dyntarget-sequence"
VERSION = 1
TIME_TAG = "DYNTARGET_TIME"
TIME_S_TAG = "DYNTARGET_TIME_S"
TIFF_TIME_TAG = "TIFFTAG_DATETIME"
MAX_FRAMES = 10_000
"""Most frames listed in one ``sequence.json`` (as ``dyntarget.synth.dynamic.MAX_FRAMES``)."""


def write_sequence(seq: FrameSequence, directory: str | os.PathLike[str]) -> list[Path]:
    """Write ``directory/<seq.id>/`` (frames, labels, ``sequence.json`` last); return the paths.

    Parameters
    ----------
    seq : FrameSequence
        The sequence to write.
    directory : str or os.PathLike
        The parent folder.

    Returns
    -------
    list of pathlib.Path
        The frames' images and masks, then ``sequence.json``.

    Examples
    --------
    >>> import tempfile, numpy as np
    >>> from dyntarget.scene import Scene
    >>> img = np.linspace(0.0, 0.5, 256, dtype=np.float32).reshape(4, 8, 8)
    >>> f = [Scene(img + 0.1 * i, id=f"f{i:03d}") for i in range(2)]
    >>> seq = FrameSequence(f, [0.0, 20.0], epoch="2026-01-01T00:00:00Z", id="s1")
    >>> d = tempfile.mkdtemp()
    >>> [p.name for p in write_sequence(seq, d)]
    ['f000.tif', 'f001.tif', 'sequence.json']
    >>> read_sequence(f"{d}/s1").times.tolist()
    [0.0, 20.0]
    """
    folder = Path(directory) / seq.id
    written: list[Path] = []
    entries = []
    for i, frame in enumerate(seq.frames):
        tags = {TIME_S_TAG: repr(float(seq.times[i]))}
        if seq.epoch is not None:
            tags[TIME_TAG] = format_time(seq.epoch, float(seq.times[i]))
        written += write_scene(frame, folder, tags=tags)
        entries.append({"file": f"{frame.id}.tif", "time_s": float(seq.times[i])})
    doc: dict[str, Any] = {
        "format": FORMAT,
        "version": VERSION,
        "id": seq.id,
        "epoch": seq.epoch,
        "frames": entries,
        "meta": seq.meta,
    }
    written.append(
        write_text(folder / SEQUENCE_FILE, json.dumps(doc, indent=1, sort_keys=True) + "\n")
    )
    return written


def _frame_time(path: Path):
    from dyntarget.io.acquisition import read_acquisition

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", rasterio.errors.NotGeoreferencedWarning)
            with rasterio.open(path):
                pass
    except rasterio.errors.RasterioIOError as exc:
        raise DataFileError(f"{path}: cannot read ({str(exc).splitlines()[0]})") from None
    when, _ = read_acquisition(path)
    if when is None:
        raise DataFileError(
            f"{path}: no acquisition time (a {TIME_TAG}, ACQUISITIONDATETIME or TIFF DateTime tag, "
            f"or a .meta.json sidecar) and no {SEQUENCE_FILE}"
        )
    return when


def _load_sidecar(path: Path) -> dict[str, Any]:
    from dyntarget.io.safeopen import read_json

    doc = read_json(path)  # a regular file of bounded size and nesting
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise DataFileError(f'{path}: expected "format": "{FORMAT}"')
    if doc.get("version") != VERSION:
        raise DataFileError(
            f"{path}: unsupported version {doc.get('version')!r}, expected {VERSION}"
        )
    frames = doc.get("frames")
    if not isinstance(frames, list) or not frames:
        raise DataFileError(f'{path}: "frames" must be a non-empty list')
    if len(frames) > MAX_FRAMES:
        raise DataFileError(f"{path}: {len(frames)} frames, more than the {MAX_FRAMES} accepted")
    if not isinstance(doc.get("meta", {}) or {}, dict):
        raise DataFileError(f'{path}: "meta" must be an object, got {type(doc["meta"]).__name__}')
    if not isinstance(doc.get("id", ""), str | None):
        raise DataFileError(f'{path}: "id" must be a string, got {doc["id"]!r:.60}')
    _check_sidecar_times(doc, path)
    return doc


MAX_TIME_S = 1e7
"""Largest ``time_s`` of a frame in ``sequence.json``, in size (about 116 days)."""


def _check_sidecar_times(doc: dict[str, Any], path: Path) -> None:
    """Types and ranges of ``epoch`` and each frame's ``time``/``time_s``, before any is used."""
    import math

    def instant(value: object, what: str) -> None:
        if not isinstance(value, str):
            raise DataFileError(f"{path}: {what}: expected an ISO-8601 UTC time, got {value!r:.60}")
        try:
            when = parse_time(value)
        except (InvalidParameterError, OverflowError) as exc:
            raise DataFileError(f"{path}: {what}: {exc}") from None
        if not 1900 <= when.year <= 2200:
            raise DataFileError(f"{path}: {what}: {value!r} is outside the years 1900..2200")

    if doc.get("epoch") is not None:
        instant(doc["epoch"], "epoch")
    for i, entry in enumerate(doc["frames"]):
        if not isinstance(entry, dict):
            continue  # read_sequence names it
        if not isinstance(entry.get("file", ""), str):
            raise DataFileError(
                f"{path}: frame {i}: file must be a name, got {entry['file']!r:.60}"
            )
        if "time_s" in entry:
            t = entry["time_s"]
            ok = isinstance(t, int | float) and not isinstance(t, bool)
            if not (ok and math.isfinite(t) and abs(t) <= MAX_TIME_S):
                raise DataFileError(
                    f"{path}: frame {i}: time_s must be finite seconds within "
                    f"{MAX_TIME_S:g} of the epoch, got {t!r:.60}"
                )
        elif "time" in entry:
            instant(entry["time"], f"frame {i}: time")


def read_sequence(
    directory: str | os.PathLike[str], *, scale: float | None = None, factor: int = 1
) -> FrameSequence:
    """Read one sequence folder (with or without ``sequence.json``) as a :class:`FrameSequence`.

    ``factor`` reads every frame straight onto the WFOV grid (see
    :func:`dyntarget.io.read_scene`). The sequence's ``meta`` holds what the
    sidecar stored (e.g. the world spec); no truth provider is attached here.

    Parameters
    ----------
    directory : str or os.PathLike
        The sequence folder.
    scale : float or None
        Reflectance per digital number for integer images.
    factor : int
        High-resolution pixels per WFOV pixel.

    Returns
    -------
    FrameSequence
        The frames with their times.
    """
    folder = Path(directory)
    if not folder.is_dir():
        raise DataFileError(f"{folder}: not a directory")
    sidecar = folder / SEQUENCE_FILE
    if sidecar.exists():
        doc = _load_sidecar(sidecar)
        epoch = doc.get("epoch")
        files, times = [], []
        for entry in doc["frames"]:
            if not isinstance(entry, dict) or "file" not in entry:
                raise DataFileError(f'{sidecar}: every frame needs a "file"')
            name = str(entry["file"])
            if "/" in name or "\\" in name or name.startswith("."):
                raise DataFileError(f"{sidecar}: frame file {name!r} must be a plain file name")
            if "time_s" in entry:
                try:
                    t = float(entry["time_s"])
                except (TypeError, ValueError):
                    raise DataFileError(
                        f"{sidecar}: frame {name}: time_s must be a number, got {entry['time_s']!r}"
                    ) from None
            elif "time" in entry:
                if epoch is None:
                    epoch = entry["time"]
                t = _seconds(epoch, entry["time"], sidecar)
            else:
                raise DataFileError(f"{sidecar}: frame {name} has neither time_s nor time")
            files.append(folder / name)
            times.append(t)
        meta = doc.get("meta") or {}
        seq_id = str(doc.get("id") or folder.name)
    else:
        files = sorted(
            p
            for p in folder.glob("*.tif")
            if not p.stem.endswith(MASK_SUFFIX) and not p.name.startswith(".")
        )
        if not files:
            raise DataFileError(f"{folder}: no frames (*.tif) and no {SEQUENCE_FILE}")
        parsed = [_frame_time(p) for p in files]  # dyntarget.io.acquisition's one order
        epoch_dt = min(parsed)
        order = sorted(range(len(files)), key=lambda i: parsed[i])
        files = [files[i] for i in order]
        times = [(parsed[i] - epoch_dt).total_seconds() for i in order]
        epoch, meta, seq_id = format_time(epoch_dt), {}, folder.name
    for f in files:
        if not f.exists():
            raise DataFileError(f"{f}: frame listed in {SEQUENCE_FILE} is missing")
    frames = [read_scene(f, scale=scale, factor=factor) for f in files]
    try:
        return FrameSequence(frames, times, epoch=epoch, id=seq_id, meta=meta)
    except (InvalidSceneError, InvalidParameterError) as exc:
        raise InvalidSceneError(f"{folder}: {exc}") from None


def _seconds(epoch: str, when: str, where: Path) -> float:
    try:
        return seconds_between(epoch, when)
    except InvalidParameterError as exc:
        raise DataFileError(f"{where}: {exc}") from None


def is_sequence_dir(directory: str | os.PathLike[str]) -> bool:
    """Whether ``directory`` holds sequence folders (sub-folders with ``sequence.json``).

    Parameters
    ----------
    directory : str or os.PathLike
        The folder to inspect.

    Returns
    -------
    bool
        False for anything but a directory.
    """
    d = Path(directory)
    return d.is_dir() and any((p / SEQUENCE_FILE).exists() for p in d.iterdir() if p.is_dir())


def sequence_ids(directory: str | os.PathLike[str]) -> list[str]:
    """Sorted names of the sequence folders (with ``sequence.json`` or ``*.tif``) in ``directory``.

    Parameters
    ----------
    directory : str or os.PathLike
        The sequence directory.

    Returns
    -------
    list of str
        The folder names (hidden folders excluded).
    """
    d = Path(directory)
    if not d.is_dir():
        raise DataFileError(f"{d}: not a directory")
    return sorted(
        p.name
        for p in d.iterdir()
        if p.is_dir()
        and not p.name.startswith(".")
        and ((p / SEQUENCE_FILE).exists() or any(p.glob("*.tif")))
    )


def read_sequence_dir(
    directory: str | os.PathLike[str], *, scale: float | None = None, factor: int = 1
) -> list[FrameSequence]:
    """Read every sequence folder of a sequence directory, sorted by name.

    Parameters
    ----------
    directory : str or os.PathLike
        The sequence directory.
    scale : float or None
        Reflectance per digital number for integer images.
    factor : int
        High-resolution pixels per WFOV pixel.

    Returns
    -------
    list of FrameSequence
        The sequences.

    Raises
    ------
    dyntarget.errors.DataFileError
        When it holds no sequence.
    """
    ids = sequence_ids(directory)
    if not ids:
        raise DataFileError(
            f"{directory}: no sequences (sub-folders with {SEQUENCE_FILE} or *.tif frames)"
        )
    return [read_sequence(Path(directory) / i, scale=scale, factor=factor) for i in ids]
