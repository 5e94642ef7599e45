"""When an image was acquired: parse ISO-8601, read it from image tags or a sidecar.

Inside the library time is seconds from the look-ahead acquisition; at the
edges (files, GeoJSON, HTML) it becomes an ISO-8601 UTC instant, e.g.
``2024-05-01T10:00:03.250Z``. The acquisition instant comes from, in this one order (``plan``, ``fly --watch``
and sequence folders without ``sequence.json`` all read it here, :func:`read_acquisition`):

1. the user (``--acquired 2024-05-01T10:00:00Z``);
2. a sidecar ``<image stem>.meta.json`` beside the image holding
   ``{"acquired": "2024-05-01T10:00:00Z"}``;
3. the image's tags, first found wins: ``DYNTARGET_TIME`` (what dyntarget writes
   on sequence frames, ``synth --frames``), ``DYNTARGET_ACQUIRED`` (older live-mode
   frames), ``ACQUISITIONDATETIME`` (GDAL's ``IMAGERY`` metadata domain, e.g.
   Sentinel-2 and DIMAP products), ``TIFFTAG_DATETIME`` (``YYYY:MM:DD
   HH:MM:SS``; TIFF gives no zone, taken as UTC as satellite products write it;
   last, since TIFF defines it as the file's creation time).

Nothing else: a file's modification time is never taken silently (the live mode
says so on stderr and in ``frames.csv`` when it falls back on it).
"""

from __future__ import annotations

import os
import re
from datetime import UTC, datetime, timedelta
from pathlib import Path

from dyntarget.errors import DataFileError, InvalidParameterError

TAGS = ("DYNTARGET_TIME", "DYNTARGET_ACQUIRED", "ACQUISITIONDATETIME", "TIFFTAG_DATETIME")
"""Image tags holding the acquisition time, in the order they are read."""
SIDECAR_SUFFIX = ".meta.json"
"""Suffix of the sidecar file that may hold ``{"acquired": ISO-8601}`` beside an image."""

_TIFF_DATETIME = re.compile(r"^(\d{4}):(\d{2}):(\d{2})[ T](\d{2}):(\d{2}):(\d{2})$")


def parse_acquired(text: str | datetime, *, name: str = "acquired") -> datetime:
    """An ISO-8601 instant as an aware UTC :class:`~datetime.datetime`.

    A time without a zone is taken as UTC; one with an offset is converted.

    Parameters
    ----------
    text : str or datetime
        ``2024-05-01T10:00:00Z``, ``2024-05-01T12:00:00+02:00``, ``2024-05-01 10:00``…
    name : str
        The argument's name, for the error message.

    Returns
    -------
    datetime
        Aware, in UTC.

    Raises
    ------
    InvalidParameterError
        When ``text`` is not an ISO-8601 date-time.

    Examples
    --------
    >>> parse_acquired("2024-05-01T12:00:00+02:00").isoformat()
    '2024-05-01T10:00:00+00:00'
    >>> parse_acquired("2024-05-01T10:00:00Z") == parse_acquired("2024-05-01 10:00")
    True
    """
    if isinstance(text, datetime):
        when = text
    else:
        if not isinstance(text, str):
            raise InvalidParameterError(
                f"{name}: expected an ISO-8601 date-time string, got {type(text).__name__}"
            )
        try:
            when = datetime.fromisoformat(text.strip())
        except ValueError:
            raise InvalidParameterError(
                f"{name}: expected an ISO-8601 date-time such as 2024-05-01T10:00:00Z, got {text!r}"
            ) from None
    if when.tzinfo is None:
        when = when.replace(tzinfo=UTC)
    return when.astimezone(UTC)


def iso_utc(acquired: datetime, seconds: float) -> str:
    """The instant ``seconds`` after ``acquired`` as ISO-8601 UTC with milliseconds and ``Z``.

    Parameters
    ----------
    acquired : datetime
        The acquisition instant (aware; naive is taken as UTC).
    seconds : float
        Seconds after it.

    Returns
    -------
    str

    Examples
    --------
    >>> iso_utc(parse_acquired("2024-05-01T10:00:00Z"), 63.25)
    '2024-05-01T10:01:03.250Z'
    >>> iso_utc(parse_acquired("2024-05-01T10:00:00Z"), 59.9996)
    '2024-05-01T10:01:00.000Z'
    """
    when = parse_acquired(acquired) + timedelta(seconds=float(seconds))
    # round (not truncate, as isoformat does) to the millisecond, like ``time_s``
    when = when.replace(microsecond=0) + timedelta(milliseconds=round(when.microsecond / 1000))
    return when.isoformat(timespec="milliseconds").replace("+00:00", "Z")


def read_acquired(path: str | os.PathLike[str]) -> datetime | None:
    """The acquisition instant of an image file, from its sidecar or tags; ``None`` if unknown.

    Parameters
    ----------
    path : path-like
        The image (GeoTIFF or anything GDAL reads). ``<stem>.meta.json`` beside it
        is read first when it exists.

    Returns
    -------
    datetime or None
        Aware, in UTC.

    Raises
    ------
    DataFileError
        When the sidecar exists but is not JSON with a valid ``acquired`` string,
        or a tag holds a time that cannot be read.

    Examples
    --------
    >>> import json, tempfile, pathlib
    >>> d = pathlib.Path(tempfile.mkdtemp())
    >>> _ = (d / "s.meta.json").write_text(json.dumps({"acquired": "2024-05-01T10:00:00Z"}))
    >>> read_acquired(d / "s.tif").isoformat()
    '2024-05-01T10:00:00+00:00'
    """
    return read_acquisition(path)[0]


def read_acquisition(path: str | os.PathLike[str]) -> tuple[datetime | None, str | None]:
    """:func:`read_acquired` and where the time came from (the sidecar's name or the tag).

    Parameters
    ----------
    path : path-like
        The image.

    Returns
    -------
    tuple
        ``(instant or None, source or None)``, e.g. ``(datetime, "DYNTARGET_TIME")``.

    Examples
    --------
    >>> read_acquisition("no-such-image.tif")
    (None, None)
    """
    path = Path(path)
    sidecar = path.with_name(path.stem + SIDECAR_SUFFIX)
    if sidecar.is_file():
        from dyntarget.io.safeopen import read_json  # bounded size and depth, never a FIFO

        doc = read_json(sidecar, what="acquisition sidecar")
        if not isinstance(doc, dict) or "acquired" not in doc:
            raise DataFileError(
                f"{sidecar}: expected a JSON object with an 'acquired' ISO-8601 time, got {doc!r:.80}"
            )
        try:
            return parse_acquired(doc["acquired"], name=f"{sidecar}: acquired"), sidecar.name
        except InvalidParameterError as exc:
            raise DataFileError(str(exc)) from None
    if not path.is_file():
        return None, None
    return _tag_time(path)


def _tag_time(path: Path) -> tuple[datetime | None, str | None]:
    import warnings

    import rasterio
    from rasterio.errors import NotGeoreferencedWarning, RasterioError

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", NotGeoreferencedWarning)
            with rasterio.open(path) as src:
                imagery = src.tags(ns="IMAGERY")
                default = src.tags()
    except RasterioError:
        return None, None  # not a raster GDAL reads (e.g. .npz): no tags to look at
    for key in TAGS:
        value = imagery.get(key) or default.get(key)
        if not value:
            continue
        value = value.strip()
        if key == "TIFFTAG_DATETIME" or _TIFF_DATETIME.match(value):
            m = _TIFF_DATETIME.match(value)
            if m is None:
                raise DataFileError(f"{path}: {key} {value!r} is not 'YYYY:MM:DD HH:MM:SS'")
            try:
                year, month, day, hour, minute, second = (int(g) for g in m.groups())
                return datetime(year, month, day, hour, minute, second, tzinfo=UTC), key
            except ValueError:
                raise DataFileError(f"{path}: {key} {value!r} is not a valid date") from None
        try:
            return parse_acquired(value, name=f"{path}: {key}"), key
        except InvalidParameterError as exc:
            raise DataFileError(str(exc)) from None
    return None, None
