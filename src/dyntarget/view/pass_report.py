"""What a pass leaves in its output directory: timeline, pointings, summary, picture.

The pass's report: what :func:`dyntarget.fly.fly_pass` flew (its
:class:`~dyntarget.passes.record.PassResult`) written as files, and the list of those
files (:func:`pass_files`) a rerun replaces (:func:`commit_pass`).

The text, CSV and JSON outputs are written here; the picture and the HTML pages are
drawn by :mod:`dyntarget.view` (:mod:`~dyntarget.view.pass_figure`,
:mod:`~dyntarget.view.pass_html`), from plain arrays and frames this module takes out
of the pass.

Every file is written atomically (:mod:`dyntarget.io.atomic`); ``timeline.csv``
and ``pointings.geojson`` are rewritten after every frame, so a pass stopped at
any moment leaves complete files for the frames it finished.

A pass of at most :data:`MAX_VIEW_FRAMES` frames over a strip held in memory gets
``pass.png`` (the whole strip) and ``pass.html`` (a slider over the frames). A longer
pass, or one over a long strip rendered lazily, gets an *overview* instead, built
frame by frame in bounded memory (:class:`ViewCollector`): the strip decimated
along-track to at most :data:`OVERVIEW_ROWS` rows, the plume each frame planned on,
the flown pointings, dropped frames and (with ``--geo``) the GEO targets, as
``pass.png`` (the strip cut into lanes) and ``pass.html`` (zoomable), and the
full-resolution slider view per segment of :data:`MAX_VIEW_FRAMES` frames in
``pass-segments/`` (linked from ``pass.html``; the frames wait on disk, compressed,
until the pass is written, so memory holds one segment at a time).
"""

from __future__ import annotations

import csv
import io
import itertools
import json
import os
import shutil
import sys
import tempfile
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from dyntarget.io.atomic import write_text
from dyntarget.passes.record import STAGES, TIMELINE_COLUMNS, FrameView, PassResult

if TYPE_CHECKING:
    from dyntarget.synth.worlds import World
    from dyntarget.view.html import PassFrame
    from dyntarget.view.pass_figure import PassOverview, PassPicture

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
"""Frames of one slider view: a longer pass gets an overview and one view per segment."""
SEGMENTS = "pass-segments"
"""Folder (beside ``pass.html``) of a long pass's full-resolution views, one per segment."""
OVERVIEW_ROWS = 4096
"""Most along-track rows of a long pass's overview (each the mean of a run of WFOV rows)."""


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
    >>> from dyntarget.fly import PassConfig, fly_pass
    >>> from dyntarget.synth.worlds import StaticWorld
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
    result : dyntarget.passes.record.PassResult
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
    result : dyntarget.passes.record.PassResult
        The pass.
    world : dyntarget.synth.worlds.World
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
        acquired=world.acquired,
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
    result : dyntarget.passes.record.PassResult
        The pass so far.
    world : dyntarget.synth.worlds.World
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
    result : dyntarget.passes.record.PassResult
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

    Holds every key of :meth:`~dyntarget.passes.record.PassResult.totals` (``utility``,
    ``plumes_observed``, ``plumes_total``, ``pointings_flown``, ``ratio_plume``,
    ``frames``, ...), ``stopped``, and ``geo``: the geostationary settings and
    what the blueprint did (``None`` for a look-ahead-only pass); with the pass's
    upper bound (:func:`~dyntarget.observe.bound.pass_upper_bound`), ``upper_bound_utility``,
    ``fraction_of_bound`` (``utility`` over it) and ``upper_bound`` (how it was found).

    Parameters
    ----------
    result : dyntarget.passes.record.PassResult
        The pass.

    Returns
    -------
    str
        JSON text (keys sorted, one trailing newline).

    Examples
    --------
    >>> from dyntarget.fly import PassConfig, fly_pass
    >>> from dyntarget.synth.worlds import StaticWorld
    >>> from dyntarget.scene import Scene
    >>> img = np.full((4, 128, 32), 0.1, np.float32); lab = np.zeros((128, 32), bool)
    >>> r = fly_pass(StaticWorld(Scene(img, label=lab, gsd=8.0)), None,
    ...              PassConfig(compute_budget_s=0.5))
    >>> d = json.loads(summary_json(r)); d["frames"], d["pointings_flown"], d["geo"]
    (7, 0, None)
    """
    doc = {**result.totals(), "stopped": bool(result.stopped), "geo": result.geo}
    if result.upper_bound is not None:  # the true upper bound, and the pass as a fraction of it
        ub = result.upper_bound.get("value")
        doc["upper_bound_utility"] = ub
        doc["upper_bound"] = result.upper_bound
        doc["fraction_of_bound"] = round(doc["utility"] / ub, 4) if ub else None
    return json.dumps(doc, sort_keys=True, indent=1) + "\n"


def _s(v: float | None) -> str:
    return "-" if v is None else f"{v:.3f}"


def _pass_picture(result: PassResult, world: World) -> PassPicture:
    """What :func:`~dyntarget.view.pass_figure.draw_pass_picture` draws of a short pass.

    The strip at t = 0 (and its true plumes) averaged onto the WFOV grid, the
    frames flown, and the flown pointings.
    """
    from dyntarget.scene import block_mean
    from dyntarget.view.pass_figure import PassPicture

    f = result.config.factor
    fp = result.frames
    hw, ww = fp.wfov_shape
    image = world.image_at(0.0, 0, hw * f)[:, :, : ww * f]
    rgb = block_mean(np.asarray(image, np.float32), f)[:3].transpose(1, 2, 0)
    label = world.truth_at(0.0).maps.label[: hw * f, : ww * f]
    t = result.totals()
    fl = result.flown
    return PassPicture(
        rgb=rgb,
        plume=block_mean(label[None].astype(np.float32), f)[0],
        frame_px=fp.frame_px,
        tops=fp.tops[: len(result.records)],
        dropped=[rec.dropped for rec in result.records],
        pointings=(fl.x, fl.y, fl.t),
        title=(
            f"{result.world_id}: {result.config.planner}, {result.config.agility} agility — "
            f"{t['pointings_flown']} pointings, {t['plumes_observed']} of {t['plumes_total']} "
            "plumes observed; flight →" + _parallax_note(result)
        ),
    )


class _Overview:
    """The strip decimated along-track, built frame by frame in bounded memory.

    Each overview row is the mean of ``d`` consecutive WFOV rows (RGB and the
    plume mask the frame planned on); when more than ``max_rows`` rows are held,
    neighbouring rows are merged and ``d`` doubles, so memory stays below
    ``max_rows`` x width whatever the pass's length. Overlapping frames average.
    """

    def __init__(self, max_rows: int = OVERVIEW_ROWS) -> None:
        self.max_rows = max(2, int(max_rows))
        self.d = 1
        self.sums: dict[int, np.ndarray] = {}  # overview row -> (4, W): R, G, B, plume sums
        self.counts: dict[int, int] = {}

    def add(self, top: int, image: np.ndarray, mask: np.ndarray | None) -> None:
        img = np.asarray(image, np.float32)[:3]
        m = np.zeros(img.shape[1:], np.float32) if mask is None else np.asarray(mask, np.float32)
        stack = np.concatenate([img, m[None]], axis=0)  # (4, fh, W)
        keys = (top + np.arange(stack.shape[1])) // self.d
        starts = np.flatnonzero(np.r_[True, keys[1:] != keys[:-1]])
        sums = np.add.reduceat(stack, starts, axis=1)
        counts = np.diff(np.r_[starts, len(keys)])
        for j, k in enumerate(keys[starts].tolist()):
            if k in self.sums:
                self.sums[k] += sums[:, j]
                self.counts[k] += int(counts[j])
            else:
                self.sums[k] = sums[:, j].copy()
                self.counts[k] = int(counts[j])
        while len(self.sums) > self.max_rows:
            merged: dict[int, np.ndarray] = {}
            mc: dict[int, int] = {}
            for k, v in self.sums.items():
                if k // 2 in merged:
                    merged[k // 2] += v
                    mc[k // 2] += self.counts[k]
                else:
                    merged[k // 2] = v
                    mc[k // 2] = self.counts[k]
            self.sums, self.counts, self.d = merged, mc, self.d * 2

    def arrays(self) -> tuple[int, np.ndarray, np.ndarray] | None:
        """``(first_row, rgb (n, W, 3), plume (n, W))`` from WFOV row ``first_row * d`` on."""
        if not self.sums:
            return None
        lo, hi = min(self.sums), max(self.sums)
        w = next(iter(self.sums.values())).shape[1]
        out = np.full((hi - lo + 1, 4, w), np.nan, np.float32)
        for k, v in self.sums.items():
            out[k - lo] = v / self.counts[k]
        return lo, out[:, :3].transpose(0, 2, 1), out[:, 3]


class _Spill:
    """Frames of a long pass waiting on disk (compressed) until the pass is written."""

    def __init__(self) -> None:
        self._dir: tempfile.TemporaryDirectory[str] | None = None
        self.segments = 0

    def write(self, views: list[FrameView]) -> None:
        from shapely import to_wkb

        if self._dir is None:
            self._dir = tempfile.TemporaryDirectory(prefix="dyntarget-pass-")
        wkb = [[bytes(b) for b in to_wkb(list(v.plan.polygons))] for v in views]
        lengths = [len(b) for w in wkb for b in w]
        proba = [v.plan.probability for v in views]
        np.savez_compressed(
            Path(self._dir.name) / f"{self.segments:05d}.npz",
            frame=np.array([v.frame for v in views]),
            top=np.array([v.top for v in views]),
            first=np.array([v.first for v in views]),
            end=np.array([v.end for v in views]),
            image=np.stack([np.asarray(v.image, np.float32) for v in views]),
            probability=np.stack([np.asarray(p, np.float32) for p in proba])
            if all(p is not None for p in proba)
            else np.zeros(0, np.float32),
            n_polygons=np.array([len(w) for w in wkb], np.int64),
            wkb_lengths=np.array(lengths, np.int64),
            wkb=np.frombuffer(b"".join(b for w in wkb for b in w), np.uint8),
        )
        self.segments += 1

    def read(self, i: int) -> list[FrameView]:
        from shapely import from_wkb

        assert self._dir is not None
        with np.load(Path(self._dir.name) / f"{i:05d}.npz") as z:
            blob = z["wkb"].tobytes()
            cuts = np.r_[0, np.cumsum(z["wkb_lengths"])]
            polys = list(from_wkb([blob[a:b] for a, b in itertools.pairwise(cuts)]))
            per = np.r_[0, np.cumsum(z["n_polygons"])]
            proba = z["probability"]
            return [
                FrameView(
                    int(z["frame"][j]),
                    int(z["top"][j]),
                    z["image"][j],
                    _Planned(proba[j] if proba.size else None, polys[per[j] : per[j + 1]]),
                    int(z["first"][j]),
                    int(z["end"][j]),
                )
                for j in range(len(z["frame"]))
            ]

    def close(self) -> None:
        if self._dir is not None:
            self._dir.cleanup()
            self._dir = None


class _Planned:
    """What a spilled frame keeps of its plan: the probability and the polygons."""

    def __init__(self, probability: np.ndarray | None, polygons: list[Any]) -> None:
        self.probability, self.polygons = probability, polygons


class ViewCollector:
    """Collects the :class:`~dyntarget.passes.record.FrameView` s of a pass for its pictures.

    Up to ``max_frames`` frames are kept in memory for the slider view of a short
    pass. Every frame also feeds the long-pass overview (the strip decimated to at
    most :data:`OVERVIEW_ROWS` rows); past ``max_frames`` frames, the frames are
    written to a temporary folder, ``max_frames`` at a time (compressed), for the
    per-segment views :func:`write_pass` renders one at a time. Memory does not grow
    with the pass's length.

    Parameters
    ----------
    max_frames : int
        Frames per slider view (a segment).
    segments : bool
        Keep the frames for the per-segment views (``False``: the overview only).

    Examples
    --------
    >>> from dyntarget.fly import PassConfig, fly_pass
    >>> from dyntarget.synth.worlds import StaticWorld
    >>> from dyntarget.scene import Scene
    >>> img = np.full((4, 128, 32), 0.1, np.float32); lab = np.zeros((128, 32), bool)
    >>> views = ViewCollector(max_frames=3)
    >>> r = fly_pass(StaticWorld(Scene(img, label=lab, gsd=8.0)), None,
    ...              PassConfig(compute_budget_s=0.5), frame_sink=views)
    >>> views.n_frames, views.overflow, views.spill.segments, len(views.views)
    (7, True, 2, 1)
    >>> views.close()
    """

    def __init__(self, max_frames: int = MAX_VIEW_FRAMES, *, segments: bool = True) -> None:
        self.views: list[FrameView] = []
        self.max_frames = max(1, int(max_frames))
        self.keep_segments = segments
        self.overflow = False
        self.n_frames = 0
        self.overview = _Overview()
        self.spill = _Spill()

    def __call__(self, view: FrameView) -> None:
        self.n_frames += 1
        self.overview.add(view.top, view.image, getattr(view.plan, "mask", None))
        if not self.keep_segments:
            return
        self.views.append(view)
        if not self.overflow and len(self.views) > self.max_frames:
            self.overflow = True  # a long pass: segments from now on
            self.spill.write(self.views[: self.max_frames])
            self.views = self.views[self.max_frames :]
        elif self.overflow and len(self.views) >= self.max_frames:
            self.spill.write(self.views)
            self.views = []

    def segment_views(self) -> Iterator[list[FrameView]]:
        """The frames, one segment at a time (read back from disk for a long pass).

        Yields
        ------
        list of dyntarget.passes.record.FrameView
            At most ``max_frames`` frames, in pass order.
        """
        if not self.overflow:
            if self.views:
                yield self.views
            return
        for i in range(self.spill.segments):
            yield self.spill.read(i)
        if self.views:
            yield self.views

    def close(self) -> None:
        """Remove the frames written to disk (also done when the pass is written)."""
        self.spill.close()


def _pass_frames(result: PassResult, views: Sequence[FrameView]) -> list[PassFrame]:
    """The frames of the slider view: each frame's image, probability and polygons, and the
    pointings flown from its plan (frame pixels, coloured by their time in the pass; with
    ``defer_cut`` those held and flown after a later frame too, by their ``frame``)."""
    from dyntarget.trajectory import Trajectory
    from dyntarget.view.html import PassFrame

    fl = result.flown
    frame_of = np.asarray(fl.frame, np.int64)
    x, y, t = (np.asarray(a, np.float64) for a in (fl.x, fl.y, fl.t))
    part, plume = np.asarray(fl.part, np.int64), np.asarray(fl.plume, np.float64)
    steps = []
    for v in views:
        sl = np.flatnonzero(frame_of == v.frame)
        n = len(sl)
        traj = None
        if n:
            pts = np.column_stack([x[sl], y[sl] - v.top])
            traj = Trajectory(pts, part[sl], result.config.planner, times=t[sl])
        steps.append(
            PassFrame(
                time_s=round(result.frames.acquired_s(v.frame), 3),
                image=v.image,
                probability=v.plan.probability,
                polygons=v.plan.polygons,
                trajectory=traj,
                point_values={"plume_fraction": plume[sl].tolist()} if n else None,
                label=f"frame {v.frame}: {n} flown",
            )
        )
    return steps


def _view_title(result: PassResult) -> str:
    return f"{result.world_id}: {result.config.planner}, {result.config.agility} agility"


def _long(result: PassResult, world: World) -> bool:
    """Whether the pass gets an overview: a lazily rendered strip, or too many frames."""
    return world.is_long or result.frames.n_frames > MAX_VIEW_FRAMES


def _overview_data(result: PassResult, views: ViewCollector) -> PassOverview | None:
    """The overview in kilometres: along-track (flight direction) and across."""
    from dyntarget.view.pass_figure import PassOverview

    got = views.overview.arrays()
    if got is None:
        return None
    first, rgb, plume = got
    d = views.overview.d
    fp = result.frames
    hw, ww = fp.wfov_shape
    gsd_km = fp.geometry.wfov_gsd_m / 1e3
    n = rgb.shape[0]
    # flight from the strip's last row to its first: along = (hw - row) * gsd, increasing
    rows0, rows1 = first * d, (first + n) * d  # WFOV rows covered
    fl = result.flown
    along = (hw - 0.5 - np.asarray(fl.y, np.float64)) * gsd_km
    across = (np.asarray(fl.x, np.float64) + 0.5) * gsd_km
    dropped = np.array(
        [(hw - fp.tops[r.frame] - fp.frame_px / 2) * gsd_km for r in result.records if r.dropped]
    )
    return PassOverview(
        rgb=rgb[::-1],  # along-track increasing
        plume=plume[::-1],
        extent=((hw - rows1) * gsd_km, (hw - rows0) * gsd_km, 0.0, ww * gsd_km),
        pointings=(along, across, np.asarray(fl.t, np.float64)),
        targets=_geo_targets_km(result),
        dropped=dropped,
        rows_per_cell=d,
        km_per_cell=d * gsd_km,
        title=_overview_title(result),
    )


def _geo_targets_km(result: PassResult) -> tuple[np.ndarray, np.ndarray] | None:
    """The GEO targets of the pass (along, across) in the overview's kilometres, or None."""
    geo = result.geo or {}
    if not geo.get("target_along_cross_m"):
        return None
    ac = np.asarray(geo["target_along_cross_m"], np.float64).reshape(-1, 2)
    fp = result.frames
    g = fp.geometry
    hw, ww = fp.wfov_shape
    gsd_km = g.wfov_gsd_m / 1e3
    row = (
        (hw - fp.frame_px) + (fp.frame_px - 1) / 2.0 - (ac[:, 0] - g.look_ahead_m) / (g.wfov_gsd_m)
    )
    col = ac[:, 1] / g.wfov_gsd_m + (ww - 1) / 2.0
    return (hw - 0.5 - row) * gsd_km, (col + 0.5) * gsd_km


def _overview_title(result: PassResult) -> str:
    t = result.totals()
    return (
        f"{result.world_id}: {result.config.planner}, {result.config.agility} agility: "
        f"{t['frames']} frames, {t['pointings_flown']} pointings, "
        f"{t['plumes_observed']} of {t['plumes_total']} plumes observed" + _parallax_note(result)
    )


def _parallax_note(result: PassResult) -> str:
    """On a 3D pass: how to read the picture (the ground, with the pointings' ground aims)."""
    if not result.is_3d:
        return ""
    return (
        f"\n3D world, parallax {result.parallax}: plumes drawn on the ground, pointings where "
        "they aim on it (each meets its plume's top along its line of sight)"
    )


def write_segments(
    result: PassResult, views: ViewCollector, folder: str | os.PathLike[str], *, crs: object = None
) -> list[tuple[str, str]]:
    """Write the per-segment slider views of a long pass into ``folder`` (one at a time).

    Parameters
    ----------
    result : dyntarget.passes.record.PassResult
        The pass.
    views : ViewCollector
        What it collected (the frames spilled to disk).
    folder : str or os.PathLike
        Where the pages go, with one shared ``plotly.min.js``.
    crs : object or None
        The strip's CRS, named on the pages.

    Returns
    -------
    list of (str, str)
        ``(relative href, text)`` per page written (empty without plotly).
    """
    from dyntarget.view.pass_html import write_segment_pages

    def segments() -> Iterator[tuple[str, list[PassFrame], str]]:
        for seg in views.segment_views():  # read back one at a time
            a, b = seg[0].frame, seg[-1].frame
            n = sum(v.end - v.first for v in seg)
            title = f"{result.world_id}: frames {a}-{b} of {result.frames.n_frames}"
            yield title, _pass_frames(result, seg), f"frames {a}-{b}: {n} pointings flown"

    return write_segment_pages(segments(), folder, crs=crs)


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

    ``views``: frames collected during the pass for ``pass.html`` (none: no view),
    and for the overview picture of a long pass (see the module docstring). A
    picture or view skipped for want of matplotlib or plotly (the lean onboard
    install) is said in one line on stderr and in ``summary.md``; the rest of the
    pass is written. The pictures and pages are drawn by :mod:`dyntarget.view`.

    Parameters
    ----------
    result : dyntarget.passes.record.PassResult
        The pass.
    world : dyntarget.synth.worlds.World
        The strip it flew over.
    out : str or os.PathLike
        The output folder.
    picture : bool
        Draw the pass picture (needs matplotlib).
    views : ViewCollector or None
        Frames collected for ``pass.html`` and a long pass's overview picture (a
        collector made with ``segments=False``: the picture only, no HTML view).
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
    if not result.measured:
        written.append(out / MEASURED)
    notes: list[str] = []
    missing: list[tuple[str, str]] = []  # (file, library)
    long_pass = _long(result, world)
    pic = None
    if picture:
        pic = _write_picture(result, world, out, views, long_pass, notes, missing)
    if pic is not None:
        written.append(pic)
    if views is not None and not views.keep_segments:
        views.close()  # collected for the overview picture only (no HTML view)
    elif views is not None:
        try:
            written += _write_views(result, world, out, views, long_pass, notes, missing)
        finally:
            views.close()
    if missing:
        _say_skipped(missing)
    write_text(out / SUMMARY, summary_md(result, PICTURE if pic else None, " ".join(notes) or None))
    written.append(out / SUMMARY)
    written.append(write_text(out / SUMMARY_JSON, summary_json(result)))
    return written


def _write_picture(
    result: PassResult,
    world: World,
    out: Path,
    views: ViewCollector | None,
    long_pass: bool,
    notes: list[str],
    missing: list[tuple[str, str]],
) -> Path | None:
    """``pass.png``: the whole strip, or a long pass's overview; a skip noted in ``notes``."""
    from dyntarget.view.pass_figure import draw_pass_overview, draw_pass_picture

    if not _importable("matplotlib"):
        missing.append((PICTURE, "matplotlib"))
        notes.append(f"No {PICTURE}: matplotlib is not installed (the lean onboard install).")
        return None
    if long_pass and views is not None:
        data = _overview_data(result, views)
        return None if data is None else draw_pass_overview(data, out / PICTURE)
    if long_pass:
        notes.append(f"No {PICTURE}: a long pass's overview is drawn from its frames (HTML on).")
        return None
    return draw_pass_picture(_pass_picture(result, world), out / PICTURE)


def _write_views(
    result: PassResult,
    world: World,
    out: Path,
    views: ViewCollector,
    long_pass: bool,
    notes: list[str],
    missing: list[tuple[str, str]],
) -> list[Path]:
    """``pass.html`` (and a long pass's segment pages); what was written, noted in ``notes``."""
    from dyntarget.view.pass_html import write_overview_page, write_pass_page

    if not _importable("plotly"):
        missing.append((VIEW, "plotly"))
        notes.append(f"No {VIEW}: plotly is not installed (the lean onboard install).")
        return []
    if not (long_pass or views.overflow):
        frames = _pass_frames(result, views.views)
        page = write_pass_page(frames, out / VIEW, title=_view_title(result), crs=world.crs)
        if page is None:
            return []
        notes.append(f"Interactive view (a slider over the frames): [{VIEW}]({VIEW}).")
        return [page]
    seg_dir = out / SEGMENTS
    if seg_dir.is_dir():
        shutil.rmtree(seg_dir)  # a rerun's old segments
    links = write_segments(result, views, seg_dir, crs=world.crs)
    data = _overview_data(result, views)
    page = None if data is None else write_overview_page(data, out / VIEW, segments=links)
    if page is None:
        return []
    notes.append(
        f"Interactive overview: [{VIEW}]({VIEW}); full resolution, "
        f"{views.max_frames} frames a page: `{SEGMENTS}/` ({len(links)} pages)."
    )
    return [page, seg_dir]


def _say_skipped(missing: list[tuple[str, str]]) -> None:
    """One line on stderr naming the files skipped and the libraries they need."""
    files = " and ".join(f for f, _ in missing)
    libs = " and ".join(lib for _, lib in missing)
    verb = "is" if len(missing) == 1 else "are"
    print(
        f'dyntarget: {files} skipped: {libs} {verb} not installed (pip install "dyntarget[full]"); '
        "the rest of the pass is written",
        file=sys.stderr,
        flush=True,
    )


def _importable(module: str) -> bool:
    """Whether ``module`` can be imported (an entry of ``None`` in sys.modules: not)."""
    import importlib.util

    if module in sys.modules:
        return sys.modules[module] is not None
    try:
        return importlib.util.find_spec(module) is not None
    except (ImportError, ValueError):
        return False


TIMES = "geo.timing.json"
"""File of a pass's GEO wall-clock times (``targets_s``, ``blueprint_s``), beside ``summary.json``."""


def write_times(result: PassResult, out: str | os.PathLike[str]) -> Path | None:
    """Write the GEO wall-clock times of a pass to ``out/geo.timing.json`` (none: nothing).

    ``summary.json`` holds only what a rerun reproduces byte for byte; the measured times
    of the ground segment go here, as ``stage_times.csv`` holds the frames'.

    Parameters
    ----------
    result : dyntarget.passes.record.PassResult
        The pass (its ``geo_times``).
    out : str or os.PathLike
        The pass's output folder.

    Returns
    -------
    pathlib.Path or None
        The file written, or ``None`` for a pass without GEO.

    Examples
    --------
    >>> from types import SimpleNamespace
    >>> d = Path(tempfile.mkdtemp())
    >>> write_times(SimpleNamespace(geo_times=None), d) is None
    True
    >>> write_times(SimpleNamespace(geo_times={"targets_s": 0.5}), d).read_text().split()
    ['{', '"targets_s":', '0.5', '}']
    """
    times = result.geo_times
    if times is None:
        return None
    return write_text(Path(out) / TIMES, json.dumps(times, sort_keys=True, indent=1) + "\n")


def pass_files() -> tuple[str, ...]:
    """The names of the files a pass may write (this module's, GEO times).

    Returns
    -------
    tuple of str
        Timeline, stage times, pointings, picture, view (and a long pass's segment
        views), summaries, GEO times.

    Examples
    --------
    >>> "pass.png" in pass_files(), pass_files()[-1]
    (True, 'geo.timing.json')
    """
    return (TIMELINE, MEASURED, POINTINGS, PICTURE, VIEW, SEGMENTS, SUMMARY, SUMMARY_JSON, TIMES)


def commit_pass(stage: str | os.PathLike[str], out: str | os.PathLike[str]) -> list[Path]:
    """Commit a staged pass (:func:`dyntarget.io.staging.commit`); files of an earlier pass in
    ``out`` that it did not write go.

    Parameters
    ----------
    stage : str or os.PathLike
        The staging folder the pass was written into.
    out : str or os.PathLike
        The pass's output folder.

    Returns
    -------
    list of pathlib.Path
        The files now in ``out``.
    """
    from dyntarget.io.staging import commit

    return commit(stage, out, stale=pass_files())
