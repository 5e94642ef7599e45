"""The output-path rule: a path the user gave is never moved, replaced or deleted unless it is ours.

Every command that writes calls these checks *before any work* (and ``plan``
checks all of its outputs before writing any):

* an output **file** that does not exist, or exists and is empty, is fine; an
  existing file is replaced (atomically, :mod:`dyntarget.io.atomic`) only when
  its content shows that dyntarget wrote it (:func:`is_ours`); a directory in
  its place, or any other file, is refused;
* an output **folder** (scene directory, evaluation output) that does not exist
  or is empty is claimed: created, with a marker file :data:`MARKER` in it;
  an existing folder is written into only when it holds that marker; an
  existing file in its place is refused;
* a **model directory** is replaced (atomically, by
  :meth:`~dyntarget.perceive.base.Classifier.save`) only when it holds a
  dyntarget ``metadata.json`` (or is empty).

A refusal is an :class:`OutputPathError` (exit 2) naming the path, what is
there and what to do; nothing is touched.
"""

from __future__ import annotations

import contextlib
import json
import os
from collections.abc import Iterator
from pathlib import Path

from dyntarget.errors import DataFileError

MARKER = ".dyntarget-output"
"""File dyntarget writes into every output folder it creates (JSON: format, what)."""
MARKER_FORMAT = "dyntarget-output"
_SNIFF_BYTES = 1 << 16
"""How much of an existing file is read to recognise it."""
_BENCH_MARKDOWN = b"Pipeline (classify + denoise + plan"
"""First words of ``dyntarget bench --markdown`` (``evaluate.bench.summary_tables``)."""
_PNG_SOFTWARE = b"dyntarget"
"""Start of the PNG ``Software`` text chunk of dyntarget's figures."""


class OutputPathError(DataFileError):
    """An output path is taken by something dyntarget did not write."""


def _refuse(path: Path, what: str, found: str) -> OutputPathError:
    return OutputPathError(
        f"{what} {path}: {found}, not written by dyntarget; it is left as it is "
        "(remove it or choose another path)"
    )


def is_ours(path: str | os.PathLike[str]) -> bool:  # noqa: PLR0911  (one return per file kind)
    r"""Whether the existing file ``path`` was written by dyntarget (recognised by content).

    Recognised: trajectories and plume polygons (GeoJSON FeatureCollections
    whose ``properties`` hold ``planner`` or ``polygons``), CSV starting ``order,x,y,part``), figures (PNG with a
    ``Software: dyntarget`` text chunk), JSON documents with a top-level
    ``"dyntarget"`` key or bench results (``records`` and ``machine``), bench
    Markdown tables, HTML views (``<meta name="generator" content="dyntarget">``) and files
    that start with the marker ``<!-- dyntarget``.

    Parameters
    ----------
    path : str or os.PathLike
        The file to inspect.

    Returns
    -------
    bool
        False for a folder, a symbolic link or a missing file.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> d = pathlib.Path(tempfile.mkdtemp())
    >>> (d / "t.csv").write_text("order,x,y,part\n0,1.000,2.000,0\n")
    31
    >>> is_ours(d / "t.csv"), is_ours(d)
    (True, False)
    >>> (d / "notes.csv").write_text("name,phone\n")
    11
    >>> is_ours(d / "notes.csv")
    False
    """
    path = Path(path)
    if not path.is_file() or path.is_symlink():
        return False
    try:
        with path.open("rb") as f:
            head = f.read(_SNIFF_BYTES)
        size = path.stat().st_size
    except OSError:
        return False
    if head.startswith(b"\x89PNG\r\n\x1a\n"):
        return b"Software\x00" + _PNG_SOFTWARE in head
    if head.startswith(b"order,x,y,part"):
        return True
    if head.startswith((b"<!-- dyntarget", _BENCH_MARKDOWN)):
        return True
    if head.lstrip()[:15].lower() == b"<!doctype html>":  # HTML views carry a generator tag
        return b'<meta name="generator" content="dyntarget">' in head
    if head.lstrip()[:1] == b"{" and size <= 256 * _SNIFF_BYTES:
        try:
            doc = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, ValueError, RecursionError):
            return False
        if not isinstance(doc, dict):
            return False
        props = doc.get("properties")
        if doc.get("type") == "FeatureCollection" and isinstance(props, dict):
            return "planner" in props or "polygons" in props  # trajectories, plume polygons
        return "dyntarget" in doc or ("records" in doc and "machine" in doc)
    return False


def check_output_file(path: str | os.PathLike[str], *, what: str = "output file") -> Path:
    """Refuse ``path`` unless it is free, an empty file, or a file dyntarget wrote.

    Parameters
    ----------
    path : path
        The file a command will write (atomically) later.
    what : str
        Named in the error, e.g. ``"--out"``.

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    OutputPathError
        When a directory, another kind of file, or a file dyntarget did not
        write is at ``path``; nothing is touched.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> d = pathlib.Path(tempfile.mkdtemp())
    >>> check_output_file(d / "new.geojson").name
    'new.geojson'
    >>> check_output_file(d, what="--figure")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    dyntarget.io.outputs.OutputPathError: --figure ...: a directory, not written by dyntarget; ...
    """
    path = Path(path)
    if path.is_symlink() or path.exists():
        if path.is_dir():
            raise _refuse(path, what, "a directory")
        if not path.is_file():
            raise _refuse(path, what, "not a regular file")
        if path.stat().st_size and not is_ours(path):
            raise _refuse(path, what, "an existing file")
    if path.parent.exists() and not path.parent.is_dir():
        raise _refuse(path.parent, f"folder of {what}", "a file")
    return path


def _dir_state(path: Path) -> str:
    """``"free"``, ``"ours"``, or what is there instead."""
    if path.is_symlink() and not path.exists():
        return "a broken link"
    if not path.exists():
        for parent in path.parents:  # a file part-way up the path
            if parent.exists():
                return "free" if parent.is_dir() else f"below a file ({parent})"
        return "free"
    if not path.is_dir():
        return "an existing file"
    try:
        entries = list(path.iterdir())
    except OSError as exc:
        return f"an unreadable directory ({exc.strerror})"
    if not entries:
        return "free"
    # ours: marked, or inside a marked folder (e.g. the models of a demo's output folder)
    if any(_marked(d) for d in (path, *path.absolute().parents)):
        return "ours"
    return "a directory holding other files"


def _marked(directory: Path) -> bool:
    marker = directory / MARKER
    if not marker.is_file():
        return False
    try:
        doc = json.loads(marker.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError):
        return False
    return isinstance(doc, dict) and doc.get("format") == MARKER_FORMAT


def check_output_dir(path: str | os.PathLike[str], *, what: str = "output folder") -> Path:
    """Refuse ``path`` unless it is free, empty, or an output folder dyntarget made.

    Parameters
    ----------
    path : path
        The folder a command will write into.
    what : str
        Named in the error, e.g. ``"--out"``.

    Returns
    -------
    Path
        ``path`` (nothing is created; see :func:`claim_output_dir`).

    Raises
    ------
    OutputPathError
        When a file, or a non-empty folder without dyntarget's :data:`MARKER`, is there.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> d = pathlib.Path(tempfile.mkdtemp())
    >>> _ = (d / "holiday.jpg").write_bytes(b"...")
    >>> check_output_dir(d, what="--out")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    dyntarget.io.outputs.OutputPathError: --out ...: a directory holding other files, not ...
    """
    path = Path(path)
    state = _dir_state(path)
    if state not in ("free", "ours"):
        raise _refuse(path, what, state)
    return path


def claim_output_dir(path: str | os.PathLike[str], *, what: str = "output folder") -> Path:
    """:func:`check_output_dir`, then create ``path`` and mark it as dyntarget's.

    Parameters
    ----------
    path : str or os.PathLike
        The output folder.
    what : str
        What to call it in error messages.

    Returns
    -------
    Path
        ``path``, now an existing folder holding :data:`MARKER`.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> d = pathlib.Path(tempfile.mkdtemp()) / "out"
    >>> claim_output_dir(d).is_dir(), (d / MARKER).is_file()
    (True, True)
    >>> claim_output_dir(d) == d  # ours now: claimed again without complaint
    True
    """
    from dyntarget.io.atomic import write_text

    path = check_output_dir(path, what=what)
    path.mkdir(parents=True, exist_ok=True)
    if not (path / MARKER).is_file():
        doc = {"format": MARKER_FORMAT, "what": what}
        write_text(path / MARKER, json.dumps(doc, sort_keys=True) + "\n")
    return path


def check_model_dir(path: str | os.PathLike[str], *, what: str = "model directory") -> Path:
    """Refuse ``path`` unless it is free, an empty folder, or a dyntarget model directory.

    A model directory is recognised by its ``metadata.json`` (format
    ``dyntarget-model``); only such a directory is later replaced, atomically.

    Parameters
    ----------
    path : str or os.PathLike
        The model directory to write.
    what : str
        What to call it in the error message (e.g. the option, ``--out``).

    Returns
    -------
    pathlib.Path
        ``path``.

    Raises
    ------
    dyntarget.io.outputs.OutputPathError
        When ``path`` is something else.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> d = pathlib.Path(tempfile.mkdtemp())
    >>> _ = (d / "thesis.tex").write_text("...")
    >>> check_model_dir(d / "thesis.tex", what="--out")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    dyntarget.io.outputs.OutputPathError: --out ...: an existing file, not written by dyntarget; ...
    """
    path = Path(path)
    state = _dir_state(path)
    if state == "a directory holding other files":
        try:
            meta = json.loads((path / "metadata.json").read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, ValueError):
            meta = None
        if isinstance(meta, dict) and meta.get("format") == "dyntarget-model":
            return path
    if state not in ("free", "ours"):
        raise _refuse(path, what, state)
    return path


@contextlib.contextmanager
def output_dir(path: str | os.PathLike[str], *, what: str = "output folder") -> Iterator[Path]:
    """Claim an output folder for a command (:func:`claim_output_dir`); undo a fresh claim on failure.

    When the command fails and the folder did not exist before, it is removed
    again if it holds nothing but the marker and empty folders, so a refused
    run (an unreachable scheduler, bad input found late) leaves nothing behind.

    Parameters
    ----------
    path : str or os.PathLike
        The output folder.
    what : str
        What to call it in error messages.

    Yields
    ------
    pathlib.Path
        ``path``, claimed.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> d = pathlib.Path(tempfile.mkdtemp()) / "out"
    >>> try:
    ...     with output_dir(d) as out:
    ...         (out / "parts").mkdir()
    ...         raise RuntimeError("scheduler unreachable")
    ... except RuntimeError:
    ...     pass
    >>> d.exists()
    False
    """
    path = Path(path)
    fresh = not path.exists()
    claim_output_dir(path, what=what)
    try:
        yield path
    except BaseException:
        if fresh:
            _remove_if_only_marker(path)
        raise


def _remove_if_only_marker(path: Path) -> None:
    files = [p for p in path.rglob("*") if not p.is_dir()]
    if files and files != [path / MARKER]:
        return
    (path / MARKER).unlink(missing_ok=True)
    for d in sorted((p for p in path.rglob("*") if p.is_dir()), key=lambda p: -len(p.parts)):
        d.rmdir()
    path.rmdir()
