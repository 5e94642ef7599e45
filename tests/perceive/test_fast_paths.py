"""Lean inference paths of the pixel classifiers against scikit-learn's own."""

from __future__ import annotations

import numpy as np

from dyntarget.perceive import make_classifier
from dyntarget.perceive.pixel import PREDICT_CHUNK, mlp_float32


def test_mlp_float32_equals_scikit_learn(tiny_scenes):
    model = make_classifier("mlp").fit(tiny_scenes[:3])
    rng = np.random.default_rng(0)
    x = rng.uniform(-0.1, 1.2, (5000, 4)).astype(np.float32)  # inside and beyond the data
    fast = mlp_float32(model.estimator)
    assert fast is not None
    got, ref = fast(x), model.estimator.predict_proba(x.astype(np.float64))[:, 1]
    assert got.dtype == np.float32
    np.testing.assert_allclose(got, ref, atol=1e-5, rtol=0)
    # and through predict_proba, with more than one chunk on the thread pool
    image = np.tile(tiny_scenes[3].image, (1, 9, 9))[:, :, : PREDICT_CHUNK // 500]
    assert image.shape[1] * image.shape[2] > PREDICT_CHUNK
    flat = image.reshape(4, -1).T.astype(np.float64)
    np.testing.assert_allclose(
        model.predict_proba(image).ravel(),
        model.estimator.predict_proba(flat)[:, 1],
        atol=1e-5,
        rtol=0,
    )


def test_mlp_float32_declines_other_models(tiny_scenes):
    from sklearn.neural_network import MLPClassifier
    from sklearn.pipeline import make_pipeline
    from sklearn.preprocessing import StandardScaler

    lr = make_classifier("logistic-regression").fit(tiny_scenes[:3])
    assert mlp_float32(lr.estimator) is None
    tanh = make_pipeline(StandardScaler(), MLPClassifier((4,), activation="tanh"))
    assert mlp_float32(tanh) is None  # unfitted is fine: the activation is checked first
