"""Real-pixel sanity check: train on one part of a labelled real scene, test on a disjoint part.

The scene is split by columns into a training part (left), a gap that neither
side uses (so neighbouring, correlated pixels cannot leak across), and a test
part (right). Every classifier is trained on the left part, scored on the
right with and without denoising, and every planner plans on the right part's
(denoised) prediction; observations are scored against the true mask at the
scene's own resolution (factor 1).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from typing import Any

from dyntarget.errors import InvalidParameterError
from dyntarget.evaluate.crossval import classifier_kwargs
from dyntarget.evaluate.metrics import Confusion
from dyntarget.evaluate.tables import display
from dyntarget.observe import UtilityMaps, observe
from dyntarget.perceive import CLASSIFIERS, make_classifier
from dyntarget.pipeline import plan_segmentation, segment
from dyntarget.plan import BASELINES, PAPER_PLANNERS
from dyntarget.scene import Scene


def split_columns(
    scene: Scene, *, train_fraction: float = 0.45, gap: int = 32
) -> tuple[Scene, Scene]:
    """Left ``train_fraction`` of the columns for training, then ``gap`` unused columns, the rest for testing.

    Parameters
    ----------
    scene : dyntarget.scene.Scene
        A labelled scene.
    train_fraction : float
        Share of the columns for training.
    gap : int
        Columns left unused between the parts.

    Returns
    -------
    train, test : dyntarget.scene.Scene
        The two parts (transforms shifted to their columns).

    Raises
    ------
    dyntarget.errors.InvalidParameterError
        When the scene is too narrow for the split.
    """
    w = scene.shape[1]
    cut = round(train_fraction * w)
    if not 0 < cut < w - gap - 1:
        raise InvalidParameterError(
            f"split: {w} px wide scene cannot be split at {cut} with a {gap} px gap"
        )

    def part(c0: int, c1: int, suffix: str) -> Scene:
        t = scene.transform
        if t is not None:
            from affine import Affine

            t = t @ Affine.translation(c0, 0)
        return replace(
            scene,
            image=scene.image[:, :, c0:c1],
            label=scene.truth[:, c0:c1],
            transform=t,
            id=f"{scene.id}-{suffix}",
        )

    return part(0, cut, "train"), part(cut + gap, w, "test")


def real_pixel_check(
    scene: Scene,
    *,
    classifiers: Sequence[str] | None = None,
    epochs: int = 50,
    seed: int = 0,
    train_fraction: float = 0.45,
    gap: int = 32,
) -> dict[str, Any]:
    """Train every classifier on the left part of ``scene``, score and plan on the right (see the module docstring).

    Parameters
    ----------
    scene : dyntarget.scene.Scene
        A labelled scene.
    classifiers : sequence of str or None
        Classifiers (default: all registered).
    epochs : int
        Training epochs of the U-Nets.
    seed : int
        Seed of the classifiers.
    train_fraction : float
        Share of the columns used for training.
    gap : int
        Columns left unused between the two parts.

    Returns
    -------
    dict
        ``segmentation`` and ``planning`` rows, ``split`` (column and row counts)
        and ``plume_fraction`` of each part.
    """
    train, test = split_columns(scene, train_fraction=train_fraction, gap=gap)
    classifiers = list(classifiers or CLASSIFIERS.available())
    maps = UtilityMaps.from_scene(test)
    lookahead = [p for p in PAPER_PLANNERS if p not in BASELINES]
    seg_rows, plan_rows = [], []
    truth = segment(test.image, mask=test.label, valid=test.valid, denoise=False)
    for name in BASELINES:
        m = observe(plan_segmentation(truth, name), maps, factor=1)
        plan_rows.append({"Trajectory Algorithm": display(name), "Classifier": "N/A", **_obs(m)})
    for name in classifiers:
        model = make_classifier(name, **classifier_kwargs(name, seed=seed, epochs=epochs)).fit(
            [train]
        )
        seg = segment(test.image, model, valid=test.valid)  # Algorithm 1, as plan_scene runs it
        for denoised, mask in ((False, seg.raw_mask), (True, seg.mask)):
            seg_metrics = Confusion.from_masks(mask, test.truth).metrics()
            seg_rows.append(
                {
                    "Classifier": "+ Denoising" if denoised else display(name),
                    "classifier": name,
                    "denoised": denoised,
                    "Accuracy": seg_metrics["accuracy"],
                    "Precision": seg_metrics["precision"],
                    "Recall": seg_metrics["recall"],
                    "IoU": seg_metrics["iou"],
                }
            )
        for pname in lookahead:
            o = observe(plan_segmentation(seg, pname), maps, factor=1)
            plan_rows.append(
                {"Trajectory Algorithm": display(pname), "Classifier": display(name), **_obs(o)}
            )
    return {
        "segmentation": seg_rows,
        "planning": plan_rows,
        "split": {
            "train_columns": train.shape[1],
            "gap": gap,
            "test_columns": test.shape[1],
            "rows": test.shape[0],
        },
        "plume_fraction": {"train": float(train.truth.mean()), "test": float(test.truth.mean())},
    }


def _obs(m) -> dict[str, float]:
    return {
        "Pixels Observed": float(m.pixels_observed),
        "Ratio Plume": m.ratio_plume,
        "Intensity": m.intensity,
        "Gradient": m.gradient,
    }
