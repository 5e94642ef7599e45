"""Every option that more than one command takes, defined once with its validation.

Modelled on rasterio's ``rio/options.py``: an :class:`Option` holds a flag's
name, type, default and help; a command adds it with ``OPTION.add(parser)``
(overriding the help or default where its meaning differs, e.g. ``--factor`` of
``plan`` defaults to 1). Every numeric option parses through one of the *type
functions* below, which check the value's range and finiteness where it is
defined: a bad value is one line naming the option (argparse's
``dyntarget: error: argument --x: ...``) and exit 2, before any work.

Help texts may use ``%(default)s``; argparse fills in the default of the
parser it is added to.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from dyntarget import defaults

# -- type functions: one clear line (argparse names the option), exit 2 ----------------------


def positive_int(text: str) -> int:
    """An integer >= 1.

    Parameters
    ----------
    text : str
        The option's value.

    Returns
    -------
    int
        The value.

    Examples
    --------
    >>> positive_int("3")
    3
    >>> positive_int("0")
    Traceback (most recent call last):
    ...
    argparse.ArgumentTypeError: expected a positive integer, got 0
    """
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {value}")
    return value


def int_range(lo: int, hi: int, what: str = "an integer") -> Callable[[str], int]:
    """A type function for integers in ``lo..hi``.

    Parameters
    ----------
    lo, hi : int
        The inclusive bounds.
    what : str
        What the value is, for the message.

    Returns
    -------
    callable
        ``str -> int``, raising :class:`argparse.ArgumentTypeError` outside the range.

    Examples
    --------
    >>> int_range(0, 9)("7")
    7
    >>> int_range(0, 9, "a digit")("10")
    Traceback (most recent call last):
    ...
    argparse.ArgumentTypeError: expected an integer <= 9 (a digit in 0..9), got 10
    """

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"expected {what} in {lo}..{hi}, got {text!r}"
            ) from None
        if value < lo:
            raise argparse.ArgumentTypeError(
                f"expected an integer >= {lo} ({what} in {lo}..{hi}), got {value}"
            )
        if value > hi:
            raise argparse.ArgumentTypeError(
                f"expected an integer <= {hi} ({what} in {lo}..{hi}), got {value}"
            )
        return value

    parse.__name__ = f"int_{lo}_{hi}"
    return parse


def _float(text: str, what: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"expected {what} (a finite number), got {text!r}")
    return value


def finite_float(text: str) -> float:
    """Any finite number.

    Parameters
    ----------
    text : str
        The option's value.

    Returns
    -------
    float
        The value.

    Examples
    --------
    >>> finite_float("-2.5")
    -2.5
    >>> finite_float("nan")
    Traceback (most recent call last):
    ...
    argparse.ArgumentTypeError: expected a number (a finite number), got 'nan'
    """
    return _float(text, "a number")


def positive_float(text: str) -> float:
    """A finite number > 0.

    Parameters
    ----------
    text : str
        The option's value.

    Returns
    -------
    float
        The value.

    Examples
    --------
    >>> positive_float("0.5")
    0.5
    >>> positive_float("inf")
    Traceback (most recent call last):
    ...
    argparse.ArgumentTypeError: expected a positive finite number, got 'inf'
    """
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}") from None
    if not value > 0 or value == float("inf"):
        raise argparse.ArgumentTypeError(f"expected a positive finite number, got {text!r}")
    return value


def float_range(
    lo: float, hi: float, what: str = "a number", *, lo_open: bool = False, hi_open: bool = False
) -> Callable[[str], float]:
    """A type function for finite numbers in ``[lo, hi]`` (open ends with ``lo_open``/``hi_open``).

    Parameters
    ----------
    lo, hi : float
        The bounds.
    what : str
        What the value is (with its unit), for the message.
    lo_open, hi_open : bool
        Exclude ``lo`` (``hi``) itself.

    Returns
    -------
    callable
        ``str -> float``, raising :class:`argparse.ArgumentTypeError` outside the range.

    Examples
    --------
    >>> float_range(-360, 360, "degrees")("90")
    90.0
    >>> float_range(-360, 360, "degrees")("1e300")
    Traceback (most recent call last):
    ...
    argparse.ArgumentTypeError: expected degrees in -360..360, got '1e300'
    >>> float_range(0, 1, "a fraction", lo_open=True)("0")
    Traceback (most recent call last):
    ...
    argparse.ArgumentTypeError: expected a fraction in (0, 1], got '0'
    """
    if lo_open or hi_open:
        span = f"{'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}"
    else:
        span = f"{lo:g}..{hi:g}"

    def parse(text: str) -> float:
        value = _float(text, f"{what} in {span}")
        if not (lo < value if lo_open else lo <= value) or not (
            value < hi if hi_open else value <= hi
        ):
            raise argparse.ArgumentTypeError(f"expected {what} in {span}, got {text!r}")
        return value

    parse.__name__ = f"float_{lo:g}_{hi:g}"
    return parse


def scheduler_address(text: str) -> str:
    """``local``, ``processes`` or a Dask scheduler address.

    Parameters
    ----------
    text : str
        The option's value.

    Returns
    -------
    str
        The value.

    Examples
    --------
    >>> scheduler_address("tcp://10.0.0.1:8786")
    'tcp://10.0.0.1:8786'
    """
    if text in ("local", "processes") or "://" in text:
        return text
    raise argparse.ArgumentTypeError(
        f"expected local, processes or a scheduler address like tcp://HOST:PORT, got {text!r}"
    )


def odd_footprint(text: str) -> int:
    """An odd number of WFOV pixels, 1..:data:`MAX_FOOTPRINT`.

    Parameters
    ----------
    text : str
        The option's value.

    Returns
    -------
    int
        The value.

    Examples
    --------
    >>> odd_footprint("3")
    3
    >>> odd_footprint("999999")
    Traceback (most recent call last):
    ...
    argparse.ArgumentTypeError: expected an integer <= 255 (an odd number of WFOV px in 1..255), got 999999
    """
    value = int_range(1, MAX_FOOTPRINT, "an odd number of WFOV px")(text)
    if value % 2 == 0:
        raise argparse.ArgumentTypeError(f"expected an odd number of WFOV px, got {value}")
    return value


MAX_SEED = 2**32 - 1
"""Largest seed (numpy and scikit-learn take 0..2**32-1)."""
MAX_FOOTPRINT = 255
"""Widest NFOV footprint, WFOV pixels (a pass further checks it against the strip's width)."""
MAX_WIND_MPS = 60.0
"""Strongest wind accepted, m/s (as ``synth`` has always refused faster ones)."""
MAX_SECONDS = 86_400.0
"""Longest time accepted by a seconds option (a day)."""
MIN_INTERVAL_S = 1e-3
"""Shortest time between two looks, s (closer looks give no usable motion)."""

seconds = float_range(0.0, MAX_SECONDS, "seconds")  # seconds >= 0, at most a day
positive_seconds = float_range(0.0, MAX_SECONDS, "seconds", lo_open=True)  # > 0, at most a day
seed_int = int_range(0, MAX_SEED, "a seed")
wind_speed = float_range(0.0, MAX_WIND_MPS, "a wind speed, m/s")
degrees = float_range(-360.0, 360.0, "degrees")

# -- the options ----------------------------------------------------------------------------


def _pair(text: str, *, single: bool, usage: str) -> tuple[float, float]:
    """``"LO,HI"`` as two floats (``"H"`` as ``(H, H)`` where ``single``); else one line."""
    parts = text.split(",")
    try:
        vals = [float(v) for v in parts] if len(parts) == 2 or (single and len(parts) == 1) else []
    except ValueError:
        vals = []
    if not vals:
        raise argparse.ArgumentTypeError(f"expected LO,HI {usage}, got {text!r}")
    return vals[0], vals[-1]


MAX_HEIGHT_KM = 25.0
"""Highest plume or cloud top, km (:data:`dyntarget.synth.dynamic.MAX_HEIGHT_M` / 1000; checked equal by the tests)."""


def height_range(text: str) -> tuple[float, float]:
    """``"LO,HI"`` (or one height ``"H"``) in km, ``0 <= LO <= HI <= 25``, finite.

    Parameters
    ----------
    text : str
        The option's value.

    Returns
    -------
    tuple of float
        ``(lo, hi)`` km.

    Examples
    --------
    >>> height_range("2,15"), height_range("8")
    ((2.0, 15.0), (8.0, 8.0))
    >>> height_range("15,2")
    Traceback (most recent call last):
    ...
    argparse.ArgumentTypeError: expected LO,HI km with 0 <= LO <= HI <= 25, got '15,2'
    """
    lo, hi = _pair(text, single=True, usage="km (e.g. 2,15)")
    if not (math.isfinite(lo) and math.isfinite(hi) and 0.0 <= lo <= hi <= MAX_HEIGHT_KM):
        raise argparse.ArgumentTypeError(
            f"expected LO,HI km with 0 <= LO <= HI <= {MAX_HEIGHT_KM:g}, got {text!r}"
        )
    return lo, hi


# one plume-top height in km (a prior): finite, 0 < H <= 25
plume_height_km = float_range(0.0, MAX_HEIGHT_KM, "a plume-top height in km", lo_open=True)


MAX_ONSET_MIN = 1440.0
"""Onsets and durations within a day, minutes (:data:`dyntarget.synth.dynamic.MAX_SECONDS`)."""


def minute_span(text: str) -> tuple[float, float]:
    """``"LO,HI"`` minutes on the pass clock (negative: before the pass), ``LO < HI``, within a day.

    Parameters
    ----------
    text : str
        The option's value.

    Returns
    -------
    tuple of float
        ``(lo, hi)`` minutes.

    Examples
    --------
    >>> minute_span("-60,0")
    (-60.0, 0.0)
    >>> minute_span("5,5")
    Traceback (most recent call last):
    ...
    argparse.ArgumentTypeError: expected LO,HI minutes with LO < HI within ±1440, got '5,5'
    """
    lo, hi = _pair(text, single=False, usage="minutes (e.g. -60,0)")
    if not (math.isfinite(lo) and math.isfinite(hi) and -MAX_ONSET_MIN <= lo < hi <= MAX_ONSET_MIN):
        raise argparse.ArgumentTypeError(
            f"expected LO,HI minutes with LO < HI within ±{MAX_ONSET_MIN:g}, got {text!r}"
        )
    return lo, hi


@dataclass(frozen=True)
class Option:
    """One command-line option, defined once: its flags and ``add_argument`` keywords.

    Parameters
    ----------
    flags : tuple of str
        ``("--factor",)``.
    kwargs : dict
        ``add_argument`` keywords (``type``, ``default``, ``help``, ...).

    Examples
    --------
    >>> p = argparse.ArgumentParser()
    >>> _ = FACTOR.add(p, default=1)
    >>> p.parse_args(["--factor", "2"]).factor, p.parse_args([]).factor
    (2, 1)
    """

    flags: tuple[str, ...]
    kwargs: dict[str, Any] = field(default_factory=dict)

    def add(self, parser: Any, **overrides: Any) -> argparse.Action:
        """Add the option to ``parser`` (a parser or argument group), ``overrides`` replacing keywords.

        Parameters
        ----------
        parser : argparse.ArgumentParser or argument group
            Where to add it.
        **overrides
            ``add_argument`` keywords replacing the defined ones (``help``, ``default``, ...).

        Returns
        -------
        argparse.Action
            What ``add_argument`` returns.
        """
        return parser.add_argument(*self.flags, **{**self.kwargs, **overrides})


def _opt(flag: str, **kwargs: Any) -> Option:
    return Option((flag,), kwargs)


SCHEDULER_HELP = (
    "run the tasks on dask.distributed: local (threads), processes (one worker process per "
    "core) or a scheduler address tcp://HOST:PORT (default: one by one in this process)"
)

QUIET = _opt("--quiet", action="store_true", help="no progress bar")
OUT = _opt("--out", required=True, help="output folder")
DATA = _opt("--data", required=True, help="scene directory with labels")
MODELS = _opt("--models", help="folder to keep trained models in and reuse them from")
FACTOR = _opt(
    "--factor",
    type=positive_int,
    default=defaults.FACTOR,
    help="high-res -> WFOV factor (default %(default)s)",
)
SEED = _opt("--seed", type=seed_int, default=0, help="random seed (default 0)")
EPOCHS = _opt(
    "--epochs",
    type=positive_int,
    default=defaults.EPOCHS,
    help="U-Net epochs (default %(default)s)",
)
FOLDS = _opt(
    "--folds",
    type=int_range(2, 1000, "a number of folds"),
    default=defaults.FOLDS,
    help="number of folds (default %(default)s)",
)
SCHEDULER = _opt("--scheduler", type=scheduler_address, help=SCHEDULER_HELP)
CLASSIFIERS = _opt("--classifiers", help="comma-separated subset (default: all)")
CLASSIFIER = _opt("--classifier", help="classifier name (see 'dyntarget classifiers')")
PLANNERS = _opt("--planners", help="comma-separated subset (default: all)")
PLANNER = _opt("--planner", help="planner name (see 'dyntarget planners')")
AGILITY = _opt("--agility", help="agility preset: unlimited, fast, slow ('dyntarget agility')")
OBJECTIVE = _opt(
    "--objective",
    default=defaults.OBJECTIVE,
    choices=defaults.OBJECTIVES,
    help="what utility-max maximises (default %(default)s)",
)
MODEL = _opt("--model", help="trained model directory (from 'dyntarget train')")
ONNX = _opt("--onnx", action="store_true", help="run the model's ONNX export with onnxruntime")
INT8 = _opt(
    "--int8",
    action="store_true",
    help="run the model's INT8 ONNX export ('export-onnx --int8'; implies --onnx)",
)
FORCE = _opt(
    "--force",
    action="store_true",
    help="run a model at more than twice or half the resolution it was trained at",
)
FALLBACK_MODEL = _opt(
    "--fallback-model", help="a cheaper trained model to fall back on under --deadline-s"
)
DEADLINE_S = _opt(
    "--deadline-s",
    type=positive_seconds,
    help="seconds allowed for classify + denoise + plan; cheaper paths are taken to meet it",
)
NO_DENOISE = _opt("--no-denoise", action="store_true", help="plan on the raw mask")
TRUTH_STEP_S = _opt(
    "--truth-step-s",
    type=seconds,
    default=1.0,
    help="time quantum of a moving strip's truth (default 1 s)",
)
MASK = _opt("--mask", help="plume mask to plan on (.tif, non-zero = plume, or .geojson)")
PRESET = _opt("--preset", help="sensor preset (see docs/sensors.md)")
BANDS = _opt(
    "--bands", help="R,G,B,NIR band numbers (1-based) or names, e.g. 3,2,1,7 or B4,B3,B2,B8"
)
SCALE = _opt(
    "--scale",
    type=float_range(0.0, 10.0, "reflectance per digital number", lo_open=True),
    help="reflectance per digital number for integer images",
)
OFFSET = _opt(
    "--offset",
    type=float_range(-1.0, 1.0, "a reflectance offset"),
    help="reflectance offset added after scaling (e.g. -0.1)",
)
SCENES = _opt(
    "--scenes",
    type=positive_int,
    default=38,
    help="number of scenes (default %(default)s)",
)
SIZE = _opt(
    "--size",
    type=positive_int,  # the generator refuses what does not fit in memory, naming it
    default=512,
    help="scene size in pixels (default %(default)s)",
)
CRS = _opt(
    "--crs",
    choices=["rfc7946", "native"],
    default="rfc7946",
    help="GeoJSON coordinates: rfc7946 = WGS 84 lon/lat, no 'crs' member (default); "
    "native = the image's CRS with the legacy 'crs' member GDAL/QGIS read",
)
WIND_MPS = _opt("--wind-mps", type=wind_speed, help="wind speed prior, m/s")
WIND_FROM_DEG = _opt(
    "--wind-from-deg",
    type=degrees,
    help="direction the wind blows FROM, degrees clockwise from north (meteorological)",
)
GROUND = _opt(
    "--ground",
    choices=["auto", "fixed", "moving"],
    default="auto",
    help="with two looks: is the background a fixed ground (its shift is misregistration, "
    "removed) or moving itself (weather, radar, a plume over moving cloud)? auto "
    "(default) decides from the frames and says so",
)
ALTITUDE_KM = _opt(
    "--altitude-km",
    type=float_range(0.0, 100_000.0, "km", lo_open=True),
    default=defaults.ALTITUDE_M / 1e3,
    help="orbit altitude (default %(default)g)",
)
LOOK_AHEAD_KM = _opt(
    "--look-ahead-km",
    type=finite_float,  # the horizon seen from --altitude-km bounds it (check_orbit)
    default=defaults.LOOK_AHEAD_M / 1e3,
    help="ground distance from nadir to the WFOV scene centre at acquisition (default %(default)g)",
)
PLUME_HEIGHT_KM = _opt(
    "--plume-height-km",
    type=plume_height_km,
    metavar="H",
    help="correct the NFOV pointings for the parallax of a plume top H km above sea level "
    "(a prior, e.g. from a volcanic ash advisory; 0 < H <= 25)",
)
NO_PARALLAX = _opt(
    "--no-parallax",
    action="store_true",
    help="no parallax correction: aim where the look-ahead saw the plume",
)
NO_PICTURE = _opt("--no-picture", action="store_true", help="skip the picture (PNG)")
NO_HTML = _opt("--no-html", action="store_true", help="skip the interactive view (HTML)")
MAX_SPACING_PX = 1e6
"""Largest ``--step``/``--width``, pixels: far beyond any image, and small enough that the
planners' derived spacings (a transect width of twice the step) stay finite."""
STEP = _opt(
    "--step",
    type=float_range(0, MAX_SPACING_PX, "pixels", lo_open=True),
    help="pixels between pointings (default 1%% of the width)",
)
WIDTH = _opt(
    "--width",
    type=float_range(0, MAX_SPACING_PX, "pixels", lo_open=True),
    help="pixels between transects (default 2 x step)",
)


def add_orbit_options(p: Any, *, look_ahead_positive: bool = False) -> None:
    """``--altitude-km`` and ``--look-ahead-km`` (defaults from :mod:`dyntarget.defaults`).

    Parameters
    ----------
    p : argparse.ArgumentParser or argument group
        Where to add them.
    look_ahead_positive : bool
        A look-ahead > 0 only (a pass looks ahead, never behind).
    """
    ALTITUDE_KM.add(p)
    if look_ahead_positive:
        LOOK_AHEAD_KM.add(p, type=positive_float)
    else:
        LOOK_AHEAD_KM.add(p)


def add_plan_options(p: Any) -> None:
    """``--step`` and ``--width`` of the planners.

    Parameters
    ----------
    p : argparse.ArgumentParser or argument group
        Where to add them.
    """
    STEP.add(p)
    WIDTH.add(p)


def add_wind_options(p: Any, **helps: str) -> None:
    """``--wind-mps`` and ``--wind-from-deg`` (``helps``: ``mps=``/``from_deg=`` help texts).

    Parameters
    ----------
    p : argparse.ArgumentParser or argument group
        Where to add them.
    **helps : str
        ``mps`` and ``from_deg``: the help texts where the meaning differs.
    """
    WIND_MPS.add(p, **({"help": helps["mps"]} if "mps" in helps else {}))
    WIND_FROM_DEG.add(p, **({"help": helps["from_deg"]} if "from_deg" in helps else {}))


def add_model_options(p: Any, *, onnx_help: str | None = None) -> None:
    """``--model``-side options of the commands that run one: ``--onnx``, ``--int8``, ``--force``.

    Parameters
    ----------
    p : argparse.ArgumentParser or argument group
        Where to add them.
    onnx_help : str or None
        A shorter help for ``--onnx``/``--int8``.
    """
    ONNX.add(p, **({"help": onnx_help} if onnx_help else {}))
    INT8.add(p, **({} if onnx_help is None else {"help": "its INT8 export (implies --onnx)"}))


def add_sensor_options(p: Any) -> None:
    """``--preset``, ``--bands``, ``--scale``, ``--offset``: how an image's bands are read.

    Parameters
    ----------
    p : argparse.ArgumentParser or argument group
        Where to add them.
    """
    from dyntarget.io.presets import PRESETS

    PRESET.add(p, help="sensor preset: " + ", ".join(PRESETS))
    BANDS.add(p)
    SCALE.add(p)
    OFFSET.add(p)


def add_parallax_options(
    p: Any, *, height_help: str | None = None, no_parallax_help: str | None = None
) -> None:
    """``--plume-height-km H`` (a prior) and ``--no-parallax``, excluding each other.

    Giving both is one line and exit 2 (argparse names them). Read the choice back
    with :func:`parallax_height_m`.

    Parameters
    ----------
    p : argparse.ArgumentParser or argument group
        Where to add them.
    height_help, no_parallax_help : str or None
        Help texts where the command's meaning differs (e.g. its default).

    Examples
    --------
    >>> parser = argparse.ArgumentParser()
    >>> add_parallax_options(parser)
    >>> parallax_height_m(parser.parse_args(["--plume-height-km", "8.5"]))
    8500.0
    >>> parallax_height_m(parser.parse_args(["--no-parallax"])) is None
    True
    """
    group = p.add_mutually_exclusive_group()
    PLUME_HEIGHT_KM.add(group, **({"help": height_help} if height_help else {}))
    NO_PARALLAX.add(group, **({"help": no_parallax_help} if no_parallax_help else {}))


def parallax_height_m(args: argparse.Namespace) -> float | None:
    """The prior plume-top height of :func:`add_parallax_options`, metres (``None``: none given).

    Parameters
    ----------
    args : argparse.Namespace
        Parsed with :func:`add_parallax_options`.

    Returns
    -------
    float or None
        ``--plume-height-km`` x 1000, or ``None`` (``--no-parallax`` or neither).

    Examples
    --------
    >>> parallax_height_m(argparse.Namespace(plume_height_km=2.0, no_parallax=False))
    2000.0
    """
    km = getattr(args, "plume_height_km", None)
    return None if km is None else float(km) * 1000.0


def parallax_choice(args: argparse.Namespace) -> str | None:
    """Which of :func:`add_parallax_options` was given: ``"prior"``, ``"off"`` or ``None``.

    Parameters
    ----------
    args : argparse.Namespace
        Parsed with :func:`add_parallax_options`.

    Returns
    -------
    str or None
        ``"prior"`` (``--plume-height-km``), ``"off"`` (``--no-parallax``) or ``None``
        (neither: the command's default).

    Examples
    --------
    >>> parallax_choice(argparse.Namespace(plume_height_km=None, no_parallax=True))
    'off'
    """
    if getattr(args, "plume_height_km", None) is not None:
        return "prior"
    return "off" if getattr(args, "no_parallax", False) else None
