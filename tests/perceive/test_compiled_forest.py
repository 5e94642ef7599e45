"""The compiled random forest (treelite + tl2cgen) against scikit-learn."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from dyntarget import InvalidParameterError
from dyntarget.perceive import make_classifier

pytest.importorskip("tl2cgen")
pytest.importorskip("treelite")
if shutil.which("gcc") is None:
    pytest.skip("no C compiler", allow_module_level=True)


@pytest.mark.slow
def test_compiled_forest_equals_scikit_learn(tiny_scenes, tmp_path, monkeypatch):
    """A small forest (5 trees, depth 6, so it compiles in seconds) through the
    compiled backend gives scikit-learn's probabilities bit for bit."""
    from sklearn.ensemble import RandomForestClassifier

    from dyntarget.perceive.base import sample_pixels
    from dyntarget.perceive.compiled import compile_forest

    monkeypatch.setenv("DYNTARGET_CACHE", str(tmp_path))
    x, y = sample_pixels(tiny_scenes[:3], max_per_class=2000, rng=np.random.default_rng(0))
    est = RandomForestClassifier(n_estimators=5, max_depth=6, random_state=0).fit(x, y)
    predict = compile_forest(est)
    assert len(list((tmp_path / "forests").glob("forest-*.so"))) == 1
    image = tiny_scenes[3].image
    px = image.reshape(4, -1).T
    got = predict(px)
    np.testing.assert_array_equal(got, est.predict_proba(px)[:, 1].astype(np.float32))
    # through the classifier, with the compiled library reused from the cache
    model = make_classifier("random-forest")
    model.estimator, model.fitted = est, True
    ref = model.predict_proba(image)
    np.testing.assert_array_equal(model.set_backend("compiled").predict_proba(image), ref)
    assert len(list((tmp_path / "forests").glob("forest-*.so"))) == 1


def test_backend_choice_is_checked():
    with pytest.raises(InvalidParameterError, match="backend: expected 'sklearn' or 'compiled'"):
        make_classifier("random-forest").set_backend("gpu")
    from dyntarget.perceive.compiled import compile_forest

    with pytest.raises(InvalidParameterError, match="RandomForestClassifier"):
        compile_forest(object())
