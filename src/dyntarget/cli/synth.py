"""``dyntarget synth``: generate synthetic volcanic scenes."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from dyntarget.cli._common import EXIT_OK, log, positive_float, positive_int, writes
from dyntarget.errors import InvalidParameterError


@writes(dirs=("out",))
def cmd_synth(args: argparse.Namespace) -> int:
    if getattr(args, "strip", False):  # demo calls this with the static options only
        return _synth_strips(args)
    from tqdm import tqdm

    from dyntarget.io import write_scene
    from dyntarget.synth import generate_scenes

    out = Path(args.out)
    t0 = time.perf_counter()
    n_files = 0
    if getattr(args, "frames", None) is not None:  # demo calls this with the static options only
        return _synth_sequences(args, out, t0)
    if (
        getattr(args, "wind_mps", None) is not None
        or getattr(args, "wind_from_deg", None) is not None
    ):
        log("note: --wind-mps/--wind-from-deg apply to moving scenes (--frames) only")
    gen = generate_scenes(args.scenes, size=args.size, seed=args.seed, gsd=args.gsd)
    for scene, _params in tqdm(
        gen, total=args.scenes, desc="synth", unit="scene", disable=args.quiet
    ):
        n_files += len(write_scene(scene, out))
    log(
        f"wrote {args.scenes} scenes ({n_files} files) to {out} in {time.perf_counter() - t0:.1f} s"
    )
    return EXIT_OK


def _synth_strips(args: argparse.Namespace) -> int:
    """``synth --strip``: long moving strips with several plumes, to fly (``dyntarget fly``)."""
    from dyntarget.fly.strip import long_strip_spec, strip_spec, write_long_strip, write_strip

    out = Path(args.out)
    t0 = time.perf_counter()
    if args.length_km is not None or args.plumes_per_100km is not None:
        if args.length_km is None:
            raise InvalidParameterError("--plumes-per-100km: give --length-km too")
        if args.length is not None:
            raise InvalidParameterError("--length (px) and --length-km exclude each other")
        width = args.size if args.size_given else 256
        for i in range(args.scenes):
            spec, window = long_strip_spec(
                args.seed + i,
                args.length_km,
                width=width,
                gsd=args.gsd,
                plumes=args.plumes if args.plumes_given else None,
                plumes_per_100km=args.plumes_per_100km,
                clouds_per_100km=args.clouds_per_100km,
                wind_mps=getattr(args, "wind_mps", None),
                wind_from_deg=getattr(args, "wind_from_deg", None),
            )
            write_long_strip(spec, window, out)
        log(
            f"wrote {args.scenes} strip(s) of {args.length_km:g} km to {out} "
            f"in {time.perf_counter() - t0:.1f} s"
        )
        return EXIT_OK
    for i in range(args.scenes):
        spec, window = strip_spec(
            args.seed + i,
            width=args.size,
            length=args.length or 4 * args.size + args.size // 2,
            plumes=args.plumes,
            gsd=args.gsd,
            wind_mps=getattr(args, "wind_mps", None),
            wind_from_deg=getattr(args, "wind_from_deg", None),
        )
        write_strip(spec, window, out)
    log(f"wrote {args.scenes} strip(s) to {out} in {time.perf_counter() - t0:.1f} s")
    return EXIT_OK


def _synth_sequences(args: argparse.Namespace, out: Path, t0: float) -> int:
    from tqdm import tqdm

    from dyntarget.io import write_sequence
    from dyntarget.synth import generate_sequences

    gen = generate_sequences(
        args.scenes,
        size=args.size,
        seed=args.seed,
        gsd=args.gsd,
        frames=args.frames,
        interval_s=args.frame_interval_s,
        wind_mps=args.wind_mps,
        wind_from_deg=args.wind_from_deg,
    )
    n_files = 0
    for seq in tqdm(gen, total=args.scenes, desc="synth", unit="sequence", disable=args.quiet):
        n_files += len(write_sequence(seq, out))
    log(
        f"wrote {args.scenes} moving-scene sequences of {args.frames} frame(s) "
        f"({n_files} files) to {out} in {time.perf_counter() - t0:.1f} s"
    )
    return EXIT_OK


class _Given(argparse.Action):
    """Store the value and remember that it was given (``<dest>_given``)."""

    def __call__(self, parser, namespace, values, option_string=None):
        setattr(namespace, self.dest, values)
        setattr(namespace, f"{self.dest}_given", True)


def _wind_speed(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected m/s, got {text!r}") from None
    if not 0 <= value <= 60:
        raise argparse.ArgumentTypeError(f"expected a wind speed in 0..60 m/s, got {text!r}")
    return value


def _degrees(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected degrees, got {text!r}") from None
    if not -360 <= value <= 360:
        raise argparse.ArgumentTypeError(f"expected degrees in -360..360, got {text!r}")
    return value


def register(sub: argparse._SubParsersAction) -> None:
    """Add this module's command(s) to the ``dyntarget`` sub-commands."""
    p = sub.add_parser("synth", help="generate synthetic volcanic scenes (GeoTIFF + mask)")
    p.add_argument("--scenes", type=positive_int, default=38, help="number of scenes (default 38)")
    p.add_argument(
        "--size",
        type=positive_int,
        action=_Given,
        default=512,
        help="scene size in pixels (default 512)",
    )
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--gsd", type=positive_float, default=8.0, help="metres per pixel (default 8)")
    p.add_argument("--out", required=True, help="output scene directory")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    g = p.add_argument_group(
        "moving scenes",
        "with --frames, each scene is a folder <id>/ of look-ahead frames f000.tif, f001.tif, "
        "... (+ _mask.tif) at t = 0, S, 2S, ... and sequence.json (times, and the world spec "
        "from which the true plume at any time is rebuilt); see docs/synthetic-scenes.md",
    )
    g.add_argument(
        "--frames", type=positive_int, help="number of look-ahead frames per moving scene"
    )
    g.add_argument(
        "--frame-interval-s",
        type=positive_float,
        default=10.0,
        help="seconds between frames (default 10)",
    )
    g.add_argument(
        "--wind-mps",
        type=_wind_speed,
        help="wind speed in m/s for every scene (default: drawn per scene, 0-16)",
    )
    g.add_argument(
        "--wind-from-deg",
        type=_degrees,
        help="direction the wind blows from, degrees clockwise from north (default: drawn)",
    )
    s = p.add_argument_group("strips to fly ('dyntarget fly'; --scenes strips, --size px wide)")
    s.add_argument(
        "--strip",
        action="store_true",
        help="write long moving strips (seed, seed+1, ...) with several plumes instead of scenes",
    )
    s.add_argument(
        "--plumes",
        type=positive_int,
        action=_Given,
        default=4,
        help="vents per strip (default 4; with --length-km, default 1 per 100 km)",
    )
    s.add_argument(
        "--length", type=positive_int, help="strip length in px (default 4.5 x --size: 8 frames)"
    )
    s.add_argument(
        "--length-km",
        type=positive_float,
        help="a pass-length strip (10-10000 km, e.g. 3000), rendered lazily when flown; "
        "--size defaults to 256 px across",
    )
    s.add_argument(
        "--plumes-per-100km",
        type=positive_float,
        help="vent density along a --length-km strip (default 1; or give --plumes)",
    )
    s.add_argument(
        "--clouds-per-100km",
        type=float,
        default=2.0,
        help="meteorological clouds per 100 km of a --length-km strip (default 2)",
    )
    p.set_defaults(func=cmd_synth, size_given=False, plumes_given=False)
