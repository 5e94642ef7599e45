"""Many passes: every strip of a directory x planners x agility presets, as resumable tasks.

Each pass is one task of :func:`dyntarget.evaluate.distributed.run_tasks`
(here, on Dask with ``scheduler``; finished passes kept in ``OUT/parts`` and
not flown again). Each pass writes its own outputs to
``OUT/passes/<strip>-<planner>-<agility>/``; the campaign writes one tidy table,
``OUT/campaign.csv`` (and ``.md``), one row per pass (:meth:`PassResult.totals`).
"""

from __future__ import annotations

import csv
import functools
import hashlib
import io
import os
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from dyntarget.errors import DataFileError, InvalidParameterError
from dyntarget.fly.loop import fly_pass
from dyntarget.io.atomic import write_text
from dyntarget.passes.record import PassConfig

if TYPE_CHECKING:
    from dyntarget.passes.geo import GeoSettings

COLUMNS = (
    "strip",
    "planner",
    "agility",
    "frames",
    "frames_dropped",
    "deadlines_missed",
    "pointings_flown",
    "plume_px",
    "utility",
    "ratio_plume",
    "plumes_observed",
    "plumes_total",
    "latency_median_s",
    "latency_max_s",
)


def strips_in(directory: str | os.PathLike[str]) -> list[Path]:
    """The strip GeoTIFFs of a directory (``<id>.tif``, not masks), sorted.

    Parameters
    ----------
    directory : a folder of strips (``dyntarget synth --strip`` output or GeoTIFFs with labels).

    Returns
    -------
    list of paths.
    """
    from dyntarget.io import scene_ids
    from dyntarget.io.safeopen import check_regular

    directory = Path(directory)
    ids = scene_ids(directory)
    if not ids:
        raise DataFileError(f"--campaign {directory}: no strips (<id>.tif files) found")
    strips = [directory / f"{i}.tif" for i in ids]
    for s in strips:  # a FIFO, a device link, a folder named *.tif: refused before any pass
        for p in strip_files(s):
            check_regular(p, what="--campaign strip file")
    return strips


STRIP_SUFFIXES = (".tif", "_mask.tif", ".geojson", ".world.json", ".meta.json")
"""The files of strip ``<id>``: ``<id>`` + each suffix (others in the folder are ignored)."""


def strip_files(strip: Path) -> list[Path]:
    """The files of a strip that exist (or are links): image, mask or GeoJSON label, sidecars.

    Names are built, never globbed, so ``strip-[0].tif`` is one strip, and other files
    beside it (``strip-0000.notes/``, ``strip-0000.lock``, a dangling ``strip-0000.old``)
    are not read.

    Parameters
    ----------
    strip : pathlib.Path
        The strip's ``<id>.tif``.

    Returns
    -------
    list of pathlib.Path
        In :data:`STRIP_SUFFIXES` order.

    Examples
    --------
    >>> import tempfile
    >>> d = Path(tempfile.mkdtemp())
    >>> for n in ("s[0].tif", "s[0].world.json", "s[0].lock", "s0.tif"): _ = (d / n).write_text("")
    >>> [p.name for p in strip_files(d / "s[0].tif")]
    ['s[0].tif', 's[0].world.json']
    """
    stem = strip.name[: -len(".tif")] if strip.name.endswith(".tif") else strip.stem
    paths = [strip.with_name(stem + suffix) for suffix in STRIP_SUFFIXES]
    return [p for p in paths if p.exists() or p.is_symlink()]


@functools.lru_cache(maxsize=4)
def _classifier(model: str | None, onnx: bool, int8: bool = False):
    if model is None:
        return None
    if onnx or int8:
        from dyntarget.perceive.onnx import load_onnx

        return load_onnx(model, int8=int8)
    from dyntarget.perceive import load_classifier

    return load_classifier(model)


def _digest(path: Path) -> str:
    h = hashlib.sha1(usedforsecurity=False)
    for p in strip_files(path):  # the image, its label, its sidecars; nothing else
        h.update(p.name.encode())
        h.update(_file_digest(p))
    return h.hexdigest()[:16]


def _file_digest(p: Path) -> bytes:
    import stat

    from dyntarget.io.safeopen import check_regular

    check_regular(p, what="--campaign strip file")
    fd = os.open(p, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    with os.fdopen(fd, "rb") as f:
        if not stat.S_ISREG(os.fstat(f.fileno()).st_mode):
            raise DataFileError(f"--campaign strip file {p}: not a regular file")
        return hashlib.file_digest(f, "sha1").digest()


def fly_one(
    task: dict[str, str],
    *,
    config: PassConfig,
    model: str | None,
    onnx: bool,
    out: str,
    truth_step_s: float,
    int8: bool = False,
    geo: GeoSettings | None = None,
) -> dict[str, Any]:
    """Fly one pass of a campaign and write its outputs; return its row of totals.

    Parameters
    ----------
    task : dict of str to str
        ``strip`` (the strip file), ``planner`` and ``agility`` of the pass.
    config : dyntarget.passes.record.PassConfig
        The pass settings (the task's planner and agility replace its own).
    model : str or None
        The classifier's model directory (``None``: plan on the truth).
    onnx : bool
        Run the exported ONNX model rather than the native one.
    out : str
        The campaign's output folder; the pass goes to ``out/passes/<strip>-<planner>-<agility>``.
    truth_step_s : float
        Time grid of the moving strip's truth, seconds.
    int8 : bool
        Run the INT8 ONNX export (``model.int8.onnx``) instead.
    geo : dyntarget.passes.geo.GeoSettings or None
        Fly with a GEO blueprint (``None``: look-ahead only).

    Returns
    -------
    dict
        :meth:`~dyntarget.passes.record.PassResult.totals` of the pass.
    """
    from dyntarget.synth.strip_world import load_world
    from dyntarget.view.pass_report import write_pass

    world = load_world(task["strip"], truth_step_s=truth_step_s)
    cfg = replace(config, planner=task["planner"], agility=task["agility"])
    if geo is not None:
        geo.check_against(world.gsd * cfg.factor)
    result = fly_pass(world, _classifier(model, onnx, int8), cfg, geo=geo)
    strip = Path(task["strip"])  # named after the strip file: unique in its folder, unlike world.id
    stem = strip.name[: -len(".tif")] if strip.name.endswith(".tif") else strip.stem
    from dyntarget.io.staging import discard, new_stage
    from dyntarget.view.pass_report import commit_pass, write_times

    where = Path(out) / "passes" / f"{stem}-{cfg.planner}-{cfg.agility}"
    stage = new_stage(where)  # an earlier pass there is replaced only by a complete one
    try:
        write_pass(result, world, stage, picture=False)
        write_times(result, stage)
        commit_pass(stage, where)
    except BaseException:
        discard(stage)
        raise
    return {**result.totals(), "strip": stem}


def run_campaign(
    strips: list[Path],
    planners: tuple[str, ...],
    agilities: tuple[str, ...],
    out: str | os.PathLike[str],
    *,
    config: PassConfig,
    model: str | None = None,
    onnx: bool = False,
    int8: bool = False,
    scheduler: str | None = None,
    truth_step_s: float = 1.0,
    progress: bool = True,
    geo: GeoSettings | None = None,
) -> list[dict[str, Any]]:
    """Fly every strip x planner x preset; write ``campaign.csv``/``.md``; return the rows.

    Parameters
    ----------
    strips : strip files (see :func:`strips_in`).
    planners, agilities : registered planner names and agility presets.
    out : output folder.
    config : settings shared by every pass (its planner and agility are replaced per task).
    model, onnx : the classifier's model directory (``None``: plan on the truth) and
        whether to run its ONNX export.
    int8 : run its INT8 ONNX export (``export-onnx --int8``) instead.
    scheduler : ``None``, ``"local"``, ``"processes"`` or a Dask scheduler address.
    truth_step_s : time quantum of moving strips' truth.
    progress : show a progress bar.
    geo : GEO settings (:class:`dyntarget.passes.geo.GeoSettings`) for every pass, or ``None``.

    Returns
    -------
    list of rows (dicts with :data:`COLUMNS`), in strip, planner, preset order.
    """
    from dyntarget.evaluate.distributed import run_tasks

    _check_axes(planners, agilities)
    out = Path(out)
    tasks = [
        {"strip": str(s), "planner": p, "agility": a}
        for s in strips
        for p in planners
        for a in agilities
    ]
    key = _task_key(strips, config, model, onnx, int8, truth_step_s, geo)
    rows = run_tasks(
        fly_one,
        tasks,
        key=key,
        parts=out / "parts",
        scheduler=scheduler,
        shared={
            "config": config,
            "model": model,
            "onnx": onnx,
            "int8": int8,
            "out": str(out),
            "truth_step_s": truth_step_s,
            "geo": geo,
        },
        progress=progress,
        desc="passes",
    )
    write_text(out / "campaign.csv", _csv(rows))
    write_text(out / "campaign.md", _markdown(rows))
    return rows


def _check_axes(planners: tuple[str, ...], agilities: tuple[str, ...]) -> None:
    """Refuse an empty axis, an unknown planner or an unknown agility preset."""
    from dyntarget.plan import PLANNERS
    from dyntarget.schedule import get_agility

    if not planners or not agilities:
        raise InvalidParameterError("campaign: give at least one planner and one agility preset")
    for p in planners:
        PLANNERS.get(p)
    for a in agilities:
        get_agility(a)


def _task_key(
    strips: list[Path],
    config: PassConfig,
    model: str | None,
    onnx: bool,
    int8: bool,
    truth_step_s: float,
    geo: GeoSettings | None,
) -> Callable[[dict[str, str]], str]:
    """The key of a pass's part: the strip's bytes, planner, preset, model and settings."""
    from dyntarget.evaluate.distributed import task_key

    digests = {str(s): _digest(s) for s in strips}
    runtime = (onnx, "int8") if int8 else (onnx,)  # FP32 keys as before: parts stay valid
    model_id = None if model is None else (model, *runtime, _model_digest(Path(model)))
    settings = {**config.as_dict(), "truth_step_s": truth_step_s}
    if geo is not None:  # passes without --geo keep their keys (parts stay valid)
        from dataclasses import asdict

        settings["geo"] = asdict(geo)

    def key(task: dict[str, str]) -> str:
        return task_key(
            "fly", digests[task["strip"]], task["planner"], task["agility"], model_id, settings
        )

    return key


def _model_digest(model: Path) -> str:
    h = hashlib.sha1(usedforsecurity=False)
    for p in sorted(model.glob("*")) if model.is_dir() else []:
        if p.is_file() and not p.is_symlink():  # is_file: no FIFO, no device
            h.update(p.name.encode())
            h.update(_file_digest(p))
    return h.hexdigest()[:16]


def _csv(rows: list[dict[str, Any]]) -> str:
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=list(COLUMNS), lineterminator="\n", extrasaction="ignore")
    w.writeheader()
    w.writerows(rows)
    return buf.getvalue()


def _markdown(rows: list[dict[str, Any]]) -> str:
    lines = ["| " + " | ".join(COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
    for r in rows:
        lines.append("| " + " | ".join("-" if r[c] is None else str(r[c]) for c in COLUMNS) + " |")
    return "\n".join(lines) + "\n"
