"""Figures (matplotlib, PNG).

matplotlib is imported when a figure is drawn, never at import; figures are
:class:`matplotlib.figure.Figure` objects rendered straight to PNG, so no
pyplot backend is selected or switched.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from dyntarget.io.atomic import atomic_path
from dyntarget.scene import Scene

if TYPE_CHECKING:
    from matplotlib.figure import Figure


def subplots(nrows: int, ncols: int, *, figsize: tuple[float, float], **kwargs: Any):
    """A new figure and its axes (:meth:`matplotlib.figure.Figure.subplots`), without pyplot.

    Parameters
    ----------
    nrows, ncols : int
        Grid of axes.
    figsize : tuple of float
        Inches.
    **kwargs
        Passed to :meth:`~matplotlib.figure.Figure.subplots` (e.g. ``squeeze=False``).

    Returns
    -------
    tuple
        ``(figure, axes)``.
    """
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize)
    return fig, fig.subplots(nrows, ncols, **kwargs)


def rgb(image: np.ndarray, bands: tuple[int, int, int] = (0, 1, 2)) -> np.ndarray:
    """An 8-bit-like display image ``(H, W, 3)`` in 0..1 with a 2-98 % stretch.

    Parameters
    ----------
    image : numpy.ndarray
        ``(4, H, W)`` image.
    bands : tuple of int
        Bands shown as red, green and blue.

    Returns
    -------
    numpy.ndarray
        ``float32 (H, W, 3)``.
    """
    stack = np.stack([image[b] for b in bands], axis=-1).astype(np.float32)
    lo, hi = np.percentile(stack, [2, 98])
    if hi <= lo:
        hi = lo + 1e-6
    return np.clip((stack - lo) / (hi - lo), 0.0, 1.0)


def save(fig: Figure, path: str | os.PathLike[str], *, dpi: int = 110) -> Path:
    """Save a figure atomically as PNG.

    Parameters
    ----------
    fig : matplotlib.figure.Figure
        The figure.
    path : str or os.PathLike
        The PNG to write.
    dpi : int
        Resolution.

    Returns
    -------
    pathlib.Path
        ``path``.
    """
    with atomic_path(path) as tmp:
        fig.savefig(  # the Software tag lets a rerun recognise (and replace) its own figure
            tmp, dpi=dpi, bbox_inches="tight", format="png", metadata={"Software": "dyntarget"}
        )
    return Path(path)


def scenes_figure(
    scenes: Sequence[Scene], path: str | os.PathLike[str], *, max_scenes: int = 4, dpi: int = 110
) -> Path:
    """Rows of scenes: true colour, false colour (NIR, R, G), label.

    Parameters
    ----------
    scenes : sequence of dyntarget.scene.Scene
        The scenes.
    path : str or os.PathLike
        The PNG to write.
    max_scenes : int
        Most scenes shown.
    dpi : int
        Resolution.

    Returns
    -------
    pathlib.Path
        The figure written.
    """
    scenes = list(scenes)[:max_scenes]
    fig, axes = subplots(len(scenes), 3, figsize=(9, 3 * len(scenes)), squeeze=False)
    for row, scene in zip(axes, scenes, strict=True):
        row[0].imshow(rgb(scene.image))
        row[0].set_title(f"{scene.id}: RGB", fontsize=9)
        row[1].imshow(rgb(scene.image, (3, 0, 1)))
        row[1].set_title("false colour (NIR, R, G)", fontsize=9)
        if scene.label is not None:
            row[2].imshow(scene.label, cmap="gray", vmin=0, vmax=1)
            row[2].set_title(f"label ({100 * scene.label.mean():.1f} % plume)", fontsize=9)
        for ax in row:
            ax.set_axis_off()
    fig.tight_layout()
    return save(fig, path, dpi=dpi)


PATH_COLOURS = {
    "trace-outline": "#e41a1c",
    "track-center": "#ff7f00",
    "diagonal-transect": "#4daf4a",
    "lawnmower-transect": "#377eb8",
    "straight-nadir": "#984ea3",
    "naive-transect": "#a65628",
}


def draw_trajectory(ax, trajectory, *, colour: str | None = None, label: str | None = None) -> None:
    """Draw a trajectory: observation legs as lines with dots, travel hops dashed.

    Parameters
    ----------
    ax : matplotlib.axes.Axes
        Where to draw (pixel coordinates).
    trajectory : dyntarget.trajectory.Trajectory
        The trajectory.
    colour : str or None
        Line colour (default: the planner's).
    label : str or None
        Legend label.
    """
    pts = trajectory.points
    colour = colour or PATH_COLOURS.get(trajectory.planner, "red")
    if len(pts) == 0:
        return
    for p in np.unique(trajectory.part):
        leg = pts[trajectory.part == p]
        ax.plot(
            leg[:, 0],
            leg[:, 1],
            "-",
            color=colour,
            lw=1.0,
            label=label if p == trajectory.part[0] else None,
        )
        ax.plot(leg[:, 0], leg[:, 1], ".", color=colour, ms=2.5)
    hops = np.flatnonzero(np.diff(trajectory.part) != 0)
    for i in hops:
        ax.plot(pts[i : i + 2, 0], pts[i : i + 2, 1], "--", color=colour, lw=0.8, alpha=0.7)
    ax.plot(*pts[0], "o", color=colour, ms=5, mec="white", mew=0.8)


def trajectories_figure(
    image: np.ndarray,
    trajectories,
    path: str | os.PathLike[str],
    *,
    mask: np.ndarray | None = None,
    title: str | None = None,
    gsd: float | None = None,
    dpi: int = 110,
) -> Path:
    """The paper's Figure 3: one panel per trajectory, drawn over the RGB image (and mask outline).

    Each panel has a scale bar when ``gsd`` is known; one legend under the panels names
    the mask outline, the observation legs, the travel hops and the start marker. A single
    panel is drawn about 800 px wide.

    Parameters
    ----------
    image : numpy.ndarray
        ``(4, H, W)`` WFOV image.
    trajectories : iterable of dyntarget.trajectory.Trajectory
        The trajectories, one panel each.
    path : str or os.PathLike
        The PNG to write.
    mask : numpy.ndarray or None
        Mask whose outline is drawn.
    title : str or None
        Figure title.
    gsd : float or None
        Metres per pixel of ``image``, for the scale bar (none drawn when ``None``).
    dpi : int
        Resolution.

    Returns
    -------
    pathlib.Path
        The figure written.
    """
    trajectories = list(trajectories)
    n = max(len(trajectories), 1)
    panel = 7.6 if n == 1 else 3.8
    fig, axes = subplots(1, n, figsize=(panel * n, panel + 0.9), squeeze=False)
    for ax, traj in zip(axes[0], trajectories, strict=False):
        ax.imshow(rgb(image))
        if mask is not None and mask.any():
            ax.contour(mask.astype(float), levels=[0.5], colors="yellow", linewidths=0.7)
        draw_trajectory(ax, traj)
        ax.set_title(f"{traj.planner} ({len(traj)} pointings)", fontsize=9)
        ax.set_xlim(-0.5, image.shape[2] - 0.5)
        ax.set_ylim(image.shape[1] - 0.5, -0.5)
        if gsd:
            _scale_bar(ax, image.shape[2], gsd)
        ax.set_axis_off()
    if title:
        fig.suptitle(title, fontsize=11)
    colour = PATH_COLOURS.get(trajectories[0].planner, "red") if trajectories else "red"
    fig.legend(
        handles=_trajectory_legend(colour, mask is not None),
        loc="lower center",
        ncol=4,
        fontsize=9,
        frameon=False,
    )
    fig.tight_layout(rect=(0, 0.06 if n == 1 else 0.1, 1, 1))
    return save(fig, path, dpi=dpi)


def _trajectory_legend(colour: str, with_mask: bool) -> list:
    from matplotlib.lines import Line2D

    handles = [
        Line2D([], [], color=colour, lw=1.0, marker=".", ms=5, label="pointings (observing)"),
        Line2D([], [], color=colour, lw=0.8, ls="--", label="travel between legs"),
        Line2D([], [], color=colour, lw=0, marker="o", ms=6, mec="white", label="first pointing"),
    ]
    if with_mask:
        handles.insert(0, Line2D([], [], color="yellow", lw=1.2, label="plume mask outline"))
    return handles


def _scale_bar(ax, width_px: int, gsd: float) -> None:
    """A white scale bar about a fifth of the image wide, at a round length (1, 2 or 5 × 10^k m)."""
    from mpl_toolkits.axes_grid1.anchored_artists import AnchoredSizeBar

    target = width_px * gsd / 5
    k = 10 ** np.floor(np.log10(target))
    metres = max(m * k for m in (1, 2, 5) if m * k <= target)
    text = f"{metres / 1000:g} km" if metres >= 1000 else f"{metres:g} m"
    bar = AnchoredSizeBar(
        ax.transData, metres / gsd, text, "lower right", pad=0.4, color="white",
        frameon=False, size_vertical=max(width_px / 150, 0.5), fontproperties={"size": 9},
    )  # fmt: skip
    ax.add_artist(bar)


def classification_figure(rows, path: str | os.PathLike[str], *, dpi: int = 110) -> Path:
    """The paper's Figure 4: per scene, image / classifier probability / denoised mask.

    ``rows`` is a sequence of ``(title, image, probability, denoised_mask, truth)``.

    Parameters
    ----------
    rows : sequence of tuple
        ``(title, image, probability, denoised_mask, truth)`` per scene (``truth`` may be ``None``).
    path : str or os.PathLike
        The PNG to write.
    dpi : int
        Resolution.

    Returns
    -------
    pathlib.Path
        The figure written.
    """
    rows = list(rows)
    fig, axes = subplots(len(rows), 3, figsize=(9, 3 * len(rows)), squeeze=False)
    for ax_row, (title, image, proba, clean, truth) in zip(axes, rows, strict=True):
        ax_row[0].imshow(rgb(image))
        ax_row[0].set_title(title, fontsize=9)
        shown = ax_row[1].imshow(proba, cmap="magma", vmin=0, vmax=1)
        ax_row[1].set_title("classifier output", fontsize=9)
        bar = fig.colorbar(shown, ax=ax_row[1], fraction=0.046, pad=0.03)
        bar.set_label("plume probability (0–1)", fontsize=8)
        bar.ax.tick_params(labelsize=7)
        ax_row[2].imshow(clean, cmap="gray", vmin=0, vmax=1)
        if truth is not None and truth.any():
            ax_row[2].contour(truth.astype(float), levels=[0.5], colors="cyan", linewidths=0.8)
        ax_row[2].set_title("denoised (cyan: true outline)", fontsize=9)
        for ax in ax_row:
            ax.set_axis_off()
    fig.tight_layout()
    return save(fig, path, dpi=dpi)


UTILITY_UNITS = {
    "Ratio Plume": "plume fraction of the observed footprints (0–1)",
    "Intensity": "mean intensity utility (label × blue / max, 0–1)",
    "Gradient": "mean gradient utility (Sobel / max, 0–1)",
}
"""The y-axis label of each panel of :func:`utilities_figure`: what is averaged, and its range."""


def utilities_figure(table2_rows, path: str | os.PathLike[str], *, dpi: int = 110) -> Path:
    """Bar chart: ratio plume, intensity and gradient per planner x classifier; baselines as lines.

    The three are dimensionless, 0 to 1 (:data:`UTILITY_UNITS` labels the axes).

    Parameters
    ----------
    table2_rows : list of dict
        Table 2 rows.
    path : str or os.PathLike
        The PNG to write.
    dpi : int
        Resolution.

    Returns
    -------
    pathlib.Path
        The figure written.
    """
    from dyntarget.plan import BASELINES

    metrics = ("Ratio Plume", "Intensity", "Gradient")
    look = [r for r in table2_rows if r["planner"] not in BASELINES]
    base = [r for r in table2_rows if r["planner"] in BASELINES]
    planners = list(dict.fromkeys(r["planner"] for r in look))
    classifiers = list(dict.fromkeys(r["classifier"] for r in look))
    fig, axes = subplots(1, 3, figsize=(15, 4.6))
    width = 0.8 / max(len(classifiers), 1)
    import matplotlib

    cmap = matplotlib.colormaps["tab10"]
    for ax, metric in zip(axes, metrics, strict=True):
        for j, cname in enumerate(classifiers):
            vals = [
                next(
                    (r[metric] for r in look if r["planner"] == p and r["classifier"] == cname), 0.0
                )
                for p in planners
            ]
            ax.bar(
                np.arange(len(planners)) + (j - (len(classifiers) - 1) / 2) * width,
                vals,
                width,
                color=cmap(j % 10),
                label=next(r["Classifier"] for r in look if r["classifier"] == cname),
            )
        for k, r in enumerate(base):
            ax.axhline(
                r[metric],
                color="black",
                ls=["--", ":"][k % 2],
                lw=1,
                label=f"{r['Trajectory Algorithm']} (baseline)",
            )
        ax.set_xticks(np.arange(len(planners)))
        ax.set_xticklabels(
            [next(r["Trajectory Algorithm"] for r in look if r["planner"] == p) for p in planners],
            fontsize=8,
            rotation=15,
        )
        ax.set_title(metric, fontsize=10)
        ax.set_ylabel(UTILITY_UNITS[metric], fontsize=8)
        ax.grid(axis="y", alpha=0.3)
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(
        handles, labels, fontsize=8, ncol=min(len(labels), 6), loc="lower center", frameon=False
    )
    fig.tight_layout(rect=(0, 0.1, 1, 1))
    return save(fig, path, dpi=dpi)
