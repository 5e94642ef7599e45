"""The ``dyntarget`` command line: a thin layer over the library.

Exit codes: 0 success, 2 bad usage or bad input (any :class:`DynTargetError`),
1 internal error. No traceback is printed unless ``--debug`` is given.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable, Sequence

from dyntarget.cli import (
    bench,
    constellation,
    datasets,
    demo,
    evaluate,
    fly,
    models,
    plan,
    sweep,
    synth,
)
from dyntarget.cli._common import EXIT_INTERNAL, EXIT_OK, EXIT_USAGE, Parser
from dyntarget.errors import DynTargetError, missing_extra

COMMANDS = (synth, models, evaluate, plan, fly, constellation, sweep, bench, datasets, demo)
"""The command modules, in the order ``dyntarget --help`` lists them. Each has
``register(sub)``; to add a command, add a module with one and list it here."""


class _Version(argparse.Action):
    """``--version``: the installed version, read only when asked (``dyntarget.__version__``)."""

    def __init__(self, option_strings: Sequence[str], dest: str, **kwargs) -> None:
        kwargs.update(nargs=0, default=argparse.SUPPRESS)
        super().__init__(option_strings, dest, **kwargs)

    def __call__(self, parser, namespace, values, option_string=None) -> None:
        import dyntarget

        print(f"dyntarget {dyntarget.__version__}")
        parser.exit()


def build_parser() -> argparse.ArgumentParser:
    """The ``dyntarget`` argument parser, with every command of :data:`COMMANDS` registered.

    Returns
    -------
    argparse.ArgumentParser
        The parser; a usage error prints one line and exits with status 2.
    """
    parser = Parser(
        prog="dyntarget",
        description="Dynamic targeting of plumes: classify look-ahead imagery, denoise, plan NFOV trajectories.",
    )
    parser.add_argument("--version", action=_Version, help="show the version and exit")
    parser.add_argument("--debug", action="store_true", help="print full tracebacks on errors")
    sub = parser.add_subparsers(
        dest="command", required=True, metavar="COMMAND", parser_class=Parser
    )
    for command in COMMANDS:
        command.register(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``dyntarget`` console script; returns the exit code.

    Parameters
    ----------
    argv : sequence of str or None
        The arguments after the program name (default: ``sys.argv[1:]``).

    Returns
    -------
    int
        0 on success, 2 for bad usage or bad input (or a missing optional extra),
        1 for an internal error, 130 when interrupted.
    """
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help, --version and usage errors
        return int(exc.code or 0)
    func: Callable[[argparse.Namespace], int] = args.func
    from dyntarget.perceive.resources import bound_openmp_spin, keep_freed_memory

    keep_freed_memory()  # large arrays are reused, not page-faulted in on every pass
    bound_openmp_spin()  # before torch loads: a thread waiting at a barrier gives its core back
    try:
        return func(args)
    except DynTargetError as exc:
        if args.debug:
            raise
        print(f"dyntarget: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print("dyntarget: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # `dyntarget planners | head -1`: the reader has gone
        _silence_stdout()
        return EXIT_OK
    except RecursionError:  # a hostile input nested too deeply, wherever it was read
        if args.debug:
            raise
        print(
            "dyntarget: error: an input is nested too deeply to read (hostile or corrupt file?)",
            file=sys.stderr,
        )
        return EXIT_USAGE
    except Exception as exc:  # an internal error: one line unless --debug
        if args.debug:
            raise
        extra = missing_extra(exc) if isinstance(exc, ImportError) else None
        if extra is not None:  # an optional dependency is not installed: name the extra
            print(f"dyntarget: error: {extra}", file=sys.stderr)
            return EXIT_USAGE
        first = str(exc).splitlines()[0] if str(exc) else ""
        print(
            f"dyntarget: internal error: {type(exc).__name__}: {first} (rerun with --debug for a traceback)",
            file=sys.stderr,
        )
        return EXIT_INTERNAL


def _silence_stdout() -> None:
    """Point stdout at /dev/null so Python's exit flush does not fail on the closed pipe again."""
    import os

    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
    except (OSError, ValueError):  # stdout is not a real file (tests): nothing to flush
        pass


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
