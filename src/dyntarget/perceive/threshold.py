"""Band threshold: the haze-optimised transform (HOT) cloud test adapted to plumes.

HOT (Zhang, Guindon & Cihlar 2002, *Remote Sens. Environ.* 82) measures haze
and cloud as the departure from the clear-sky line in blue-red space::

    HOT = blue - 0.5 * red - 0.08

Bright, hazy pixels (cloud and plume alike) have large HOT. As the paper says,
clouds and plumes look alike in the visible, so a NIR test is added: plumes of
small droplets, sulfate and ash reflect less in the NIR relative to the
visible than large-droplet clouds do, so the ratio ``NIR / mean(R, G, B)`` must
stay below a second threshold. A pixel is plume when both tests pass.

Both thresholds are fitted on the training scenes by a grid search that
maximises the plume IoU on a class-balanced pixel sample (the grids are
quantiles of the sampled feature values).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from dyntarget.errors import ModelFileError
from dyntarget.perceive.base import (
    CLASSIFIERS,
    DEFAULT_MAX_PIXELS_PER_CLASS,
    Classifier,
    sample_pixels,
)

HOT_SLOPE, HOT_OFFSET = 0.5, 0.08


def hot_features(image_or_pixels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(HOT, NIR/visible ratio)`` for a ``(4, ...)`` array.

    Parameters
    ----------
    image_or_pixels : numpy.ndarray
        Bands R, G, B, NIR along the first axis: a ``(4, H, W)`` image or ``(4, n)`` pixels.

    Returns
    -------
    hot : numpy.ndarray
        ``blue - 0.5 * red - 0.08``, shaped as the rest of the input.
    ratio : numpy.ndarray
        ``NIR / mean(R, G, B)`` (the mean at least 1e-3).
    """
    r, g, b, nir = image_or_pixels[0], image_or_pixels[1], image_or_pixels[2], image_or_pixels[3]
    hot = b - HOT_SLOPE * r - HOT_OFFSET
    ratio = nir / np.maximum((r + g + b) / 3.0, 1e-3)
    return hot, ratio


@CLASSIFIERS.register("band-threshold")
class BandThreshold(Classifier):
    """The HOT haze test and the NIR/visible ratio test (see the module docstring).

    Parameters
    ----------
    seed : int
        Seed of the class-balanced pixel sample the thresholds are fitted on.
    softness : float
        Width of the sigmoids that turn the two tests into a probability, in
        feature units (smaller is sharper).
    """

    name = "band-threshold"
    kind = "threshold"
    summary = "HOT haze test (Zhang et al. 2002) + NIR/visible ratio test; thresholds fitted on training scenes"

    def __init__(self, *, seed: int = 0, softness: float = 0.01) -> None:
        super().__init__(seed=seed)
        self.softness = float(softness)
        self.hot_threshold = 0.0
        self.ratio_threshold = 1.0

    def get_config(self) -> dict[str, Any]:
        """Constructor arguments as JSON-able values (stored in the model's metadata).

        Returns
        -------
        dict
            ``seed`` and ``softness``.
        """
        return {"seed": self.seed, "softness": self.softness}

    def _fit(self, scenes) -> None:
        rng = np.random.default_rng(self.seed)
        x, y = sample_pixels(scenes, max_per_class=DEFAULT_MAX_PIXELS_PER_CLASS, rng=rng)
        hot, ratio = hot_features(x.T)
        yb = y.astype(bool)
        hot_grid = np.quantile(hot, np.linspace(0.02, 0.98, 49))
        ratio_grid = np.quantile(ratio, np.linspace(0.02, 1.0, 50))
        best = (-1.0, 0.0, 1.0)
        above = hot[None, :] > hot_grid[:, None]  # (49, n)
        for rt in ratio_grid:
            pred = above & (ratio <= rt)[None, :]
            tp = (pred & yb).sum(axis=1)
            fp = (pred & ~yb).sum(axis=1)
            fn = yb.sum() - tp
            iou = tp / np.maximum(tp + fp + fn, 1)
            i = int(np.argmax(iou))
            if iou[i] > best[0]:
                best = (float(iou[i]), float(hot_grid[i]), float(rt))
        _, self.hot_threshold, self.ratio_threshold = best

    def _predict_proba(self, image: np.ndarray) -> np.ndarray:
        from scipy.special import expit

        hot, ratio = hot_features(image)
        k = 1.0 / self.softness
        p_hot = expit(k * (hot - self.hot_threshold))
        p_nir = expit(k * (self.ratio_threshold - ratio) / max(self.ratio_threshold, 1e-3))
        # both tests pass <=> both sigmoids >= 0.5 <=> min >= 0.5
        return np.minimum(p_hot, p_nir)

    def _save_weights(self, directory: Path) -> None:
        params = {"hot_threshold": self.hot_threshold, "ratio_threshold": self.ratio_threshold}
        (directory / "params.json").write_text(json.dumps(params), encoding="utf-8")

    def _load_weights(self, directory: Path) -> None:
        try:
            from dyntarget.io.safeopen import read_json

            params = read_json(directory / "params.json", max_bytes=1 << 16)
            self.hot_threshold = float(params["hot_threshold"])
            self.ratio_threshold = float(params["ratio_threshold"])
        except (OSError, ValueError, KeyError, TypeError) as exc:
            raise ModelFileError(f"{directory}: bad params.json ({exc})") from None
