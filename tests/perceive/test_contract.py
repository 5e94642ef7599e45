"""One contract test run on every registered classifier."""

from __future__ import annotations

import numpy as np
import pytest

from dyntarget import InvalidParameterError, InvalidSceneError
from dyntarget.perceive import CLASSIFIERS, load_classifier, make_classifier
from helpers import FAST_KWARGS

NAMES = CLASSIFIERS.available()
CASES = [  # U-Nets train for seconds even at their test size: the slow tier
    pytest.param(n, marks=pytest.mark.slow) if CLASSIFIERS.get(n).kind == "unet" else n
    for n in NAMES
]


def test_registry_has_exactly_the_paper_classifiers():
    assert NAMES == [
        "band-threshold",
        "naive-bayes",
        "logistic-regression",
        "decision-tree",
        "random-forest",
        "mlp",
        "unet-xception",
        "unet-uavsar",
    ]


@pytest.fixture(scope="module", params=CASES)
def fitted(request, tiny_scenes):
    name = request.param
    return make_classifier(name, **FAST_KWARGS.get(name, {})).fit(tiny_scenes[:3])


def test_output_shape_dtype_range(fitted, tiny_scenes):
    image = tiny_scenes[3].image
    proba = fitted.predict_proba(image)
    assert proba.shape == (64, 64) and proba.dtype == np.float32
    assert np.isfinite(proba).all() and proba.min() >= 0.0 and proba.max() <= 1.0
    mask = fitted.predict(image)
    assert mask.dtype == bool and mask.shape == (64, 64)
    np.testing.assert_array_equal(mask, proba >= 0.5)
    assert not np.array_equal(
        fitted.predict(image, threshold=0.0), fitted.predict(image, threshold=1.0)
    )


def test_non_square_and_small_images(fitted, tiny_scenes):
    image = tiny_scenes[3].image[:, :40, :23]
    assert fitted.predict_proba(image).shape == (40, 23)


def test_save_load_identical(fitted, tiny_scenes, tmp_path):
    path = fitted.save(tmp_path / "model")
    loaded = load_classifier(path)
    assert type(loaded) is type(fitted)
    assert loaded.get_config() == fitted.get_config()
    np.testing.assert_array_equal(
        loaded.predict_proba(tiny_scenes[3].image), fitted.predict_proba(tiny_scenes[3].image)
    )


def test_same_seed_same_model(fitted, tiny_scenes):
    again = make_classifier(fitted.name, **FAST_KWARGS.get(fitted.name, {})).fit(tiny_scenes[:3])
    np.testing.assert_array_equal(
        again.predict_proba(tiny_scenes[3].image), fitted.predict_proba(tiny_scenes[3].image)
    )


def test_rejects_three_band_image(fitted):
    with pytest.raises(InvalidSceneError, match="expected 4 bands"):
        fitted.predict_proba(np.zeros((3, 16, 16), np.float32))


def test_rejects_nan_image(fitted):
    image = np.zeros((4, 8, 8), np.float32)
    image[0, 0, 0] = np.nan
    with pytest.raises(InvalidSceneError, match="NaN"):
        fitted.predict(image)


@pytest.mark.parametrize("name", CASES)
def test_unfitted_and_bad_training(name, tiny_scenes):
    model = make_classifier(name, **FAST_KWARGS.get(name, {}))
    with pytest.raises(InvalidParameterError, match="fit"):
        model.predict_proba(tiny_scenes[0].image)
    with pytest.raises(InvalidParameterError, match="not fitted"):
        model.save("unused")
    with pytest.raises(InvalidParameterError, match="at least one"):
        model.fit([])
    from dataclasses import replace

    empty = replace(tiny_scenes[0], label=np.zeros((64, 64), bool))
    with pytest.raises(InvalidSceneError, match="no plume pixel"):
        model.fit([empty])
    unlabelled = replace(tiny_scenes[0], label=None)
    with pytest.raises(InvalidSceneError, match="has no label"):
        model.fit([unlabelled])


def test_unet_parameter_validation():
    with pytest.raises(InvalidParameterError, match="tile"):
        make_classifier("unet-xception", tile=40)
    with pytest.raises(InvalidParameterError, match="epochs"):
        make_classifier("unet-uavsar", epochs=0)


def test_unknown_classifier_lists_names():
    from dyntarget import UnknownNameError

    with pytest.raises(UnknownNameError, match="expected one of: band-threshold, naive-bayes"):
        make_classifier("svm")


@pytest.mark.slow
def test_unet_tiles_stitch_without_seams(tiny_scenes):
    """Prediction of overlapping tiles equals running the net on the whole image in the tile interiors."""
    import torch

    from dyntarget.perceive.unet import tile_origins

    model = make_classifier("unet-uavsar", **FAST_KWARGS["unet-uavsar"]).fit(tiny_scenes[:2])
    image = tiny_scenes[3].image
    tiled = model.predict_proba(image)
    with torch.inference_mode():
        whole = torch.softmax(model.model(torch.from_numpy(image[None])), 1)[0, 1].numpy()
    # no seam: tiled and whole-image probabilities agree closely everywhere away from the image edge
    inner = np.abs(tiled - whole)[4:-4, 4:-4]
    assert inner.max() < 0.15
    # and the tiled output is smooth across tile boundaries (no jump larger than elsewhere)
    assert tile_origins(64, 32, 16) == [0, 16, 32]
    jumps_at_boundary = np.abs(np.diff(tiled, axis=1))[:, [15, 31, 47]].mean()
    jumps_elsewhere = np.abs(np.diff(tiled, axis=1)).mean()
    assert jumps_at_boundary < 2.0 * jumps_elsewhere


def test_band_threshold_learns_plume_over_cloud():
    """Hand-built pixels: hazy plume (low NIR ratio) vs cloud (high NIR) vs ground."""
    from dyntarget import Scene

    image = np.zeros((4, 6, 6), np.float32)
    image[:] = np.array([0.2, 0.18, 0.12, 0.3], np.float32)[:, None, None]  # soil
    image[:, :2, :] = np.array([0.74, 0.76, 0.80, 0.58], np.float32)[:, None, None]  # steam plume
    image[:, 4:, :] = np.array([0.80, 0.81, 0.83, 0.79], np.float32)[:, None, None]  # cloud
    label = np.zeros((6, 6), bool)
    label[:2] = True
    model = make_classifier("band-threshold").fit([Scene(image, label=label)])
    np.testing.assert_array_equal(model.predict(image), label)


@pytest.mark.parametrize(
    "name", ["naive-bayes", "logistic-regression", "decision-tree", "random-forest", "mlp"]
)
def test_chunked_parallel_prediction_equals_one_call(name, tiny_scenes, monkeypatch):
    """The fast path (fixed chunks on a thread pool) is bit-identical to one predict_proba
    call. The MLP runs its own float32 forward pass (equal to scikit-learn to 1e-5,
    test_fast_paths.py), whose matrix products may block differently for other row
    counts: there, equal to one call of that pass to 1e-6."""
    from dyntarget.perceive import pixel
    from dyntarget.perceive.base import pixels

    model = make_classifier(name).fit(tiny_scenes[:3])
    image = tiny_scenes[3].image
    x = np.ascontiguousarray(pixels(image))
    if name == "mlp":
        straight = model.chunk_predictor()(x)
    else:
        straight = model.estimator.predict_proba(x)[:, 1]
    monkeypatch.setattr(pixel, "PREDICT_CHUNK", 500)  # 64 x 64 px -> 9 chunks, last one short
    chunked = model.predict_proba(image)
    expected = straight.astype(np.float32).reshape(64, 64)
    if name == "mlp":
        np.testing.assert_allclose(chunked, expected, atol=1e-6, rtol=0)
    else:
        np.testing.assert_array_equal(chunked, expected)
