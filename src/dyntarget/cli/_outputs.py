"""Output options shared by the commands that write pointings: GeoJSON form, time, polygons, HTML."""

from __future__ import annotations

import argparse
from pathlib import Path

_OUTPUT_FLAGS = ("--out", "--figure", "--polygons", "--html")


def add_output_options(p: argparse.ArgumentParser) -> None:
    """``--crs``, ``--acquired``, ``--polygons``, ``--html`` (see docs/outputs.md)."""
    g = p.add_argument_group("outputs (fields and units: docs/outputs.md)")
    from dyntarget.cli.options import CRS

    CRS.add(g)
    g.add_argument(
        "--acquired",
        metavar="ISO-8601",
        help="acquisition time (UTC unless an offset is given), e.g. 2024-05-01T10:00:00Z; "
        "default: the image's TIFFTAG_DATETIME/ACQUISITIONDATETIME or <stem>.meta.json",
    )
    g.add_argument(
        "--polygons", metavar="OUT.geojson", help="also write the denoised plume polygons"
    )
    g.add_argument("--html", metavar="VIEW.html", help="also write the interactive HTML view")


def acquisition(args: argparse.Namespace, image: str | None):
    """``--acquired``, else what the image file says, else ``None``."""
    from dyntarget.cli._common import check_acquired
    from dyntarget.errors import InvalidParameterError
    from dyntarget.io.acquisition import parse_acquired, read_acquired

    try:
        if args.acquired:
            return check_acquired(parse_acquired(args.acquired, name="--acquired"), "--acquired")
        return check_acquired(read_acquired(image) if image else None, str(image))
    except OverflowError:  # year 1 at +14:00 is before datetime's year 1 in UTC
        what = f"--acquired {args.acquired}" if args.acquired else f"{image}: its acquisition time"
        raise InvalidParameterError(
            f"{what}: outside the years 1900..2200 dyntarget dates pointings in"
        ) from None


def write_outputs(
    args: argparse.Namespace,
    wfov,
    traj,
    *,
    polygons=None,
    probability=None,
    title: str = "",
    properties: dict | None = None,
    polygon_properties: dict | None = None,
) -> None:
    """Write ``--out`` (GeoJSON or CSV), ``--polygons`` and ``--html``; print each path.

    ``properties`` (e.g. ``{"prediction": ...}``) join the GeoJSON collections' properties;
    ``polygon_properties`` join every plume polygon's own (e.g. its top height)."""
    from dyntarget.errors import InvalidParameterError
    from dyntarget.io.geojson import write_polygons, write_trajectory

    # validate every output before writing any of them: nothing half-written
    if args.polygons and polygons is None:
        raise InvalidParameterError(f"--polygons: planner {args.planner} made no plume polygons")
    if args.polygons and Path(args.polygons).suffix.lower() not in (".geojson", ".json"):
        raise InvalidParameterError(f"--polygons: expected a .geojson path, got {args.polygons!r}")
    if args.html and Path(args.html).suffix.lower() not in (".html", ".htm"):
        raise InvalidParameterError(f"--html: expected a .html path, got {args.html!r}")
    named = [(f, getattr(args, f.strip("-").replace("-", "_"), None)) for f in _OUTPUT_FLAGS]
    seen: dict[Path, str] = {}
    for flag, value in named:
        if value is None:
            continue
        where = Path(value).absolute()
        if where in seen:
            raise InvalidParameterError(
                f"{flag} {value}: the same path as {seen[where]}; expected different outputs"
            )
        if where.is_dir():
            raise InvalidParameterError(f"{flag} {value}: is a directory; expected a file path")
        seen[where] = flag
    when = acquisition(args, args.image[0])
    georef = {"transform": wfov.transform, "crs": wfov.crs, "acquired": when}
    if args.html:  # plotly is optional: fail before anything is written
        from dyntarget.view import require_plotly

        require_plotly()
    print(write_trajectory(args.out, traj, crs_mode=args.crs, properties=properties, **georef))
    if args.polygons:
        print(
            write_polygons(
                args.polygons,
                polygons,
                crs_mode=args.crs,
                properties=properties,
                feature_properties=polygon_properties,
                **georef,
            )
        )
    if args.html:
        from dyntarget.observe import pointing_truth
        from dyntarget.view import write_scene_view

        truth = None
        if getattr(args, "mask", None) and wfov.label is not None:
            truth = pointing_truth(traj, wfov.image, wfov.label)
        print(
            write_scene_view(
                args.html,
                wfov.image,
                probability=probability,
                polygons=polygons or (),
                trajectory=traj,
                point_values=truth,
                title=title or f"{wfov.id}: {args.planner}",
                **georef,
            )
        )
