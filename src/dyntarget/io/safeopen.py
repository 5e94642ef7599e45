"""Open input files safely: regular files only, of bounded size; JSON of bounded depth.

Every small file dyntarget reads (sidecars, ``sequence.json``, ``metadata.json``,
label exports) goes through :func:`read_json`, and every raster is checked with
:func:`check_regular` before GDAL opens it. A FIFO, a device (a link to
``/dev/zero``), a directory or a dangling link is refused at once instead of
blocking or reading forever; a file larger than its limit is refused before it
is read; JSON nested deeper than :data:`MAX_JSON_DEPTH` is refused with one line
instead of a ``RecursionError``.
"""

from __future__ import annotations

import json
import os
import stat
from pathlib import Path
from typing import Any

from dyntarget.errors import DataFileError

MAX_JSON_BYTES = 16 * 1024 * 1024
"""Largest JSON side file read (16 MiB): sidecars and metadata are a few kB."""

MAX_JSON_DEPTH = 64
"""Deepest nesting of arrays and objects accepted in a JSON side file."""


def check_regular(
    path: str | os.PathLike[str], *, what: str = "", max_bytes: int | None = None
) -> int:
    """Refuse anything but an existing regular file (after links) of at most ``max_bytes``.

    Nothing is opened: a FIFO or a device is refused by :func:`os.stat` alone.

    Parameters
    ----------
    path : str or os.PathLike
        The file.
    what : str
        How the message names it (e.g. ``"--scene"``); default: just the path.
    max_bytes : int or None
        Largest size accepted.

    Returns
    -------
    int
        The file's size in bytes.

    Raises
    ------
    dyntarget.errors.DataFileError
        Missing, a dangling link, not a regular file, or too large.

    Examples
    --------
    >>> import tempfile
    >>> p = Path(tempfile.mkdtemp()) / "a.json"; _ = p.write_text("{}")
    >>> check_regular(p)
    2
    >>> check_regular(p.parent)
    Traceback (most recent call last):
    ...
    dyntarget.errors.DataFileError: ...: a directory, not a regular file
    """
    name = f"{what} {path}" if what else str(path)
    try:
        st = os.stat(path)
    except FileNotFoundError:
        kind = "a dangling link" if os.path.islink(path) else "no such file"
        raise DataFileError(f"{name}: {kind}") from None
    except OSError as exc:
        raise DataFileError(f"{name}: cannot be read ({exc.strerror or exc})") from None
    if not stat.S_ISREG(st.st_mode):
        raise DataFileError(f"{name}: {_kind(st.st_mode)}, not a regular file")
    if max_bytes is not None and st.st_size > max_bytes:
        raise DataFileError(
            f"{name}: {st.st_size:,} bytes, more than the {max_bytes:,} accepted for it"
        )
    return int(st.st_size)


def _kind(mode: int) -> str:
    for test, kind in (
        (stat.S_ISDIR, "a directory"),
        (stat.S_ISFIFO, "a FIFO (named pipe)"),
        (stat.S_ISCHR, "a character device"),
        (stat.S_ISBLK, "a block device"),
        (stat.S_ISSOCK, "a socket"),
    ):
        if test(mode):
            return kind
    return "a special file"


def read_bytes(path: str | os.PathLike[str], *, max_bytes: int, what: str = "") -> bytes:
    """The content of a regular file of at most ``max_bytes`` (checked before and while reading).

    The file is opened with ``O_NONBLOCK`` (a FIFO swapped in after the check cannot
    block the open) and checked again on the open descriptor.

    Parameters
    ----------
    path : str or os.PathLike
        The file.
    max_bytes : int
        Largest size accepted.
    what : str
        How the message names it.

    Returns
    -------
    bytes
        The content.

    Examples
    --------
    >>> import tempfile
    >>> p = Path(tempfile.mkdtemp()) / "a.txt"; _ = p.write_bytes(b"abc")
    >>> read_bytes(p, max_bytes=10)
    b'abc'
    """
    check_regular(path, what=what, max_bytes=max_bytes)
    name = f"{what} {path}" if what else str(path)
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    except OSError as exc:
        raise DataFileError(f"{name}: cannot be read ({exc.strerror or exc})") from None
    with os.fdopen(fd, "rb") as f:
        st = os.fstat(f.fileno())
        if not stat.S_ISREG(st.st_mode):
            raise DataFileError(f"{name}: {_kind(st.st_mode)}, not a regular file")
        # read what the file holds (plus one byte, to see it grow), not max_bytes: a read
        # of n bytes allocates n first, so a 16-byte file read with a 1 GB limit cost 1 GB
        data = f.read(min(max_bytes, st.st_size) + 1)
        if len(data) > st.st_size and len(data) <= max_bytes:  # grew while read
            data += f.read(max_bytes + 1 - len(data))
    if len(data) > max_bytes:
        raise DataFileError(f"{name}: more than the {max_bytes:,} bytes accepted for it")
    return data


def read_text(
    path: str | os.PathLike[str], *, max_bytes: int = MAX_JSON_BYTES, what: str = ""
) -> str:
    """UTF-8 text of a regular file of at most ``max_bytes``.

    Parameters
    ----------
    path : str or os.PathLike
        The file.
    max_bytes : int
        Largest size accepted.
    what : str
        How the message names it.

    Returns
    -------
    str
        The text.

    Examples
    --------
    >>> import tempfile
    >>> p = Path(tempfile.mkdtemp()) / "a.txt"; _ = p.write_text("hé")
    >>> read_text(p)
    'hé'
    """
    data = read_bytes(path, max_bytes=max_bytes, what=what)
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        name = f"{what} {path}" if what else str(path)
        raise DataFileError(f"{name}: not UTF-8 text ({exc.reason} at byte {exc.start})") from None


def loads_json(text: str | bytes, *, where: str = "JSON", max_depth: int = MAX_JSON_DEPTH) -> Any:
    """Parse JSON, refusing documents nested deeper than ``max_depth`` before parsing them.

    The depth is counted on the text (brackets outside strings), so a document
    nested 100,000 levels deep is refused without recursing.

    Parameters
    ----------
    text : str or bytes
        The JSON text.
    where : str
        How the message names the document (a path).
    max_depth : int
        Deepest nesting of arrays and objects accepted.

    Returns
    -------
    object
        The parsed document.

    Raises
    ------
    dyntarget.errors.DataFileError
        Not JSON, or nested too deeply.

    Examples
    --------
    >>> loads_json('{"a": [1, {"b": 2}]}')
    {'a': [1, {'b': 2}]}
    >>> loads_json("[" * 100000 + "]" * 100000)
    Traceback (most recent call last):
    ...
    dyntarget.errors.DataFileError: JSON: nested more than 64 levels deep; not a dyntarget file
    """
    if isinstance(text, bytes):
        try:
            text = text.decode("utf-8")
        except UnicodeDecodeError as exc:
            raise DataFileError(f"{where}: not UTF-8 text ({exc.reason})") from None
    if _depth(text) > max_depth:
        raise DataFileError(
            f"{where}: nested more than {max_depth} levels deep; not a dyntarget file"
        )
    try:
        return json.loads(text)
    except RecursionError:  # pragma: no cover - the depth check comes first
        raise DataFileError(f"{where}: nested too deeply") from None
    except ValueError as exc:
        raise DataFileError(f"{where}: not valid JSON ({exc})") from None


def _depth(text: str) -> int:
    """Deepest bracket nesting of ``text`` outside JSON strings (C-speed per string run)."""
    import re

    # drop strings (with their escapes), then count brackets cumulatively
    bare = re.sub(r'"(?:[^"\\]|\\.)*"', "", text)
    if "[" not in bare and "{" not in bare:
        return 0
    import numpy as np

    codes = np.frombuffer(bare.encode("utf-8", "surrogatepass"), np.uint8)
    steps = (codes == ord("[")).astype(np.int32) + (codes == ord("{"))
    steps -= (codes == ord("]")).astype(np.int32) + (codes == ord("}"))
    return int(np.cumsum(steps).max(initial=0))


def read_json(
    path: str | os.PathLike[str],
    *,
    max_bytes: int = MAX_JSON_BYTES,
    max_depth: int = MAX_JSON_DEPTH,
    what: str = "",
) -> Any:
    """A JSON side file: regular, at most ``max_bytes``, nested at most ``max_depth`` deep.

    Parameters
    ----------
    path : str or os.PathLike
        The file.
    max_bytes : int
        Largest size accepted.
    max_depth : int
        Deepest nesting accepted.
    what : str
        How the message names it.

    Returns
    -------
    object
        The parsed document.

    Raises
    ------
    dyntarget.errors.DataFileError
        Not a regular file, too large, not UTF-8 JSON, nested too deeply.

    Examples
    --------
    >>> import tempfile
    >>> p = Path(tempfile.mkdtemp()) / "a.json"; _ = p.write_text('{"x": 1}')
    >>> read_json(p)
    {'x': 1}
    """
    text = read_text(path, max_bytes=max_bytes, what=what)
    return loads_json(text, where=f"{what} {path}" if what else str(path), max_depth=max_depth)


def writable_dir(path: str | os.PathLike[str], *, what: str = "") -> Path:
    """The nearest existing folder at or above ``path``; refuse it unless this user may write there.

    Parameters
    ----------
    path : str or os.PathLike
        An output folder or file (it need not exist yet).
    what : str
        How the message names it (e.g. ``"--out"``).

    Returns
    -------
    pathlib.Path
        The existing folder that will hold the output.

    Raises
    ------
    dyntarget.errors.DataFileError
        When that folder is not writable (or a file is in the way).

    Examples
    --------
    >>> import tempfile
    >>> d = Path(tempfile.mkdtemp())
    >>> writable_dir(d / "new" / "deeper") == d
    True
    """
    from dyntarget.io.outputs import OutputPathError

    name = f"{what} {path}" if what else str(path)
    p = Path(path).absolute()
    probe = p
    while not probe.exists() and not probe.is_symlink():
        if probe.parent == probe:
            break
        probe = probe.parent
    if probe != p and not probe.is_dir():
        raise OutputPathError(f"{name}: {probe} is not a folder; nothing written")
    folder = probe if probe.is_dir() else probe.parent
    why = None if os.access(folder, os.W_OK | os.X_OK) else "permission denied"
    if why is None:  # root passes os.access everywhere: try it (read-only mounts, /sys)
        import tempfile

        try:
            with tempfile.TemporaryFile(dir=folder, prefix=".dyntarget-probe-"):
                pass
        except OSError as exc:
            why = exc.strerror or type(exc).__name__
    if why is not None:
        raise OutputPathError(
            f"{name}: cannot write in {folder} ({why}); nothing written (choose another path)"
        )
    return folder


def raster_size(path: str | os.PathLike[str]) -> tuple[int, int] | None:
    """``(height, width)`` from a raster's header (no pixel read); ``None`` if GDAL cannot open it.

    Parameters
    ----------
    path : str or os.PathLike
        The raster; refused first unless a regular file (:func:`check_regular`).

    Returns
    -------
    tuple of int or None
        Rows and columns.

    Examples
    --------
    >>> import tempfile
    >>> p = Path(tempfile.mkdtemp()) / "x.tif"; _ = p.write_bytes(b"not a tiff")
    >>> raster_size(p) is None
    True
    """
    import warnings

    import rasterio
    import rasterio.errors

    check_regular(path)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            with rasterio.open(path) as src:
                return int(src.height), int(src.width)
    except rasterio.errors.RasterioError:
        return None
