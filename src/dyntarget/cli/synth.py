"""``dyntarget synth``: generate synthetic volcanic scenes."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from dyntarget.cli import options as o
from dyntarget.cli._common import EXIT_OK, log, writes
from dyntarget.errors import InvalidParameterError


@writes(dirs=("out",))
def cmd_synth(args: argparse.Namespace) -> int:
    """Write the scenes, sequences or strips into a staging folder, then into ``--out``."""
    from dyntarget.io.staging import staged

    if getattr(args, "strip", False):  # demo calls this with the static options only
        _check_strip_size(args)  # before anything is written
    heights = _heights(args)  # before anything is written
    _check_onsets(args)
    with staged(args.out) as stage:
        if getattr(args, "strip", False):
            return _synth_strips(args, stage, heights)
        if getattr(args, "frames", None) is not None:  # demo: the static options only
            return _synth_sequences(args, stage, heights)
        return _synth_scenes(args, stage)


Heights = tuple[tuple[float, float], tuple[float, float]]


def _heights(args: argparse.Namespace) -> Heights | None:
    """The height ranges of a 3D world (plume, cloud; km), or ``None`` for a flat world.

    Moving worlds (``--frames``, ``--strip``) are 3D by default, their heights drawn in the
    given ranges or the defaults (:data:`PLUME_HEIGHT_KM`, :data:`CLOUD_HEIGHT_KM`);
    ``--flat`` keeps them flat (the bytes written before worlds had heights). Static scenes
    stay flat (the paper's setting), and a height option there is refused.
    """
    plume = getattr(args, "plume_height_km", None)
    cloud = getattr(args, "cloud_height_km", None)
    given = plume is not None or cloud is not None
    if given and getattr(args, "flat", False):
        raise InvalidParameterError(
            "--flat and --plume-height-km/--cloud-height-km exclude each other"
        )
    if not getattr(args, "strip", False) and getattr(args, "frames", None) is None:
        if given:
            raise InvalidParameterError(
                "--plume-height-km/--cloud-height-km: static scenes stay flat; heights apply "
                "to moving worlds (--frames, --strip)"
            )
        return None
    if getattr(args, "flat", False):
        return None
    return (plume or PLUME_HEIGHT_KM, cloud or CLOUD_HEIGHT_KM)


def _check_onsets(args: argparse.Namespace) -> None:
    """Refuse onset options without ``--strip``, or a duration without a fraction."""
    given = [
        n for n in ("onset_fraction", "onset_window_min", "onset_duration_min")
        if getattr(args, n, None) is not None
    ]  # fmt: skip
    if given and not getattr(args, "strip", False):
        raise InvalidParameterError(
            "--onset-fraction/--onset-window-min/--onset-duration-min: onsets apply to "
            "strips (--strip)"
        )
    if given and getattr(args, "onset_fraction", None) is None:
        raise InvalidParameterError(
            "--onset-window-min/--onset-duration-min: give --onset-fraction too"
        )


def _onsets(spec, args: argparse.Namespace):
    """The strip's world with the onsets of ``--onset-fraction`` (unchanged without it)."""
    from dyntarget.synth.dynamic import ONSET_WINDOW_S, with_onsets

    f = getattr(args, "onset_fraction", None)
    if f is None:
        return spec
    win = getattr(args, "onset_window_min", None)
    dur = getattr(args, "onset_duration_min", None)
    return with_onsets(
        spec,
        f,
        window_s=ONSET_WINDOW_S if win is None else (win[0] * 60.0, win[1] * 60.0),
        duration_s=None if dur is None else (dur[0] * 60.0, dur[1] * 60.0),
    )


def _write_plumes(spec, dest: Path) -> Path:
    """``<id>.plumes.geojson`` beside the strip or frame folder: the per-vent truth."""
    from dyntarget.io.geojson import write_plumes

    return write_plumes(
        dest / f"{spec.id}.plumes.geojson",
        spec.plumes(),
        transform=spec.grid_transform(),
        crs=spec.crs,
    )


def _synth_scenes(args: argparse.Namespace, dest: Path) -> int:
    from tqdm import tqdm

    from dyntarget.io import write_scene
    from dyntarget.synth import generate_scenes

    t0 = time.perf_counter()
    n_files = 0
    if (
        getattr(args, "wind_mps", None) is not None
        or getattr(args, "wind_from_deg", None) is not None
    ):
        log("note: --wind-mps/--wind-from-deg apply to moving scenes (--frames) only")
    gen = generate_scenes(args.scenes, size=args.size, seed=args.seed, gsd=args.gsd)
    for scene, _params in tqdm(
        gen, total=args.scenes, desc="synth", unit="scene", disable=args.quiet
    ):
        n_files += len(write_scene(scene, dest))
    log(
        f"wrote {args.scenes} scenes ({n_files} files) to {args.out} in "
        f"{time.perf_counter() - t0:.1f} s"
    )
    return EXIT_OK


def _synth_strips(args: argparse.Namespace, dest: Path, heights: Heights | None) -> int:
    """``synth --strip``: long moving strips with several plumes, to fly (``dyntarget fly``)."""
    from dyntarget.synth.dynamic import with_heights
    from dyntarget.synth.strip import (
        long_strip_spec,
        strip_spec,
        with_parallax_margin,
        write_long_strip,
        write_strip,
    )

    out = Path(args.out)
    t0 = time.perf_counter()
    if args.length_km is not None or args.plumes_per_100km is not None:
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
            spec = _onsets(spec, args)
            if heights is not None:
                spec = with_heights(spec, plume_height_km=heights[0], cloud_height_km=heights[1])
                _write_plumes(spec, dest)
            write_long_strip(spec, window, dest)
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
        spec = _onsets(spec, args)
        if heights is not None:
            spec = with_heights(spec, plume_height_km=heights[0], cloud_height_km=heights[1])
            spec, window = with_parallax_margin(spec, window)  # displaced plumes stay on it
            _write_plumes(spec, dest)
        write_strip(spec, window, dest)
    log(f"wrote {args.scenes} strip(s) to {out} in {time.perf_counter() - t0:.1f} s")
    return EXIT_OK


def _synth_sequences(args: argparse.Namespace, dest: Path, heights: Heights | None) -> int:
    from tqdm import tqdm

    from dyntarget.io import write_sequence
    from dyntarget.synth import generate_sequences
    from dyntarget.synth.dynamic import WorldSpec

    t0 = time.perf_counter()
    gen = generate_sequences(
        args.scenes,
        size=args.size,
        seed=args.seed,
        gsd=args.gsd,
        frames=args.frames,
        interval_s=args.frame_interval_s,
        wind_mps=args.wind_mps,
        wind_from_deg=args.wind_from_deg,
        heights_km=heights,
    )
    n_files = 0
    for seq in tqdm(gen, total=args.scenes, desc="synth", unit="sequence", disable=args.quiet):
        n_files += len(write_sequence(seq, dest))
        if heights is not None:
            _write_plumes(WorldSpec.from_dict(seq.meta["world"]), dest)
            n_files += 1
    log(
        f"wrote {args.scenes} moving-scene sequences of {args.frames} frame(s) "
        f"({n_files} files) to {args.out} in {time.perf_counter() - t0:.1f} s"
    )
    return EXIT_OK


PLUME_HEIGHT_KM, CLOUD_HEIGHT_KM = (2.0, 15.0), (1.0, 12.0)
"""Default height ranges of a 3D world, km (:data:`dyntarget.synth.dynamic.PLUME_HEIGHT_KM`,
``CLOUD_HEIGHT_KM``; written out here so that ``--help`` does not import the renderer)."""
MAX_VENTS, MAX_CLOUDS = 64, 256
"""Vents and clouds a strip may hold (:data:`dyntarget.synth.dynamic.MAX_VENTS`,
``MAX_CLOUDS``; written out here so that ``--help`` does not import the renderer, and
checked equal by the tests)."""
MIN_LENGTH_KM, MAX_LENGTH_KM = 10.0, 10_000.0
"""Pass-length strips (:data:`dyntarget.synth.strip.MIN_LENGTH_KM`, ``MAX_LENGTH_KM``)."""
MAX_WINDOW_SIDE = 1 << 16
"""Longest side of a rendered window, px (:data:`dyntarget.synth.dynamic.MAX_WINDOW_SIDE`)."""
MAX_WINDOW_PIXELS = 1 << 23
"""Most pixels rendered at once (:data:`dyntarget.synth.dynamic.MAX_WINDOW_PIXELS`): a short
strip is rendered whole, a long strip's frames (``--size`` square) one at a time."""
MAX_LONG_WIDTH = 2896
"""Widest pass-length strip, px: its square frames (``--size`` x ``--size``) must render at
once (``isqrt(MAX_WINDOW_PIXELS)``)."""


def _check_strip_size(args: argparse.Namespace) -> None:
    """Refuse, naming the options, a strip that could not be rendered or would hold too much."""
    if args.length_km is None and args.plumes_per_100km is None:
        length = args.length or 4 * args.size + args.size // 2
        if args.size > 4096 or args.size * length > MAX_WINDOW_PIXELS:
            raise InvalidParameterError(
                f"--size {args.size} --length {length}: a {args.size} x {length} px strip is "
                f"rendered whole, more than the {MAX_WINDOW_PIXELS:,} px rendered at once; "
                "give a smaller --size or --length, or a pass-length strip with --length-km"
            )
        return
    if args.length_km is None:
        raise InvalidParameterError("--plumes-per-100km: give --length-km too")
    if args.length is not None:
        raise InvalidParameterError("--length (px) and --length-km exclude each other")
    width = args.size if args.size_given else 256
    if not 32 <= width <= MAX_LONG_WIDTH:
        raise InvalidParameterError(
            f"--size {width}: a pass-length strip is 32 to {MAX_LONG_WIDTH} px across (its "
            f"square frames are rendered whole, at most {MAX_WINDOW_PIXELS:,} px)"
        )
    if args.plumes_given:
        return  # --plumes is within 1..MAX_VENTS by its type
    density = 1.0 if args.plumes_per_100km is None else args.plumes_per_100km
    vents = max(1, round(args.length_km / 100.0 * density))
    if vents > MAX_VENTS:
        flag = "" if args.plumes_per_100km is None else f" --plumes-per-100km {density:g}"
        raise InvalidParameterError(
            f"--length-km {args.length_km:g}{flag}: {vents} vents at {density:g} per 100 km, "
            f"more than the {MAX_VENTS} a strip may hold; give --plumes-per-100km "
            f"{MAX_VENTS * 100 / args.length_km:.3g} or less (or --plumes N)"
        )
    clouds = args.length_km / 100.0 * args.clouds_per_100km
    if clouds > MAX_CLOUDS:
        raise InvalidParameterError(
            f"--clouds-per-100km {args.clouds_per_100km:g}: about {clouds:.0f} clouds over "
            f"{args.length_km:g} km, more than the {MAX_CLOUDS} a strip may hold; give "
            f"--clouds-per-100km {MAX_CLOUDS * 100 / args.length_km:.3g} or less"
        )


class _Given(argparse.Action):
    """Store the value and remember that it was given (``<dest>_given``)."""

    def __call__(self, parser, namespace, values, option_string=None):
        setattr(namespace, self.dest, values)
        setattr(namespace, f"{self.dest}_given", True)


def register(sub: argparse._SubParsersAction) -> None:
    """Add this module's command(s) to the ``dyntarget`` sub-commands."""
    p = sub.add_parser("synth", help="generate synthetic volcanic scenes (GeoTIFF + mask)")
    o.SCENES.add(p)
    o.SIZE.add(p, action=_Given)
    o.SEED.add(p)
    p.add_argument(
        "--gsd",
        type=o.float_range(0.0, 10_000.0, "metres", lo_open=True),
        default=8.0,
        help="metres per pixel (default 8)",
    )
    o.OUT.add(p, help="output scene directory")
    o.QUIET.add(p)
    g = p.add_argument_group(
        "moving scenes",
        "with --frames, each scene is a folder <id>/ of look-ahead frames f000.tif, f001.tif, "
        "... (+ _mask.tif) at t = 0, S, 2S, ... and sequence.json (times, and the world spec "
        "from which the true plume at any time is rebuilt); see docs/synthetic-scenes.md",
    )
    g.add_argument(
        "--frames",
        type=o.int_range(1, 10_000, "a number of frames"),
        help="number of look-ahead frames per moving scene",
    )
    g.add_argument(
        "--frame-interval-s",
        type=o.positive_seconds,
        default=10.0,
        help="seconds between frames (default 10)",
    )
    o.add_wind_options(
        g,
        mps="wind speed in m/s for every scene (default: drawn per scene, 0-16)",
        from_deg="direction the wind blows from, degrees clockwise from north (default: drawn)",
    )
    s = p.add_argument_group("strips to fly ('dyntarget fly'; --scenes strips, --size px wide)")
    s.add_argument(
        "--strip",
        action="store_true",
        help="write long moving strips (seed, seed+1, ...) with several plumes instead of scenes",
    )
    s.add_argument(
        "--plumes",
        type=o.int_range(1, MAX_VENTS, "a number of vents"),
        action=_Given,
        default=4,
        help="vents per strip (default 4; with --length-km, default 1 per 100 km)",
    )
    s.add_argument(
        "--length",
        type=o.int_range(64, MAX_WINDOW_SIDE, "a length in px"),
        help="strip length in px (default 4.5 x --size: 8 frames)",
    )
    s.add_argument(
        "--length-km",
        type=o.float_range(MIN_LENGTH_KM, MAX_LENGTH_KM, "km"),
        help=f"a pass-length strip ({MIN_LENGTH_KM:g}-{MAX_LENGTH_KM:g} km, e.g. 3000), rendered "
        f"lazily when flown; --size defaults to 256 px across (at most {MAX_LONG_WIDTH}). At most "
        f"{MAX_VENTS} vents and {MAX_CLOUDS} clouds per strip: beyond {MAX_VENTS * 100} km give a "
        "lower --plumes-per-100km (or --plumes)",
    )
    s.add_argument(
        "--plumes-per-100km",
        type=o.float_range(0.0, 100.0, "vents per 100 km", lo_open=True),
        help="vent density along a --length-km strip (default 1; or give --plumes)",
    )
    s.add_argument(
        "--clouds-per-100km",
        type=o.float_range(0.0, 100.0, "clouds per 100 km"),
        default=2.0,
        help="meteorological clouds per 100 km of a --length-km strip (default 2; at most "
        f"{MAX_CLOUDS} per strip)",
    )
    e = p.add_argument_group(
        "eruptions that start during the pass (strips)",
        "an onset on the pass clock (t = 0: the first look-ahead frame) for a share of the "
        "vents: before it the vent shows nothing (GEO images, look-ahead frames, truth); after "
        "it the plume grows downwind. The other vents erupt from long before the pass",
    )
    e.add_argument(
        "--onset-fraction",
        type=o.float_range(0.0, 1.0, "a fraction"),
        metavar="F",
        help="share of the vents (each with probability F) that start erupting at a time drawn "
        "uniformly in --onset-window-min",
    )
    e.add_argument(
        "--onset-window-min",
        type=o.minute_span,
        metavar="LO,HI",
        help="span of the onsets, minutes on the pass clock (default -60,0: the hour before "
        "the pass, when the GEO images a blueprint uses are taken)",
    )
    e.add_argument(
        "--onset-duration-min",
        type=o.minute_span,
        metavar="LO,HI",
        help="the eruptions with an onset stop after a duration drawn in LO..HI minutes "
        "(default: they do not stop)",
    )
    d = p.add_argument_group(
        "3D worlds (docs/plumes-3d.md)",
        "moving worlds (--frames, --strip) are 3D by default: plume tops and clouds carry "
        "heights, written in the world spec and as <id>.plumes.geojson beside the images (one "
        "Point per vent: plume_id, top_height_m, rise_mps, onset_s). The images written here are "
        "rendered from straight above; 'dyntarget fly' renders its look-ahead frames of a 3D "
        "strip obliquely. Static scenes stay flat (the paper's setting); --flat gives a flat "
        "moving world",
    )
    d.add_argument(
        "--plume-height-km",
        type=o.height_range,
        metavar="LO,HI",
        help="each vent's column-top height drawn in LO..HI km (default "
        f"{PLUME_HEIGHT_KM[0]:g},{PLUME_HEIGHT_KM[1]:g}); the column rises at 10-100 m/s from "
        "the eruption's onset until it reaches it",
    )
    d.add_argument(
        "--cloud-height-km",
        type=o.height_range,
        metavar="LO,HI",
        help="each cloud's height drawn in LO..HI km (default "
        f"{CLOUD_HEIGHT_KM[0]:g},{CLOUD_HEIGHT_KM[1]:g})",
    )
    d.add_argument(
        "--flat",
        action="store_true",
        help="a flat moving world (every feature on the ground, no plumes.geojson: the bytes "
        "written before worlds had heights, for the published flat-world results)",
    )
    p.set_defaults(func=cmd_synth, size_given=False, plumes_given=False)
