"""What a pass leaves in its output directory: timeline, pointings, summary, picture.

Every file is written atomically (:mod:`dyntarget.io.atomic`); ``timeline.csv``
and ``pointings.geojson`` are rewritten after every frame, so a pass stopped at
any moment leaves complete files for the frames it finished.
"""

from __future__ import annotations

import csv
import io
import json
import os
from pathlib import Path
from typing import Any

import numpy as np

from dyntarget.fly.loop import STAGES, TIMELINE_COLUMNS, FrameView, PassResult
from dyntarget.fly.world import World
from dyntarget.io.atomic import atomic_path, write_text

TIMELINE = "timeline.csv"
POINTINGS = "pointings.geojson"
SUMMARY = "summary.md"
SUMMARY_JSON = "summary.json"
SUMMARY_KEYS = (
    "utility",
    "plumes_observed",
    "plumes_total",
    "pointings_flown",
    "ratio_plume",
    "frames",
    "geo",
)
"""Keys every ``summary.json`` has (with the rest of :meth:`PassResult.totals`)."""
PICTURE = "pass.png"
MEASURED = "stage_times.csv"
VIEW = "pass.html"
MAX_VIEW_FRAMES = 64
"""Passes with more frames get no HTML view (each frame's image is embedded)."""


def timeline_csv(result: PassResult) -> str:
    """The timeline as CSV text (one row per frame; columns :data:`TIMELINE_COLUMNS`).

    Parameters
    ----------
    result : a (possibly partial) pass.

    Returns
    -------
    str: CSV with a header row.

    Examples
    --------
    >>> from dyntarget.fly.loop import PassConfig, fly_pass
    >>> from dyntarget.fly.world import StaticWorld
    >>> from dyntarget.scene import Scene
    >>> img = np.full((4, 128, 32), 0.1, np.float32); lab = np.zeros((128, 32), bool)
    >>> r = fly_pass(StaticWorld(Scene(img, label=lab, gsd=8.0)), None,
    ...              PassConfig(compute_budget_s=0.5))
    >>> timeline_csv(r).splitlines()[1].split(",")[:5]
    ['0', '0.0000', '0.0000', '0.5000', '0.5000']
    """
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=list(TIMELINE_COLUMNS), lineterminator="\n")
    writer.writeheader()
    for rec in result.records:
        writer.writerow(rec.row(measured=result.measured))
    return buf.getvalue()


def measured_csv(result: PassResult) -> str:
    """Measured stage wall times per frame (written beside a fixed-budget timeline).

    Parameters
    ----------
    result : dyntarget.fly.loop.PassResult
        The pass.

    Returns
    -------
    str
        CSV text: ``frame``, one ``<stage>_s`` column per stage and ``loop_s``.
    """
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(["frame", *(f"{s}_s" for s in STAGES), "loop_s"])
    for rec in result.records:
        stages = [f"{rec.stage_s.get(s, 0.0):.6f}" for s in STAGES]
        writer.writerow([rec.frame, *stages, f"{rec.loop_s:.6f}"])
    return buf.getvalue()


def pointings_geojson(
    result: PassResult, world: World, *, crs_mode: str = "rfc7946"
) -> dict[str, Any]:
    """The flown pointings as GeoJSON (:func:`dyntarget.io.geojson.trajectory_geojson`).

    RFC 7946 (WGS 84 lon/lat) for a georeferenced strip, unless ``crs_mode`` is
    ``"native"``; pixel coordinates of the strip's WFOV grid otherwise. Each
    pointing carries ``order``, ``part`` (plume visited, numbered over the
    pass), ``time_s`` (seconds after the first frame's acquisition; with the
    strip's acquisition time, an ISO-8601 ``time``), ``frame`` (whose plan it
    came from) and ``plume_fraction`` (what it observed of the truth at its time).

    Parameters
    ----------
    result : dyntarget.fly.loop.PassResult
        The pass.
    world : dyntarget.fly.world.World
        The strip it flew over (its CRS and transform).
    crs_mode : {"rfc7946", "native"}
        WGS 84 coordinates, or the strip's CRS.

    Returns
    -------
    dict
        The GeoJSON ``FeatureCollection``.
    """
    from dyntarget.io.geojson import trajectory_geojson

    traj = result.flown.trajectory(result.config.planner, result.config.as_dict())
    transform = None
    if world.transform is not None:
        from affine import Affine

        transform = world.transform @ Affine.scale(result.config.factor)
    return trajectory_geojson(
        traj,
        transform=transform,
        crs=world.crs,
        crs_mode=crs_mode,
        acquired=getattr(world, "acquired", None),
        point_properties={
            "frame": list(result.flown.frame),
            "plume_fraction": [round(p, 4) for p in result.flown.plume],
        },
        properties={"strip": result.world_id, "frames": len(result.records)},
    )


def write_progress(
    result: PassResult, world: World, out: str | os.PathLike[str], *, crs_mode: str = "rfc7946"
) -> None:
    """Rewrite ``timeline.csv`` and ``pointings.geojson`` (after every frame).

    Parameters
    ----------
    result : dyntarget.fly.loop.PassResult
        The pass so far.
    world : dyntarget.fly.world.World
        The strip it flies over.
    out : str or os.PathLike
        The output folder.
    crs_mode : {"rfc7946", "native"}
        Coordinates of the pointings' GeoJSON.
    """
    from dyntarget.io.geojson import write_geojson

    out = Path(out)
    write_text(out / TIMELINE, timeline_csv(result))
    if not result.measured:
        write_text(out / MEASURED, measured_csv(result))
    write_geojson(out / POINTINGS, pointings_geojson(result, world, crs_mode=crs_mode))


def summary_md(result: PassResult, picture: str | None, note: str | None = None) -> str:
    """The pass summary in Markdown: settings, totals, latency.

    Parameters
    ----------
    result : dyntarget.fly.loop.PassResult
        The pass.
    picture : str or None
        File name of the pass picture to show (``None``: no picture).
    note : str or None
        A line to add.

    Returns
    -------
    str
        The Markdown text.
    """
    t = result.totals()
    c = result.config
    fp = result.frames
    lat = "fixed budget" if not result.measured else "measured"
    lines = [
        f"# Pass over {result.world_id}",
        "",
        f"- planner **{c.planner}**, agility **{c.agility}**, WFOV factor {c.factor}, "
        f"footprint {c.footprint} WFOV px",
        f"- {fp.n_frames} frames of {fp.frame_px} x {fp.wfov_shape[1]} WFOV px, "
        f"every {fp.cadence_s:.3f} s ({fp.step} rows apart, overlap {c.overlap:g}); "
        f"look-ahead {c.look_ahead_m / 1e3:g} km at {c.altitude_m / 1e3:g} km altitude",
        f"- compute latency: {lat}"
        + (f" ({c.compute_budget_s:g} s per frame)" if c.compute_budget_s else "")
        + (f"; deadline {c.deadline_s:g} s per frame" if c.deadline_s else ""),
    ]
    if result.stopped:
        lines.append(f"- **stopped** after {len(result.records)} of {fp.n_frames} frames")
    lines += [
        "",
        "| frames | dropped | deadlines missed | pointings flown | plumes observed "
        "| plume px | utility (intensity) | ratio plume | latency median / max (s) |",
        "|---|---|---|---|---|---|---|---|---|",
        f"| {t['frames']} | {t['frames_dropped']} | {t['deadlines_missed']} "
        f"| {t['pointings_flown']} | {t['plumes_observed']} of {t['plumes_total']} "
        f"| {t['plume_px']:.2f} | {t['utility']:.2f} | {t['ratio_plume']:.3f} "
        f"| {_s(t['latency_median_s'])} / {_s(t['latency_max_s'])} |",
        "",
        "Plume px: the plume fraction of each flown pointing's footprint, summed; utility: its "
        "intensity utility, summed (both scored against the truth at the pointing's time). "
        "Per-frame rows: `timeline.csv`; pointings: `pointings.geojson`.",
    ]
    if picture:
        lines += ["", f"![the pass]({picture})"]
    if note:
        lines += ["", note]
    return "\n".join(lines) + "\n"


def summary_json(result: PassResult) -> str:
    """The pass totals as JSON (``summary.json``, beside ``summary.md``).

    Holds every key of :meth:`~dyntarget.fly.loop.PassResult.totals` (``utility``,
    ``plumes_observed``, ``plumes_total``, ``pointings_flown``, ``ratio_plume``,
    ``frames``, ...), ``stopped``, and ``geo``: the geostationary settings and
    what the blueprint did (``None`` for a look-ahead-only pass).

    Parameters
    ----------
    result : dyntarget.fly.loop.PassResult
        The pass.

    Returns
    -------
    str
        JSON text (keys sorted, one trailing newline).

    Examples
    --------
    >>> from dyntarget.fly.loop import PassConfig, fly_pass
    >>> from dyntarget.fly.world import StaticWorld
    >>> from dyntarget.scene import Scene
    >>> img = np.full((4, 128, 32), 0.1, np.float32); lab = np.zeros((128, 32), bool)
    >>> r = fly_pass(StaticWorld(Scene(img, label=lab, gsd=8.0)), None,
    ...              PassConfig(compute_budget_s=0.5))
    >>> d = json.loads(summary_json(r)); d["frames"], d["pointings_flown"], d["geo"]
    (7, 0, None)
    """
    doc = {**result.totals(), "stopped": bool(result.stopped), "geo": result.geo}
    return json.dumps(doc, sort_keys=True, indent=1) + "\n"


def _s(v: float | None) -> str:
    return "-" if v is None else f"{v:.3f}"


def draw_pass(result: PassResult, world: World, path: str | os.PathLike[str]) -> Path | None:
    """Draw the strip with its frames, true plumes and flown pointings to a PNG.

    Returns ``None`` (and draws nothing) when matplotlib is not installed
    (the lean onboard install).

    Parameters
    ----------
    result : dyntarget.fly.loop.PassResult
        The pass.
    world : dyntarget.fly.world.World
        The strip it flew over.
    path : str or os.PathLike
        The PNG to write.

    Returns
    -------
    pathlib.Path or None
        The PNG written, or ``None`` without matplotlib.
    """
    try:
        import matplotlib

        matplotlib.use("Agg", force=False)
        import matplotlib.pyplot as plt
        from matplotlib.patches import Rectangle
    except ImportError:
        return None
    if not hasattr(world, "truth_at") or getattr(world, "truth_rows", None) is not None:
        return None  # a long strip: no whole-strip picture (it is never rendered whole)
    f = result.config.factor
    fp = result.frames
    hw, ww = fp.wfov_shape
    image = world.image_at(0.0, 0, hw * f)[:, :, : ww * f]
    from dyntarget.scene import block_mean

    rgb = np.clip(block_mean(np.asarray(image, np.float32), f)[:3].transpose(1, 2, 0) * 2.5, 0, 1)
    label = world.truth_at(0.0).maps.label[: hw * f, : ww * f]
    lab = block_mean(label[None].astype(np.float32), f)[0]
    # the strip lies on its side: flight direction to the right
    fig, ax = plt.subplots(figsize=(min(16.0, 2.0 + hw / ww * 2.4), 4.6), dpi=110)
    ax.imshow(np.rot90(rgb, -1), origin="upper", interpolation="nearest")
    ax.contour(np.rot90(lab, -1), levels=[0.5], colors="orange", linewidths=0.8)
    for k, top in enumerate(fp.tops[: len(result.records)]):
        # rotated: strip row r -> x = hw - 1 - r; frames as bars under the strip, two lanes
        colour = "red" if result.records[k].dropped else "tab:blue"
        lane = ww + 1.0 + (k % 2) * 0.11 * ww
        ax.add_patch(
            Rectangle(
                (hw - (top + fp.frame_px) - 0.5, lane),
                fp.frame_px,
                0.1 * ww,
                facecolor=colour,
                edgecolor="white",
                linewidth=0.6,
            )
        )
        ax.text(hw - top - fp.frame_px / 2 - 0.5, lane + 0.05 * ww, str(k), fontsize=8,
                color="w", fontweight="bold", ha="center", va="center")  # fmt: skip
    ax.set_ylim(ww + 1.5 + 0.22 * ww, -0.5)
    fl = result.flown
    if fl.x:
        sc = ax.scatter(
            hw - 1 - np.asarray(fl.y), fl.x, c=fl.t, s=6, cmap="viridis", edgecolors="none"
        )
        fig.colorbar(sc, ax=ax, label="pointing time (s)", fraction=0.03, pad=0.01)
    t = result.totals()
    ax.set_title(
        f"{result.world_id}: {result.config.planner}, {result.config.agility} agility — "
        f"{t['pointings_flown']} pointings, {t['plumes_observed']} of {t['plumes_total']} plumes "
        "observed; flight →",
        fontsize=9,
    )
    from matplotlib.lines import Line2D

    ax.legend(
        handles=[
            Line2D([], [], color="orange", lw=1.2, label="true plumes at t = 0"),
            Rectangle((0, 0), 1, 1, facecolor="tab:blue", label="frame k (planned)"),
            Rectangle((0, 0), 1, 1, facecolor="red", label="frame k (dropped: late)"),
            Line2D(
                [],
                [],
                color="tab:green",
                lw=0,
                marker="o",
                ms=4,
                label="pointing flown (colour: time)",
            ),
        ],
        loc="upper left",
        bbox_to_anchor=(0, -0.22),
        ncol=4,
        fontsize=8,
        frameon=False,
    )
    ax.set_xlabel("along track (WFOV px)")
    ax.set_ylabel("across (px)")
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png")
    plt.close(fig)
    return Path(path)


class ViewCollector:
    """Collects :class:`~dyntarget.fly.loop.FrameView` s during a pass for :func:`write_view`.

    Keeps at most ``max_frames`` frames (each holds its WFOV image); beyond that
    the view is not written.

    Parameters
    ----------
    max_frames : int
        Most frames kept.
    """

    def __init__(self, max_frames: int = MAX_VIEW_FRAMES) -> None:
        self.views: list[FrameView] = []
        self.max_frames = max_frames
        self.overflow = False

    def __call__(self, view: FrameView) -> None:
        if len(self.views) >= self.max_frames:
            self.overflow = True
            self.views.clear()
        if not self.overflow:
            self.views.append(view)


def write_view(
    result: PassResult,
    views: list[FrameView],
    path: str | os.PathLike[str],
    *,
    crs: object | None = None,
) -> Path | None:
    """The interactive HTML view of the pass: one slider step per frame (plotly, inline).

    Each step shows the frame's WFOV image, the classifier's probability, the
    denoised polygons and the pointings flown from that frame's plan (frame
    pixels, coloured by their time in the pass). ``None`` when plotly is not
    installed (the lean onboard install).

    Parameters
    ----------
    result : dyntarget.fly.loop.PassResult
        The pass.
    views : list of dyntarget.fly.loop.FrameView
        The frames to show.
    path : str or os.PathLike
        The HTML file to write.
    crs : object or None
        The strip's CRS, named on the page (the frames are drawn in their own pixels).

    Returns
    -------
    pathlib.Path or None
        The page written, or ``None`` without plotly.
    """
    try:
        from dyntarget.view.html import PassFrame, write_pass_view
        from dyntarget.view.html import _plotly as need_plotly

        need_plotly()
    except Exception:  # plotly absent: no view
        return None
    from dyntarget.trajectory import Trajectory

    fl = result.flown
    steps = []
    for v in views:
        sl = slice(v.first, v.end)
        n = v.end - v.first
        traj = None
        if n:
            pts = np.column_stack([fl.x[sl], np.asarray(fl.y[sl]) - v.top])
            traj = Trajectory(
                pts, np.asarray(fl.part[sl]), result.config.planner, times=np.asarray(fl.t[sl])
            )
        steps.append(
            PassFrame(
                time_s=round(result.frames.acquired_s(v.frame), 3),
                image=v.image,
                probability=v.plan.probability,
                polygons=v.plan.polygons,
                trajectory=traj,
                point_values={"plume_fraction": fl.plume[sl]} if n else None,
                label=f"frame {v.frame}: {n} flown",
            )
        )
    if not steps:
        return None
    title = f"{result.world_id}: {result.config.planner}, {result.config.agility} agility"
    return write_pass_view(path, steps, title=title, crs=crs)


def write_pass(
    result: PassResult,
    world: World,
    out: str | os.PathLike[str],
    *,
    picture: bool = True,
    views: ViewCollector | None = None,
    crs_mode: str = "rfc7946",
) -> list[Path]:
    """Write every output of a (possibly stopped) pass into ``out``; return the paths.

    ``views``: frames collected during the pass for ``pass.html`` (none: no view).

    Parameters
    ----------
    result : dyntarget.fly.loop.PassResult
        The pass.
    world : dyntarget.fly.world.World
        The strip it flew over.
    out : str or os.PathLike
        The output folder.
    picture : bool
        Draw the pass picture (needs matplotlib).
    views : ViewCollector or None
        Frames collected for ``pass.html``.
    crs_mode : {"rfc7946", "native"}
        Coordinates of the pointings' GeoJSON.

    Returns
    -------
    list of pathlib.Path
        The files written.
    """
    out = Path(out)
    write_progress(result, world, out, crs_mode=crs_mode)
    written = [out / TIMELINE, out / POINTINGS]
    notes = []
    pic = draw_pass(result, world, out / PICTURE) if picture else None
    if picture and pic is None:
        if getattr(world, "truth_rows", None) is not None:
            notes.append("No picture: a long strip is never rendered whole.")
        else:
            notes.append("No picture: matplotlib is not installed (the lean onboard install).")
    if pic is not None:
        written.append(pic)
    if views is not None:
        page = (
            None if views.overflow else write_view(result, views.views, out / VIEW, crs=world.crs)
        )
        if page is not None:
            written.append(page)
            notes.append(f"Interactive view (a slider over the frames): [{VIEW}]({VIEW}).")
        elif views.overflow:
            notes.append(f"No {VIEW}: more than {views.max_frames} frames.")
        else:
            notes.append(f"No {VIEW}: plotly is not installed (the lean onboard install).")
    write_text(out / SUMMARY, summary_md(result, PICTURE if pic else None, " ".join(notes) or None))
    written.append(out / SUMMARY)
    written.append(write_text(out / SUMMARY_JSON, summary_json(result)))
    return written
