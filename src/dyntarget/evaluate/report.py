"""The Markdown report of an evaluation run (demo and reproduce), with its figures."""

from __future__ import annotations

import os
import time
from dataclasses import asdict, replace
from pathlib import Path
from typing import Any

import numpy as np

from dyntarget.evaluate.claims import check_claims, paper_results
from dyntarget.evaluate.crossval import TABLE1_COLUMNS
from dyntarget.evaluate.endtoend import TABLE2_COLUMNS
from dyntarget.evaluate.figures import classification_figure, trajectories_figure, utilities_figure
from dyntarget.evaluate.options import RunOptions, TrainingConfig
from dyntarget.evaluate.tables import display, markdown_table
from dyntarget.io.atomic import write_text
from dyntarget.perceive import load_classifier
from dyntarget.pipeline import PipelineConfig, plan_scene
from dyntarget.plan import BASELINES
from dyntarget.scene import Scene

_TABLES = ("table1_classification", "table2_end_to_end")
_FIGURES = ("fig3_trajectories.png", "view.html", "fig4_classification.png", "fig_utilities.png")
RESULT_FILES = (
    *(f"{t}{s}" for t in _TABLES for s in (".md", ".csv", ".json", ".timing.json")),
    *_FIGURES,
    "report.md",
)
"""The files of one evaluation report (:func:`evaluate_all`, :func:`write_report`): a rerun
that does not write one of them (``view.html`` without plotly) removes the earlier one."""


def best_classifier(table1_rows: list[dict]) -> str:
    """Classifier with the highest IoU (raw or denoised).

    Parameters
    ----------
    table1_rows : list of dict
        Table 1 rows.

    Returns
    -------
    str
        The classifier's name.
    """
    return max(table1_rows, key=lambda r: r["IoU"])["classifier"]


def make_figures(
    out: Path,
    scenes: list[Scene],
    table1: dict[str, Any],
    table2: dict[str, Any],
    models_dir: Path,
    *,
    factor: int,
    pipeline: PipelineConfig | None = None,
) -> dict[str, Path]:
    """Figure 3 (four planners over one held-out scene), Figure 4 and the utilities chart.

    Parameters
    ----------
    out : pathlib.Path
        Output folder.
    scenes : list of dyntarget.scene.Scene
        The evaluated scenes.
    table1 : dict
        Cross-validation result (its best classifier and fold 0 are used).
    table2 : dict
        End-to-end result.
    models_dir : pathlib.Path
        Where the fold models are.
    factor : int
        High-res -> WFOV downsampling factor.
    pipeline : dyntarget.pipeline.PipelineConfig or None
        Settings of the pipeline.

    Returns
    -------
    dict of str to pathlib.Path
        Figure name to file.
    """
    pipeline = pipeline or PipelineConfig()
    best = best_classifier(table1["rows"])
    fold0 = set(table1["folds"][0])
    held_out = [s for s in scenes if s.id in fold0]
    model = load_classifier(models_dir / "fold-0" / best)
    figs: dict[str, Path] = {}
    # Figure 3: the held-out scene with the largest plume
    scene = max(held_out, key=lambda s: float(s.truth.mean()))
    wfov = scene.to_wfov(factor)
    lookahead = [
        p for p in dict.fromkeys(r["planner"] for r in table2["rows"]) if p not in BASELINES
    ]
    results = [plan_scene(wfov.image, model, p, config=pipeline) for p in lookahead]
    figs["fig3"] = trajectories_figure(
        wfov.image,
        [r.trajectory for r in results],
        out / "fig3_trajectories.png",
        mask=results[0].mask,
        title=f"{scene.id}: planners on the {display(best)} mask (held-out scene)",
        gsd=wfov.gsd,
    )
    if results and _has_plotly():  # the same plan, interactive: view.html beside report.md
        figs["view"] = _scene_view(out / "view.html", scene, wfov, results[0], lookahead[0], factor)
    # Figure 4: three held-out scenes
    rows = []
    for s in held_out[:3]:
        w = s.to_wfov(factor)
        r = plan_scene(
            w.image, model, lookahead[0] if lookahead else "trace-outline", config=pipeline
        )
        rows.append((f"{s.id} ({display(best)})", w.image, r.probability, r.mask, w.label))
    figs["fig4"] = classification_figure(rows, out / "fig4_classification.png")
    figs["utilities"] = utilities_figure(table2["rows"], out / "fig_utilities.png")
    return figs


def _has_plotly() -> bool:
    import importlib.util

    return importlib.util.find_spec("plotly") is not None


def _scene_view(path: Path, scene: Scene, wfov: Scene, result, planner: str, factor: int) -> Path:
    from dyntarget.observe import pointing_truth
    from dyntarget.view import write_scene_view

    traj = result.trajectory
    return write_scene_view(
        path,
        wfov.image,
        probability=result.probability,
        polygons=result.polygons,
        trajectory=traj,
        point_values=pointing_truth(traj, scene.image, scene.truth, factor=factor),
        transform=wfov.transform,
        crs=wfov.crs,
        title=f"{scene.id}: {planner} (held-out scene, as Figure 3)",
    )


def _paper_table1_md(ours: list[dict]) -> str:
    paper = {(r["classifier"], r["denoised"]): r for r in paper_results()["table1"]}
    rows = []
    for r in ours:
        p = paper.get((r["classifier"], r["denoised"]))
        rows.append(
            {
                "Classifier": r["Classifier"]
                if not r["denoised"]
                else f"{display(r['classifier'])} + Denoising",
                "IoU (ours)": r["IoU"],
                "IoU (paper)": p["IoU"] if p else "",
                "Precision (ours)": r["Precision"],
                "Precision (paper)": p["Precision"] if p else "",
                "Recall (ours)": r["Recall"],
                "Recall (paper)": p["Recall"] if p else "",
            }
        )
    cols = list(rows[0]) if rows else []
    return markdown_table(rows, cols)


def _paper_table2_md(ours: list[dict]) -> str:
    paper = {(r["planner"], r["classifier"]): r for r in paper_results()["table2"]}
    rows = []
    for r in ours:
        p = paper.get((r["planner"], r["classifier"]))
        rows.append(
            {
                "Trajectory Algorithm": r["Trajectory Algorithm"],
                "Classifier": r["Classifier"],
                "Ratio Plume (ours)": r["Ratio Plume"],
                "Ratio Plume (paper)": p["Ratio Plume"] if p else "",
                "Intensity (ours)": r["Intensity"],
                "Intensity (paper)": p["Intensity"] if p else "",
                "Runtime s (ours)": r["Runtime (s)"],
                "Runtime s (paper)": p["Runtime (s)"] if p else "",
            }
        )
    cols = list(rows[0]) if rows else []
    return markdown_table(rows, cols)


def claims_md(table1_rows: list[dict], table2_rows: list[dict]) -> str:
    """Markdown table of the paper's claims: verdicts on our tables and, by the same rules, on the paper's.

    Parameters
    ----------
    table1_rows : list of dict
        Our Table 1 rows.
    table2_rows : list of dict
        Our Table 2 rows.

    Returns
    -------
    str
        The Markdown table.
    """
    ours = check_claims(table1_rows, table2_rows)
    paper = paper_results()
    theirs = check_claims(paper["table1"], paper["table2"])
    lines = [
        "| claim | on our data | detail | same rule on the paper's numbers |",
        "|---|---|---|---|",
    ]
    for o, t in zip(ours, theirs, strict=True):
        verdict = o.get("verdict") or ("holds" if o["holds"] else "does not hold")
        pv = t.get("verdict") or ("holds" if t["holds"] else "does not hold")
        lines.append(f"| {o['claim']} | **{verdict}** | {o['detail']} | {pv}: {t['detail']} |")
    return "\n".join(lines) + "\n"


METRICS_MD = """## What the columns mean

**Table 1** scores the plume class of each classifier's mask against the label, pixel by
pixel. TP, FP, FN and TN (true/false positives/negatives) are counted over all held-out
pixels of a fold; the table shows the mean over folds.

| column | definition |
|---|---|
| Accuracy | (TP + TN) / (TP + FP + FN + TN): pixels classified right, either class |
| Precision | TP / (TP + FP): of the pixels called plume, the share that is plume (1 when none is called plume) |
| Recall | TP / (TP + FN): of the plume pixels, the share found (1 when there is no plume) |
| IoU | TP / (TP + FP + FN): intersection over union of predicted and true plume (1 when both are empty) |
| + Denoising | the row above after Algorithm 2 (3x3 closing, components below the minimum area removed) |

**Table 2** plans on each held-out scene's mask and points the narrow-field sensor at each
planned WFOV pixel; each pointing observes the high-resolution footprint under that pixel.
Each column is the mean over the held-out scenes of:

| column | definition |
|---|---|
| Pixels Observed | distinct WFOV pixels pointed at (a pixel pointed at twice counts once) |
| Ratio Plume | mean over the observed footprints of their plume fraction (0-1) |
| Intensity | mean over the observed footprints of the intensity utility: label x blue reflectance, divided by its maximum over the scene (0-1) |
| Gradient | mean over the observed footprints of the gradient utility: the 5x5 Sobel magnitude of the intensity, divided by its maximum over the scene (0-1) |
| Runtime (s) | wall time of classify + denoise + plan for one WFOV scene |

*Classifier N/A*: the two baselines (straight nadir, naive transect), which ignore the
plume. A trajectory with no pointing scores 0 in every column.
"""
"""The definitions of every metric ``report.md`` uses (written into it after Table 2)."""


def write_report(
    out: str | os.PathLike[str],
    *,
    title: str,
    command: str,
    table1: dict[str, Any],
    table2: dict[str, Any],
    figures: dict[str, Path],
    seconds: float,
    data_note: str,
    compare_with_paper: bool = True,
) -> Path:
    """Write ``report.md`` with both tables, the figures and (optionally) the paper comparison.

    Parameters
    ----------
    out : str or os.PathLike
        Output folder.
    title : str
        Report title.
    command : str
        The command that produced it.
    table1 : dict
        Cross-validation result.
    table2 : dict
        End-to-end result.
    figures : dict of str to pathlib.Path
        Figures to show.
    seconds : float
        Total wall time.
    data_note : str
        What the data were.
    compare_with_paper : bool
        Add the paper's tables and the claims.

    Returns
    -------
    pathlib.Path
        ``report.md``.
    """
    import platform

    import dyntarget

    out = Path(out)
    rel = {k: os.path.relpath(v, out) for k, v in figures.items()}
    parts = [
        f"# {title}\n",
        f"Command: `{command}`  \n",
        f"dyntarget {dyntarget.__version__}, {platform.platform()}, Python {platform.python_version()}, "
        f"{os.cpu_count()} CPU(s); took {seconds / 60:.1f} min; written {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}.\n",
        f"{data_note}\n",
        "## Table 1: classification (k-fold cross-validation, plume class)\n",
        markdown_table(table1["rows"], TABLE1_COLUMNS),
        "\nConfusion counts are summed over each fold's held-out pixels; the table shows the mean over folds.\n",
        "## Table 2: perception and planning (end to end)\n",
        markdown_table(table2["rows"], TABLE2_COLUMNS),
        "\nMeans over all held-out scenes; Runtime = classify + denoise + plan for one WFOV scene.\n",
        METRICS_MD,
        "## Figures\n",
        f"![Figure 3: planners' paths]({rel['fig3']})\n\n"
        f"*Figure 3 — the four look-ahead planners over one held-out scene (yellow: denoised mask).*\n",
        f"![Figure 4: classification]({rel['fig4']})\n\n"
        f"*Figure 4 — image, classifier output, denoised output for held-out scenes.*\n",
        f"![Utilities]({rel['utilities']})\n\n"
        "*Ratio plume, intensity and gradient per planner and classifier; dashed/dotted: baselines.*\n",
    ]
    if "view" in rel:
        parts.append(
            f"Interactive: [{rel['view']}]({rel['view']}) — Figure 3's scene with one planner's "
            "pointings, probability and polygons; hover a pointing for its order and what it "
            "observed (opens offline in any browser).\n"
        )
    if compare_with_paper:
        parts += [
            "## Beside the paper\n",
            "The paper's numbers (Zilberstein, Candela, Chien 2025, Tables 1-2; 38 SkySat scenes) are stored in "
            "`dyntarget/data/paper_results.json`. Different data: compare orderings and ratios, not values.\n",
            "### Table 1\n",
            _paper_table1_md(table1["rows"]),
            "\n### Table 2\n",
            _paper_table2_md(table2["rows"]),
            "\n## The paper's claims on this data\n",
            claims_md(table1["rows"], table2["rows"]),
        ]
    return write_text(out / "report.md", "\n".join(parts))


def mean_iou_gain(table1_rows: list[dict]) -> float:
    """Mean over classifiers of the IoU change from denoising.

    Parameters
    ----------
    table1_rows : list of dict
        Table 1 rows, each classifier with and without denoising.

    Returns
    -------
    float
        Denoised minus raw IoU, averaged.
    """
    by = {(r["classifier"], r["denoised"]): r["IoU"] for r in table1_rows}
    names = {r["classifier"] for r in table1_rows}
    return float(np.mean([by[(n, True)] - by[(n, False)] for n in names]))


def evaluate_all(
    scenes: list[Scene],
    out: str | os.PathLike[str],
    *,
    classifiers: tuple[str, ...],
    training: TrainingConfig = TrainingConfig(),
    options: RunOptions = RunOptions(),
    into: str | os.PathLike[str] | None = None,
) -> tuple[dict[str, Any], dict[str, Any], dict[str, Path]]:
    """Table 1 and Table 2 sharing one training run (models in ``options.models_dir``), plus figures.

    Finished tasks are kept in ``out/parts/`` so that an interrupted run resumes;
    ``options.scheduler`` runs the tasks on Dask (see :mod:`dyntarget.evaluate.distributed`).
    The tables and figures (:data:`RESULT_FILES`) go to ``into`` (default ``out``): a
    command passes a staging folder (:mod:`dyntarget.io.staging`) so that they move
    into ``out`` together, while the resume state stays in ``out``.

    Parameters
    ----------
    scenes : list of dyntarget.scene.Scene
        Labelled high-resolution scenes.
    out : str or os.PathLike
        Output folder (tables, figures, ``parts/``).
    classifiers : tuple of str
        Classifiers.
    training : TrainingConfig
        Folds, seed, factor and U-Net epochs of both tables.
    options : RunOptions
        Where the fold models are kept (default ``out/models``), progress, scheduler;
        its ``parts`` is ignored (``out/parts/`` holds each table's parts).
    into : str or os.PathLike or None
        Folder of the tables and figures (default ``out``).

    Returns
    -------
    table1 : dict
        :func:`~dyntarget.evaluate.crossval.cross_validate` result, with timing.
    table2 : dict
        :func:`~dyntarget.evaluate.endtoend.evaluate_end_to_end` result, with timing.
    figures : dict of str to pathlib.Path
        The figures written (:func:`make_figures`).
    """
    from dyntarget.evaluate.crossval import CVConfig, cross_validate
    from dyntarget.evaluate.endtoend import E2EConfig, evaluate_end_to_end
    from dyntarget.evaluate.tables import write_result

    out = Path(out)
    dest = Path(into) if into is not None else out
    models_dir = options.models_dir if options.models_dir is not None else out / "models"
    shared = asdict(training)
    t0 = time.perf_counter()
    table1 = cross_validate(
        scenes,
        CVConfig(**shared, classifiers=classifiers),
        options=replace(options, models_dir=models_dir, parts=out / "parts" / "classification"),
    )
    table1["timing"]["seconds"] = time.perf_counter() - t0
    write_result(dest, "table1_classification", table1, TABLE1_COLUMNS)
    t0 = time.perf_counter()
    table2 = evaluate_end_to_end(
        scenes,
        E2EConfig(**shared, classifiers=classifiers),
        options=replace(options, models_dir=models_dir, parts=out / "parts" / "end-to-end"),
    )
    table2["timing"] = {"seconds": time.perf_counter() - t0}
    write_result(dest, "table2_end_to_end", table2, TABLE2_COLUMNS)
    factor = training.factor
    figures = make_figures(dest, scenes, table1, table2, models_dir, factor=factor)
    return table1, table2, figures
