"""Figures (matplotlib, Agg backend, PNG)."""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from dyntarget.io.atomic import atomic_path
from dyntarget.scene import Scene


def rgb(image: np.ndarray, bands: tuple[int, int, int] = (0, 1, 2)) -> np.ndarray:
    """An 8-bit-like display image ``(H, W, 3)`` in 0..1 with a 2-98 % stretch."""
    stack = np.stack([image[b] for b in bands], axis=-1).astype(np.float32)
    lo, hi = np.percentile(stack, [2, 98])
    if hi <= lo:
        hi = lo + 1e-6
    return np.clip((stack - lo) / (hi - lo), 0.0, 1.0)


def save(fig: plt.Figure, path: str | os.PathLike[str], *, dpi: int = 110) -> Path:
    """Save a figure atomically as PNG and close it."""
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=dpi, bbox_inches="tight", format="png")
    plt.close(fig)
    return Path(path)


def scenes_figure(
    scenes: Sequence[Scene], path: str | os.PathLike[str], *, max_scenes: int = 4, dpi: int = 110
) -> Path:
    """Rows of scenes: true colour, false colour (NIR, R, G), label."""
    scenes = list(scenes)[:max_scenes]
    fig, axes = plt.subplots(len(scenes), 3, figsize=(9, 3 * len(scenes)), squeeze=False)
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
