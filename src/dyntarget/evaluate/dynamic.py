"""The paper's metrics when the plume moves: every pointing scored at its own time.

For each fold of the usual scene split (:func:`~dyntarget.evaluate.crossval.kfold_indices`
over the *sequences*), each classifier is trained on the WFOV decision frames
(the last look-ahead frame) of the training sequences, or loaded from
``models_dir``. For every held-out sequence, every classifier (and the true
mask of the decision frame, ``true-mask``), every *mode*, every look-ahead
planner and every latency:

1. the mode turns the look-ahead frames and the mask into a planned trajectory
   (:data:`MODES`; ``static`` is the paper's pipeline: denoise, then plan where
   the plume was seen);
2. the plan is timed by the kinematic schedule
   (:func:`~dyntarget.schedule.make_feasible`) starting ``latency`` seconds
   after the decision frame (onboard latency: acquisition to decision);
3. each pointing is scored against the truth at its own time
   (:func:`~dyntarget.observe.observe_at`): the decision frame's time plus its
   scheduled time. Synthetic sequences rebuild the truth at any time from their
   stored world spec; for other sequences it is the labelled frame last acquired
   at or before that time.

The baselines ignore the mask: they are planned once per scene (classifier
``N/A``, mode ``static``) and scored at every latency in the same way.

Rows of ``dynamic.csv`` are means over held-out sequences per
mode x classifier x planner x latency x wind bin.

Adding a mode: write ``fn(ctx: ModeContext) -> Trajectory`` and add it to
:data:`MODES` (an object or a lazy ``"module:function"`` string).
"""

from __future__ import annotations

import importlib
import json
import math
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from dyntarget import defaults
from dyntarget.errors import InvalidParameterError, UnknownNameError
from dyntarget.evaluate.crossval import kfold_indices, train_or_load
from dyntarget.evaluate.distributed import check_scheduler, run_tasks, task_key
from dyntarget.evaluate.options import RunOptions, TrainingConfig
from dyntarget.evaluate.tables import display
from dyntarget.observe import observe_at
from dyntarget.perceive import CLASSIFIERS
from dyntarget.perceive.base import Classifier, Predictor
from dyntarget.pipeline import (
    PipelineConfig,
    classify,
    plan_segmentation,
    schedule_on_prediction,
    segment,
)
from dyntarget.plan import BASELINES, PAPER_PLANNERS, PLANNERS, Trajectory
from dyntarget.schedule import AGILITY, OrbitGeometry, Schedule
from dyntarget.sequence import FrameSequence

DEFAULT_LATENCIES: tuple[float, ...] = defaults.DYNAMIC_LATENCIES_S
"""Seconds from the decision frame's acquisition to the start of pointing."""

WIND_BINS: tuple[tuple[float, float], ...] = defaults.DYNAMIC_WIND_BINS_MPS
"""Wind speed bins, m/s (lower bound inclusive)."""

TRUE_MASK = "true-mask"
"""Classifier name meaning: plan on the decision frame's true mask."""

DYNAMIC_COLUMNS = [
    "mode",
    "classifier",
    "planner",
    "latency_s",
    "wind_bin",
    "scenes",
    "pixels_observed",
    "ratio_plume",
    "intensity",
    "gradient",
]


def wind_bin(speed_mps: float | None) -> str:
    """The label of the :data:`WIND_BINS` bin holding ``speed_mps`` (``unknown`` for None).

    Parameters
    ----------
    speed_mps : float or None
        Wind speed, m/s.

    Returns
    -------
    str
        ``"LO-HI"``, ``"LO+"`` for the last bin, or ``"unknown"``.

    Examples
    --------
    >>> wind_bin(0.0), wind_bin(10.0), wind_bin(16.0), wind_bin(None)
    ('0-2', '8-12', '16+', 'unknown')
    """
    if speed_mps is None or not math.isfinite(speed_mps):
        return "unknown"
    for lo, hi in WIND_BINS:
        if lo <= speed_mps < hi:
            return f"{lo:g}+" if math.isinf(hi) else f"{lo:g}-{hi:g}"
    return "unknown"


def sequence_wind(seq: FrameSequence) -> float | None:
    """Wind speed (m/s) recorded with a sequence: the world spec's, or ``meta["wind"]["speed_mps"]``.

    Parameters
    ----------
    seq : dyntarget.sequence.FrameSequence
        The sequence.

    Returns
    -------
    float or None
        Wind speed, m/s; ``None`` when none is recorded.
    """
    for source in (seq.meta.get("world"), seq.meta):
        if isinstance(source, dict) and isinstance(source.get("wind"), dict):
            speed = source["wind"].get("speed_mps")
            if isinstance(speed, int | float):
                return float(speed)
    return None


@dataclass(frozen=True, eq=False)
class ModeContext:
    """What a mode may use to plan a trajectory (see :data:`MODES`).

    Parameters
    ----------
    frames : dyntarget.sequence.FrameSequence
        The look-ahead frames on the WFOV grid, the last one the decision frame
        (``frames.times[-1]``).
    mask : numpy.ndarray
        The WFOV plume mask of the decision frame (classifier output or true
        mask, not yet denoised).
    planner : str
        The planner.
    latency_s : float
        Seconds from the decision frame to the start of pointing.
    pipeline : dyntarget.pipeline.PipelineConfig
        Settings of the pipeline.
    schedule : callable
        Times a trajectory as it will be flown (the evaluator does this again on
        whatever the mode returns).
    classifier : dyntarget.perceive.Predictor or None
        The fitted classifier (``None`` for the true mask), e.g. to segment
        earlier frames.
    meta : dict
        The sequence's metadata (e.g. a wind prior, where one is known).
    """

    frames: FrameSequence
    mask: np.ndarray
    planner: str
    latency_s: float
    pipeline: PipelineConfig
    schedule: Callable[[Trajectory], Schedule]
    classifier: Predictor | None = None
    meta: dict[str, Any] = field(default_factory=dict)


Mode = Callable[[ModeContext], Trajectory]


def static_mode(ctx: ModeContext) -> Trajectory:
    """The paper's pipeline: denoise the decision frame's mask, plan where the plume was seen.

    Parameters
    ----------
    ctx : ModeContext
        The decision frame, its mask and the planner.

    Returns
    -------
    dyntarget.trajectory.Trajectory
        The plan.
    """
    decision = ctx.frames.frames[-1]
    seg = segment(decision.image, mask=ctx.mask, valid=decision.valid, config=ctx.pipeline)
    return plan_segmentation(seg, ctx.planner, ctx.pipeline)


MODES: dict[str, Mode | str] = {
    "static": static_mode,
    "predictive": "dyntarget.evaluate.predictive:predictive_mode",
    "wind-prior": "dyntarget.evaluate.predictive:wind_prior_mode",
}
"""Mode name -> ``fn(ModeContext) -> Trajectory`` or a lazy ``"module:function"``."""


def get_mode(name: str) -> Mode:
    """Resolve a mode by name (importing a lazy entry).

    Parameters
    ----------
    name : str
        A key of :data:`MODES`.

    Returns
    -------
    callable
        ``fn(ctx: ModeContext) -> Trajectory``.

    Raises
    ------
    dyntarget.errors.UnknownNameError
        For an unknown name.

    Examples
    --------
    >>> get_mode("static") is static_mode
    True
    """
    try:
        entry = MODES[name]
    except KeyError:
        raise UnknownNameError(
            f"unknown mode {name!r}; expected one of: {', '.join(MODES)}"
        ) from None
    if isinstance(entry, str):
        module, _, attr = entry.partition(":")
        entry = getattr(importlib.import_module(module), attr)
    return entry


@dataclass(frozen=True)
class DynamicConfig(TrainingConfig):
    """Settings of the dynamic evaluation (see the module docstring).

    Parameters
    ----------
    folds : int
        Cross-validation folds over the sequences.
    seed : int
        Seed of the fold split and the training.
    factor : int
        High-res -> WFOV downsampling factor.
    epochs : int
        Training epochs of a U-Net classifier.
    classifiers : tuple of str
        Classifiers to evaluate.
    true_mask : bool
        Also plan on the decision frame's true mask (``true-mask``).
    planners : tuple of str
        Planners.
    modes : tuple of str
        Modes (:data:`MODES`).
    latencies : tuple of float
        Seconds from the decision frame to the start of pointing.
    agility : str
        Agility preset of the schedule.
    altitude_m, look_ahead_m : float
        Orbit geometry, metres.
    truth_step_s : float
        Time grid of a synthetic sequence's truth, seconds.
    pipeline : dyntarget.pipeline.PipelineConfig
        Settings of the pipeline.
    """

    classifiers: tuple[str, ...] = ("mlp",)
    true_mask: bool = True
    planners: tuple[str, ...] = PAPER_PLANNERS
    modes: tuple[str, ...] = ("static",)
    latencies: tuple[float, ...] = DEFAULT_LATENCIES
    agility: str = "unlimited"
    altitude_m: float = defaults.ALTITUDE_M
    look_ahead_m: float = defaults.LOOK_AHEAD_M
    truth_step_s: float = 1.0
    pipeline: PipelineConfig = field(default_factory=PipelineConfig)

    def __post_init__(self) -> None:
        super().__post_init__()  # folds, seed, factor, epochs
        for name in self.classifiers:
            CLASSIFIERS.get(name)
        for name in self.planners:
            PLANNERS.get(name)
        for name in self.modes:
            get_mode(name)
        if not self.latencies:
            raise InvalidParameterError("latencies: expected at least one latency")
        for v in self.latencies:
            if not (isinstance(v, int | float) and math.isfinite(v) and 0 <= v <= 3600):
                raise InvalidParameterError(f"latencies: expected seconds in 0..3600, got {v!r}")
        if self.agility not in AGILITY:
            raise InvalidParameterError(
                f"agility: unknown preset {self.agility!r}; choose from {', '.join(AGILITY)}"
            )
        if not (math.isfinite(self.truth_step_s) and self.truth_step_s >= 0):
            raise InvalidParameterError(
                f"truth_step_s: expected seconds >= 0, got {self.truth_step_s!r}"
            )
        if not self.classifiers and not self.true_mask:
            raise InvalidParameterError("classifiers: give at least one, or keep the true mask")
        OrbitGeometry(altitude_m=self.altitude_m, look_ahead_m=self.look_ahead_m)  # validates


def _truth(seq: FrameSequence, step_s: float) -> Callable[[float], Any]:
    if seq.truth is not None:
        return seq.truth
    from dyntarget.synth.dynamic import truth_provider

    provider = truth_provider(seq.meta, step_s=step_s)
    return provider if provider is not None else seq.truth_at


def _dynamic_task(
    task: tuple[int, int],
    *,
    sequences: Sequence[FrameSequence],
    wfov: Sequence[FrameSequence],
    models: dict[str, Classifier],
    config: DynamicConfig,
) -> list[dict[str, Any]]:
    k, i = task
    seq, look = sequences[i], wfov[i]
    truth = _truth(seq, config.truth_step_s)
    t_dec = float(seq.times[-1])
    decision = look.frames[-1]
    speed = sequence_wind(seq)
    base = {"fold": k, "scene": seq.id, "wind_mps": speed, "wind_bin": wind_bin(speed)}
    gsd = decision.gsd if decision.gsd is not None else 1.0

    def scheduler(latency: float) -> Callable[[Trajectory], Schedule]:
        geometry = OrbitGeometry(
            altitude_m=config.altitude_m,
            look_ahead_m=config.look_ahead_m,
            wfov_gsd_m=gsd,
            start_s=float(latency),
        )
        return lambda traj: schedule_on_prediction(
            traj, decision.shape, geometry, config.agility, None
        )

    def score(traj: Trajectory, latency: float, **labels: Any) -> dict[str, Any]:
        flown = scheduler(latency)(traj).trajectory
        m = observe_at(flown, truth, factor=config.factor, latency_s=t_dec)
        return {**base, **labels, "latency_s": float(latency), "planned": len(traj), **m.as_dict()}

    records = []
    masks: dict[str, tuple[np.ndarray, Classifier | None]] = {}
    for cname in config.classifiers:
        model = models[f"{k}/{cname}"]
        proba = classify(decision.image, model)
        masks[cname] = (proba >= config.pipeline.threshold, model)
    if config.true_mask:
        if decision.label is None:
            raise InvalidParameterError(f"sequence {seq.id!r}: decision frame has no label")
        masks[TRUE_MASK] = (decision.label, None)
    lookahead = [p for p in config.planners if p not in BASELINES]
    for mode in config.modes:
        fn = get_mode(mode)
        for cname, (mask, mask_model) in masks.items():
            for pname in lookahead:
                for latency in config.latencies:
                    ctx = ModeContext(
                        frames=look,
                        mask=mask,
                        planner=pname,
                        latency_s=float(latency),
                        pipeline=config.pipeline,
                        schedule=scheduler(latency),
                        classifier=mask_model,
                        meta=seq.meta,
                    )
                    traj = fn(ctx)
                    records.append(score(traj, latency, mode=mode, classifier=cname, planner=pname))
    for pname in [p for p in config.planners if p in BASELINES]:
        seg = segment(
            decision.image, mask=np.zeros(decision.shape, bool), valid=decision.valid,
            config=config.pipeline,
        )  # fmt: skip
        traj = plan_segmentation(seg, pname, config.pipeline)
        for latency in config.latencies:
            records.append(score(traj, latency, mode="static", classifier="N/A", planner=pname))
    return records


def _signature(sequences: Sequence[FrameSequence]) -> str:
    parts: list[Any] = []
    for s in sequences:
        last = s.frames[-1]
        parts += [s.id, s.times, last.image, last.label if last.label is not None else "none"]
        parts.append(json.dumps(s.meta, sort_keys=True, default=str))
    return task_key(*parts)


def evaluate_dynamic(
    sequences: Sequence[FrameSequence],
    config: DynamicConfig = DynamicConfig(),
    *,
    options: RunOptions = RunOptions(),
) -> dict[str, Any]:
    """Run the dynamic evaluation; returns tidy ``rows``, per-scene ``records`` and the config.

    Parameters
    ----------
    sequences : sequence of FrameSequence
        High-resolution look-ahead sequences (labelled decision frames); their
        truth comes from ``truth``, else the stored world spec, else their frames.
    config : DynamicConfig
    options : RunOptions
        Models kept, progress bar, scheduler and finished parts
        (:class:`~dyntarget.evaluate.options.RunOptions`; resumable, Dask).

    Returns
    -------
    dict
        ``rows`` (see :data:`DYNAMIC_COLUMNS`), ``records``, ``config``, ``folds``.
    """
    models_dir, progress, scheduler, parts = (
        options.models_dir,
        options.progress,
        options.scheduler,
        options.parts,
    )
    check_scheduler(scheduler)
    sequences = list(sequences)
    if len(sequences) < config.folds:
        raise InvalidParameterError(
            f"folds: {config.folds} folds need at least as many sequences, got {len(sequences)}"
        )
    wfov = [s.to_wfov(config.factor) for s in sequences]
    folds = [sorted(f.tolist()) for f in kfold_indices(len(sequences), config.folds, config.seed)]
    models: dict[str, Classifier] = {}
    for k, test in enumerate(folds):
        held = set(test)
        train = [w.frames[-1] for j, w in enumerate(wfov) if j not in held]
        for cname in config.classifiers:
            model_dir = Path(models_dir) / f"fold-{k}" / cname if models_dir is not None else None
            models[f"{k}/{cname}"], _, _ = train_or_load(
                cname, train, seed=config.seed, epochs=config.epochs, model_dir=model_dir
            )
    tasks = [(k, i) for k, test in enumerate(folds) for i in test]
    cfg = _config_dict(config)
    run = task_key("dynamic", cfg, _signature(sequences))
    results = run_tasks(
        _dynamic_task,
        tasks,
        key=lambda t: task_key(run, t[0], sequences[t[1]].id),
        parts=Path(parts) if parts is not None else None,
        scheduler=scheduler,
        shared={"sequences": sequences, "wfov": wfov, "models": models, "config": config},
        progress=progress,
        desc="dynamic",
    )
    records = [r for result in results for r in result]
    return {
        "rows": dynamic_rows(records),
        "records": records,
        "config": cfg,
        "folds": [[sequences[i].id for i in f] for f in folds],
    }


def _config_dict(config: DynamicConfig) -> dict[str, Any]:
    d = asdict(config)
    for key in ("classifiers", "planners", "modes", "latencies"):
        d[key] = list(d[key])
    return d


def _order(records: list[dict[str, Any]], key: str) -> list[Any]:
    return list(dict.fromkeys(r[key] for r in records))


def dynamic_rows(records: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Tidy rows: means over scenes per mode x classifier x planner x latency x wind bin.

    Parameters
    ----------
    records : list of dict
        Per-sequence records.

    Returns
    -------
    list of dict
        One row per group with the mean metrics and the number of ``scenes``.

    Examples
    --------
    >>> recs = [{"mode": "static", "classifier": "mlp", "planner": "p", "latency_s": 0.0,
    ...          "wind_bin": "8-12", "pixels_observed": n, "ratio_plume": r,
    ...          "intensity": 0.0, "gradient": 0.0} for n, r in ((2, 0.5), (4, 1.0))]
    >>> row = dynamic_rows(recs)[0]
    >>> row["scenes"], row["ratio_plume"], row["pixels_observed"]
    (2, 0.75, 3.0)
    """
    groups: dict[tuple, list[dict[str, Any]]] = {}
    for r in records:
        key = (r["mode"], r["classifier"], r["planner"], r["latency_s"], r["wind_bin"])
        groups.setdefault(key, []).append(r)
    bins = [wind_bin(lo) for lo, _ in WIND_BINS] + ["unknown"]
    modes, classifiers, planners = (
        _order(records, "mode"),
        _order(records, "classifier"),
        _order(records, "planner"),
    )

    def sort_key(key: tuple) -> tuple:
        mode, cname, pname, latency, wbin = key
        return (
            modes.index(mode),
            classifiers.index(cname),
            planners.index(pname),
            latency,
            bins.index(wbin) if wbin in bins else len(bins),
        )

    rows = []
    for key in sorted(groups, key=sort_key):
        sel = groups[key]
        mode, cname, pname, latency, wbin = key
        rows.append(
            {
                "mode": mode,
                "classifier": cname,
                "planner": pname,
                "latency_s": latency,
                "wind_bin": wbin,
                "scenes": len(sel),
                **{
                    m: float(np.mean([r[m] for r in sel]))
                    for m in ("pixels_observed", "ratio_plume", "intensity", "gradient")
                },
            }
        )
    return rows


def latency_table(
    records: list[dict[str, Any]],
    *,
    metric: str = "ratio_plume",
    wind: str | None = None,
    mode: str = "static",
) -> tuple[list[dict[str, Any]], list[str]]:
    """A wide table for reading: one row per classifier x planner, one column per latency.

    ``wind``: only scenes of that wind bin (``None``: all scenes). Adds the change
    from the first latency to 90 s (or the last latency below it) as ``Δ to 90 s``.

    Parameters
    ----------
    records : list of dict
        Per-sequence records.
    metric : str
        The record key tabulated.
    wind : str or None
        Wind bin.
    mode : str
        The mode tabulated.

    Returns
    -------
    rows : list of dict
        The table rows.
    columns : list of str
        Its columns, in order.
    """
    sel = [r for r in records if r["mode"] == mode and (wind is None or r["wind_bin"] == wind)]
    latencies = sorted({r["latency_s"] for r in sel})
    lat_cols = [f"{metric} @ {lat:g} s" for lat in latencies]
    upto = [lat for lat in latencies if lat <= 90.0]
    rows = []
    for cname in _order(sel, "classifier"):
        for pname in _order([r for r in sel if r["classifier"] == cname], "planner"):
            mine = [r for r in sel if r["classifier"] == cname and r["planner"] == pname]
            row: dict[str, Any] = {
                "Trajectory Algorithm": display(pname),
                "Classifier": "True mask" if cname == TRUE_MASK else display(cname),
                "Scenes": len({r["scene"] for r in mine}),
            }
            means = {}
            for lat, col in zip(latencies, lat_cols, strict=True):
                vals = [r[metric] for r in mine if r["latency_s"] == lat]
                means[lat] = float(np.mean(vals)) if vals else float("nan")
                row[col] = means[lat]
            if len(upto) >= 2:
                a, b = means[upto[0]], means[upto[-1]]
                row[f"Δ {upto[0]:g}→{upto[-1]:g} s"] = b - a
                row[f"Δ % {upto[0]:g}→{upto[-1]:g} s"] = (
                    100.0 * (b - a) / a if a > 0 else float("nan")
                )
            rows.append(row)
    columns = ["Trajectory Algorithm", "Classifier", "Scenes", *lat_cols]
    if len(upto) >= 2:
        columns += [f"Δ {upto[0]:g}→{upto[-1]:g} s", f"Δ % {upto[0]:g}→{upto[-1]:g} s"]
    return rows, columns


def latency_figure(
    records: list[dict[str, Any]],
    path: str | Path,
    *,
    metric: str = "ratio_plume",
    winds: Sequence[str | None] = (None, "8-12"),
    mode: str = "static",
) -> Path:
    """Ratio plume (or ``metric``) against latency: one panel per classifier x wind selection.

    Parameters
    ----------
    records : list of dict
        Per-sequence records.
    path : str or pathlib.Path
        The PNG to write.
    metric : str
        The record key plotted.
    winds : sequence of str or None
        Wind bins, one panel row each (``None``: all scenes).
    mode : str
        The mode plotted.

    Returns
    -------
    pathlib.Path
        The figure written.
    """
    from matplotlib import colormaps

    from dyntarget.evaluate.figures import save, subplots

    sel = [r for r in records if r["mode"] == mode]
    classifiers = [c for c in _order(sel, "classifier") if c != "N/A"] or ["N/A"]  # baselines only
    fig, axes = subplots(
        len(winds), max(len(classifiers), 1), figsize=(5.2 * max(len(classifiers), 1), 3.6 * len(winds)),
        squeeze=False, sharey=True,
    )  # fmt: skip
    cmap = colormaps["tab10"]
    for wi, wind in enumerate(winds):
        wsel = [r for r in sel if wind is None or r["wind_bin"] == wind]
        for ci, cname in enumerate(classifiers):
            ax = axes[wi, ci]
            planners = _order([r for r in wsel if r["classifier"] in (cname, "N/A")], "planner")
            nb = 0
            for pi, pname in enumerate(planners):
                mine = [
                    r for r in wsel if r["planner"] == pname and r["classifier"] in (cname, "N/A")
                ]
                lats = sorted({r["latency_s"] for r in mine})
                vals = [np.mean([r[metric] for r in mine if r["latency_s"] == lat]) for lat in lats]
                baseline = pname in BASELINES
                style = ["--", ":"][nb % 2] if baseline else "-"
                nb += baseline
                ax.plot(
                    lats, vals, marker="o", ms=3,
                    ls=style, color="black" if baseline else cmap(pi % 10),
                    alpha=0.7 if baseline else 1.0, label=display(pname),
                )  # fmt: skip
            n = len({r["scene"] for r in wsel})
            where = "all winds" if wind is None else f"wind {wind} m/s"
            name = {TRUE_MASK: "true mask", "N/A": "baselines"}.get(cname) or display(cname)
            ax.set_title(f"{name}, {where} ({n} scenes)", fontsize=9)
            ax.set_xlabel("latency (s)", fontsize=8)
            ax.grid(alpha=0.3)
            if ci == 0:
                ax.set_ylabel(metric.replace("_", " "), fontsize=8)
    handles, labels = axes[0, 0].get_legend_handles_labels()
    if labels:
        fig.legend(
            handles, labels, fontsize=8, ncol=min(len(labels), 6), loc="lower center", frameon=False
        )
    fig.tight_layout(rect=(0, 0.07, 1, 1))
    return save(fig, path)
