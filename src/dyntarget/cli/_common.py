"""Shared pieces of the command modules: exit codes, the parser class, option helpers.

Exit codes: 0 success, 2 bad usage or bad input (any :class:`DynTargetError`),
1 internal error. No traceback is printed unless ``--debug`` is given.
"""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path
from typing import Any, NoReturn

from dyntarget.cli.options import (  # re-exported: defined once, in cli/options.py
    SCHEDULER_HELP,
    positive_float,
    positive_int,
    scheduler_address,
)

__all__ = ["SCHEDULER_HELP", "positive_float", "positive_int", "scheduler_address"]

EXIT_OK, EXIT_INTERNAL, EXIT_USAGE = 0, 1, 2
EXIT_NOTHING_FEASIBLE = 3
"""``plan --agility``: a plan was made but none of its pointings can be flown (the file is
written, with no pointing; the reason is on stderr)."""


class Parser(argparse.ArgumentParser):
    """argparse with one line for a usage error: ``dyntarget: error: ...`` and exit 2."""

    def error(self, message: str) -> NoReturn:  # argparse exits 2 as well; one line, no usage
        self.exit(EXIT_USAGE, f"dyntarget: error: {message} (see '{self.prog} --help')\n")


def preset_names() -> list[str]:
    from dyntarget.io.presets import PRESETS

    return list(PRESETS)


def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def plain_text(text: str) -> str:
    """A docstring line as plain text for a terminal: reST markup dropped.

    Parameters
    ----------
    text : str
        One line of reStructuredText (a docstring's summary).

    Returns
    -------
    str
        The line without inline literals, roles and references to private helpers.

    Examples
    --------
    >>> plain_text("Zig-zag every ``step`` (see :func:`_transects`).")
    'Zig-zag every step.'
    >>> plain_text("See :class:`~dyntarget.plan.PlanConfig` and *this*.")
    'See PlanConfig and this.'
    """
    text = re.sub(r"\s*\(see :\w+:`~?_[^`]*`\)", "", text)  # a private helper means nothing here
    text = re.sub(r":\w+:`~([^`]*\.)?([^`.]+)`", r"\2", text)  # :func:`~a.b.c` -> c
    text = re.sub(r":\w+:`([^`]*)`", r"\1", text)
    text = re.sub(r"``([^`]*)``", r"\1", text)
    return re.sub(r"(?<![\w*])\*{1,2}([^*]+)\*{1,2}(?![\w*])", r"\1", text)


def load_labelled(data: str) -> list:
    from dyntarget.io import read_scene_dir

    return read_scene_dir(data, require_labels=True)


def show_result(out: str, name: str, result: dict, columns: list[str]) -> None:
    """Write an evaluation's table (md, csv, json), print it, say where it went."""
    from dyntarget.evaluate.tables import markdown_table, write_result
    from dyntarget.io.staging import staged

    with staged(out, stale=_table_files(name)) as stage:  # the table's files move in together
        paths = write_result(stage, name, result, columns)
    print(markdown_table(result["rows"], columns))
    log("wrote " + ", ".join(str(Path(out) / p.name) for p in paths.values()))


def _table_files(stem: str) -> tuple[str, ...]:
    """The files of one evaluation table (:func:`dyntarget.evaluate.tables.write_table`)."""
    return tuple(f"{stem}{suffix}" for suffix in (".md", ".csv", ".json", ".timing.json"))


def plan_config(args: argparse.Namespace):
    from dyntarget.plan import PlanConfig

    return PlanConfig(step=args.step, width=args.width)


def add_evaluation_options(q: argparse.ArgumentParser, *, trains: bool = True) -> None:
    """Options the evaluations share; with ``trains``, those of training classifiers too."""
    from dyntarget.cli import options as o

    o.DATA.add(q)
    o.OUT.add(q, help="output folder for the table (md, csv, json)")
    o.FACTOR.add(q)
    o.QUIET.add(q)
    o.SCHEDULER.add(q)
    if trains:
        o.MODELS.add(q)
        o.FOLDS.add(q)
        o.EPOCHS.add(q)
        o.SEED.add(q)


def name_lists(**lists: str | None) -> dict[str, Any]:
    """Comma-separated CLI lists that were given, as keyword arguments of a config."""
    return {key: tuple(text.split(",")) for key, text in lists.items() if text}


def writes(
    *, dirs: tuple[str, ...] = (), files: tuple[str, ...] = (), model_dirs: tuple[str, ...] = ()
):
    """Decorate a command: check every output path it names *before any work*.

    ``dirs``/``files``/``model_dirs`` are argument names (``"out"`` -> ``args.out``;
    ``None`` values are skipped). Files and model directories are only checked
    (:func:`~dyntarget.io.outputs.check_output_file`,
    :func:`~dyntarget.io.outputs.check_model_dir`); folders are claimed for the
    command's run and released again if it fails having written nothing
    (:func:`~dyntarget.io.outputs.output_dir`). Two outputs on one path are refused.
    """
    import contextlib
    import functools
    from pathlib import Path

    def decorate(fn):
        @functools.wraps(fn)
        def run(args: argparse.Namespace) -> int:
            from dyntarget.errors import InvalidParameterError
            from dyntarget.io.outputs import (
                check_model_dir,
                check_output_dir,
                check_output_file,
                output_dir,
            )
            from dyntarget.io.safeopen import writable_dir

            given: list[tuple[str, str, str]] = [
                (kind, name, str(value))
                for kind, names in (("dir", dirs), ("file", files), ("model", model_dirs))
                for name in names
                if (value := getattr(args, name, None)) is not None
            ]
            seen: dict[Path, str] = {}
            for kind, name, value in given:
                flag = "--" + name.replace("_", "-")
                where = Path(value).absolute()
                if where in seen:
                    raise InvalidParameterError(
                        f"{flag} {value}: the same path as {seen[where]}; expected different outputs"
                    )
                seen[where] = flag
                check = {"dir": check_output_dir, "file": check_output_file}.get(
                    kind, check_model_dir
                )
                check(value, what=flag)
                writable_dir(value, what=flag)  # a PermissionError now, not after the work
            empty = [Path(v) for k, _, v in given if k == "dir" and _is_empty_dir(Path(v))]
            try:
                with contextlib.ExitStack() as stack:
                    for kind, name, value in given:
                        if kind == "dir":
                            flag = "--" + name.replace("_", "-")
                            stack.enter_context(output_dir(value, what=flag))
                    return fn(args)
            except BaseException:
                for d in empty:  # a refusal leaves an empty folder it was given empty
                    _unclaim(d)
                raise

        return run

    return decorate


def _is_empty_dir(path: Path) -> bool:
    try:
        return path.is_dir() and not path.is_symlink() and not any(path.iterdir())
    except OSError:
        return False


def _unclaim(path: Path) -> None:
    """Remove the marker from a folder that holds nothing else (it was given empty)."""
    from dyntarget.io.outputs import MARKER

    try:
        if [p.name for p in path.iterdir()] == [MARKER]:
            (path / MARKER).unlink()
    except OSError:
        pass


EARTH_RADIUS_M = 6_371_000.0
YEARS = (1900, 2200)
"""Acquisition years accepted (pointings are dated by adding seconds to the acquisition)."""


def check_acquired(when, what: str):
    """Refuse an acquisition instant outside :data:`YEARS`; return it (``None`` passes)."""
    from dyntarget.errors import InvalidParameterError

    if when is not None and not YEARS[0] <= when.year <= YEARS[1]:
        raise InvalidParameterError(
            f"{what}: acquired {when.isoformat()}, outside the years {YEARS[0]}..{YEARS[1]} "
            "dyntarget dates pointings in"
        )
    return when


def check_orbit(args: argparse.Namespace) -> None:
    """Refuse an altitude above 100 000 km or a look-ahead beyond the horizon seen from it."""
    import math

    from dyntarget.errors import InvalidParameterError

    alt = getattr(args, "altitude_km", None)
    ahead = getattr(args, "look_ahead_km", None)
    if alt is None or ahead is None:
        return
    if not 0 < alt <= 100_000:
        raise InvalidParameterError(f"--altitude-km {alt:g}: expected 0 < km <= 100000")
    r = EARTH_RADIUS_M / 1e3
    horizon = r * math.acos(r / (r + alt))
    if not math.isfinite(ahead) or abs(ahead) >= horizon:
        raise InvalidParameterError(
            f"--look-ahead-km {ahead:g}: beyond the horizon seen from {alt:g} km "
            f"({horizon:.0f} km of ground); expected less"
        )
