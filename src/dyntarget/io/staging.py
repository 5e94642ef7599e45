"""Output staging: a command (or a campaign's pass) writes its files into a hidden folder
inside its output folder and moves them into place only when they are complete.

A failing or interrupted rerun therefore never destroys or mixes the previous
result: until :func:`commit`, ``--out`` holds exactly what it held before; a
failure removes the staging folder (:func:`discard`); an interrupted pass may be
kept there, clearly marked (``--out/.partial-XXXXXXXX``), when committing it
would replace a previous result. :func:`commit` moves every staged entry with
:func:`os.replace` (a rename within one file system) while SIGINT, SIGTERM and
SIGHUP are held back, and removes the files of the previous result that the new
one does not write (a rerun with ``--no-picture`` leaves no old ``pass.png``; a pass's
files are listed by :func:`dyntarget.view.pass_report.pass_files`).
"""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import tempfile
from collections.abc import Iterable, Iterator
from pathlib import Path

PREFIX = ".partial-"
"""Name prefix of staging folders inside an output folder."""
_HELD = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


def new_stage(out: str | os.PathLike[str]) -> Path:
    """A fresh, empty staging folder inside ``out`` (created if needed).

    Parameters
    ----------
    out : str or os.PathLike
        The output folder (claimed by the command already).

    Returns
    -------
    pathlib.Path
        ``out/.partial-XXXXXXXX``.

    Examples
    --------
    >>> d = Path(tempfile.mkdtemp())
    >>> new_stage(d).name.startswith(PREFIX)
    True
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    return Path(tempfile.mkdtemp(prefix=PREFIX, dir=out))


def discard(stage: str | os.PathLike[str]) -> None:
    """Remove a staging folder and everything in it (nothing else is touched).

    Parameters
    ----------
    stage : str or os.PathLike
        A folder from :func:`new_stage`.
    """
    shutil.rmtree(stage, ignore_errors=True)


@contextlib.contextmanager
def _signals_held() -> Iterator[None]:
    """Hold back SIGINT/SIGTERM/SIGHUP (delivered when the block ends)."""
    try:
        old = signal.pthread_sigmask(signal.SIG_BLOCK, _HELD)
    except (AttributeError, ValueError, OSError):  # not the main thread / not POSIX
        yield
        return
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


def commit(
    stage: str | os.PathLike[str], out: str | os.PathLike[str], *, stale: Iterable[str] = ()
) -> list[Path]:
    """Move everything staged into ``out``; remove the ``stale`` names it did not write.

    Parameters
    ----------
    stage : str or os.PathLike
        The staging folder (inside ``out``).
    out : str or os.PathLike
        The output folder.
    stale : iterable of str
        Names of files (or folders) a previous result may have left in ``out`` that
        belong to the same kind of result; those the new one does not write are removed.

    Returns
    -------
    list of pathlib.Path
        The entries now in ``out``, in name order.

    Examples
    --------
    >>> d = Path(tempfile.mkdtemp())
    >>> _ = (d / "pass.png").write_text("old"); _ = (d / "notes.txt").write_text("mine")
    >>> s = new_stage(d); _ = (s / "timeline.csv").write_text("new")
    >>> [p.name for p in commit(s, d, stale=["pass.png", "timeline.csv"])]
    ['timeline.csv']
    >>> sorted(p.name for p in d.iterdir())
    ['notes.txt', 'timeline.csv']
    """
    stage, out = Path(stage), Path(out)
    entries = sorted(stage.iterdir(), key=lambda p: p.name)
    names = {p.name for p in entries}
    trash: list[Path] = []
    with _signals_held():
        for entry in entries:
            target = out / entry.name
            if target.is_dir() and not target.is_symlink():
                old = Path(tempfile.mkdtemp(prefix=PREFIX + "old-", dir=out))
                os.replace(target, old / entry.name)
                trash.append(old)
            os.replace(entry, target)
        for name in stale:
            if name in names:
                continue
            target = out / name
            if target.is_dir() and not target.is_symlink():
                old = Path(tempfile.mkdtemp(prefix=PREFIX + "old-", dir=out))
                os.replace(target, old / name)
                trash.append(old)
            else:
                target.unlink(missing_ok=True)
        stage.rmdir()
    for old in trash:
        shutil.rmtree(old, ignore_errors=True)
    return [out / p.name for p in entries]


@contextlib.contextmanager
def staged(out: str | os.PathLike[str], *, stale: Iterable[str] = ()) -> Iterator[Path]:
    """Yield a staging folder inside ``out``; :func:`commit` it on success, discard it on failure.

    Parameters
    ----------
    out : str or os.PathLike
        The output folder.
    stale : iterable of str
        Passed to :func:`commit`.

    Yields
    ------
    pathlib.Path
        The folder to write into.

    Examples
    --------
    >>> d = Path(tempfile.mkdtemp())
    >>> with staged(d) as s:
    ...     _ = (s / "a.txt").write_text("1")
    >>> try:
    ...     with staged(d) as s:
    ...         _ = (s / "a.txt").write_text("2")
    ...         raise RuntimeError("late failure")
    ... except RuntimeError:
    ...     pass
    >>> (d / "a.txt").read_text(), sorted(p.name for p in d.iterdir())
    ('1', ['a.txt'])
    """
    stage = new_stage(out)
    try:
        yield stage
    except BaseException:
        discard(stage)
        raise
    commit(stage, out, stale=stale)
