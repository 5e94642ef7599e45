"""Volcano catalogs: the one reader of a Smithsonian GVP volcano list.

A CSV with the columns of the Global Volcanism Program's *Volcanoes of the World*
export (``volcano_number``, ``volcano_name``, ``latitude``, ``longitude`` in WGS 84
degrees, ``elevation_m``, ``last_known_eruption`` such as ``2025 CE``, ``8300 BCE`` or
``Unknown``; other columns ignored). :func:`read_catalog` reads it into a columnar
:class:`Catalog`; ``latitude`` and ``longitude`` are always required, the other
columns as the caller asks (``require``). A row with a missing, non-numeric or
out-of-range field, an unreadable eruption year or a repeated volcano number is
refused with one line naming the file, the row (its line number, and its name when
it has one) and the field. Files are read through :func:`dyntarget.io.safeopen.read_text`
(a regular file of at most :data:`MAX_BYTES`), at most :data:`MAX_ROWS` volcanoes.

Used by ``dyntarget constellation --volcanoes`` (every column required) and by
``fly --geo-prior CATALOG`` (:mod:`dyntarget.geo.catalog`).
"""

from __future__ import annotations

import csv
import io
import math
import os
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dyntarget.errors import DataFileError

COLUMNS = ("latitude", "longitude")
"""Columns every catalog must have."""
OPTIONAL = ("volcano_number", "volcano_name", "elevation_m", "last_known_eruption")
"""Columns read when present (a caller may require them)."""
MAX_ROWS = 100_000
"""Most volcanoes in one catalog (the GVP Holocene list has 1,250)."""
MAX_BYTES = 256 << 20
"""Largest catalog file read, bytes."""
ELEVATION_RANGE_M = (-11_000.0, 9_000.0)
"""Summit elevations accepted, metres (the deepest trench to above Everest)."""
_YEAR = re.compile(r"^\s*(\d{1,5})\s*(CE|BCE)\s*$", re.IGNORECASE)


@dataclass(frozen=True)
class Catalog:
    """Volcanoes as arrays, one entry per catalog row in file order.

    Parameters
    ----------
    number : numpy.ndarray
        GVP volcano numbers (int64; -1 where the catalog has no ``volcano_number`` column).
    name : tuple of str
        Volcano names (``"line N"`` where the row has none).
    lat, lon : numpy.ndarray
        WGS 84 latitude and longitude, degrees.
    elevation_m : numpy.ndarray
        Summit elevation, metres (NaN where the catalog has no ``elevation_m`` column).
    last_year : numpy.ndarray
        Year of the last known eruption, astronomical (1 BCE is 0, 8300 BCE is -8299;
        float64, NaN if unknown).
    """

    number: np.ndarray
    name: tuple[str, ...]
    lat: np.ndarray
    lon: np.ndarray
    elevation_m: np.ndarray
    last_year: np.ndarray

    def __len__(self) -> int:
        return len(self.lat)


def eruption_year(text: str) -> int | None:
    """The year of a GVP ``last_known_eruption`` (``None`` for unknown).

    Parameters
    ----------
    text : str
        ``"2025 CE"``, ``"8300 BCE"``, ``"Unknown"`` or empty.

    Returns
    -------
    int or None
        Astronomical year (1 BCE is 0).

    Raises
    ------
    ValueError
        For anything else.

    Examples
    --------
    >>> eruption_year("2025 CE"), eruption_year("8300 BCE"), eruption_year("Unknown")
    (2025, -8299, None)
    """
    t = (text or "").strip()
    if not t or t.lower() == "unknown":
        return None
    m = _YEAR.match(t)
    if m is None:
        raise ValueError(f"expected a year such as '2025 CE' or '8300 BCE', got {text!r:.40}")
    year = int(m.group(1))
    return year if m.group(2).upper() == "CE" else 1 - year


def parse_catalog(text: str, *, source: str = "catalog", require: tuple[str, ...] = ()) -> Catalog:
    """Read a volcano catalog from CSV text, checking every row (module docstring).

    Parameters
    ----------
    text : str
        The CSV text, a header row first.
    source : str
        How messages name the file (its path).
    require : tuple of str
        Columns of :data:`OPTIONAL` that must be there too (each row's field then
        must be filled; ``volcano_name`` may still be empty).

    Returns
    -------
    Catalog
        The volcanoes.

    Raises
    ------
    dyntarget.errors.DataFileError
        One line naming the file, the row and the field.

    Examples
    --------
    >>> head = "volcano_number,volcano_name,latitude,longitude,elevation_m,last_known_eruption\\n"
    >>> c = parse_catalog(head + "332010,Kilauea,19.421,-155.287,1222,2025 CE\\n")
    >>> c.number.tolist(), c.name, float(c.elevation_m[0]), float(c.last_year[0])
    ([332010], ('Kilauea',), 1222.0, 2025.0)
    >>> parse_catalog(head + "1,A,95,0,0,Unknown\\n", source="v.csv")
    Traceback (most recent call last):
    ...
    dyntarget.errors.DataFileError: catalog v.csv: row at line 2 (A): latitude 95 is outside [-90, 90]
    """
    unknown = [c for c in require if c not in OPTIONAL]
    if unknown:
        raise ValueError(f"require: unknown column(s) {', '.join(unknown)}")
    try:
        reader = csv.DictReader(io.StringIO(text.removeprefix("\ufeff"), newline=""))
        fields = [f.strip() for f in reader.fieldnames or []]
        needed = [*COLUMNS, *require]
        missing = [c for c in needed if c not in fields]
        if missing:
            raise DataFileError(
                f"catalog {source}: no {' or '.join(repr(c) for c in missing)} column "
                f"(line 1 has: {', '.join(fields)[:120] or 'nothing'})"
            )
        reader.fieldnames = fields
        has = {c: c in fields for c in OPTIONAL}
        nums: list[int] = []
        names: list[str] = []
        vals: list[tuple[float, float, float, float]] = []
        seen: dict[int, int] = {}
        for row in reader:
            if len(vals) >= MAX_ROWS:
                raise DataFileError(f"catalog {source}: more than {MAX_ROWS} volcanoes")
            line = reader.line_num
            name = (row.get("volcano_name") or "").strip()
            where = f"catalog {source}: row at line {line}" + (f" ({name[:60]})" if name else "")
            lat = _number(where, row, "latitude", -90.0, 90.0)
            lon = _number(where, row, "longitude", -180.0, 180.0)
            elev = math.nan
            if has["elevation_m"] and (
                "elevation_m" in require or (row.get("elevation_m") or "").strip()
            ):
                elev = _number(where, row, "elevation_m", *ELEVATION_RANGE_M)
            num = -1
            raw = (row.get("volcano_number") or "").strip()
            if raw or "volcano_number" in require:
                num = _volcano_number(where, raw)
                if num in seen:
                    raise DataFileError(
                        f"{where}: volcano_number {num} repeats the row at line {seen[num]}"
                    )
                seen[num] = line
            try:
                year = eruption_year(row.get("last_known_eruption") or "")
            except ValueError as exc:
                raise DataFileError(f"{where}: last_known_eruption: {exc}") from None
            nums.append(num)
            names.append(name or f"line {line}")
            vals.append((lat, lon, elev, math.nan if year is None else float(year)))
    except csv.Error as exc:
        raise DataFileError(f"catalog {source}: not a CSV file ({exc})") from None
    if not vals:
        raise DataFileError(f"catalog {source}: no volcanoes")
    arr = np.asarray(vals, np.float64).reshape(-1, 4)
    return Catalog(
        np.asarray(nums, np.int64), tuple(names), arr[:, 0], arr[:, 1], arr[:, 2], arr[:, 3]
    )


def read_catalog(
    path: str | os.PathLike[str], *, require: tuple[str, ...] = (), what: str = "catalog"
) -> Catalog:
    """:func:`parse_catalog` of a file, read with a size bound (:data:`MAX_BYTES`).

    Parameters
    ----------
    path : str or os.PathLike
        The CSV file.
    require : tuple of str
        Columns of :data:`OPTIONAL` that must be there (see :func:`parse_catalog`).
    what : str
        How a read error names the file (an option such as ``--volcanoes``).

    Returns
    -------
    Catalog
        The volcanoes.

    Raises
    ------
    dyntarget.errors.DataFileError
        The file cannot be read, is too large, is not UTF-8 text, or a row is wrong.

    Examples
    --------
    >>> import tempfile
    >>> p = Path(tempfile.mkdtemp()) / "v.csv"
    >>> _ = p.write_text("volcano_name,latitude,longitude\\nKilauea,19.421,-155.287\\n")
    >>> c = read_catalog(p)
    >>> len(c), c.number.tolist(), bool(np.isnan(c.elevation_m[0]))
    (1, [-1], True)
    """
    from dyntarget.io.safeopen import read_text

    try:
        text = read_text(path, max_bytes=MAX_BYTES, what=what)
    except OSError as exc:
        raise DataFileError(
            f"{what} {path}: cannot read it ({getattr(exc, 'strerror', None) or exc})"
        ) from None
    return parse_catalog(text, source=str(Path(path)), require=require)


def _number(where: str, row: dict[str, str | None], field: str, lo: float, hi: float) -> float:
    text = (row.get(field) or "").strip()
    if not text:
        raise DataFileError(f"{where}: {field} is missing")
    try:
        v = float(text)
    except ValueError:
        raise DataFileError(f"{where}: {field} {text[:40]!r} is not a number") from None
    if not (math.isfinite(v) and lo <= v <= hi):
        raise DataFileError(f"{where}: {field} {text[:40]} is outside [{lo:g}, {hi:g}]")
    return v


def _volcano_number(where: str, text: str) -> int:
    try:
        num = int(text)
    except ValueError:
        num = -1
    if num < 0 or not text.strip().lstrip("+").isdigit():
        raise DataFileError(f"{where}: volcano_number {text[:40]!r} is not an integer >= 0")
    return num
