"""End-members estimated from GEO images (N-FINDR), checked on frames whose truth is known."""

from __future__ import annotations

import numpy as np
import pytest

from dyntarget.errors import InvalidParameterError
from dyntarget.geo import unmix
from dyntarget.geo.endmembers import classify, estimate_members, nfindr

# spectra typed in here (blue, green, red, NIR), not imported from the simulator
TRUE = {
    "cloud": np.array([0.80, 0.81, 0.83, 0.79]),
    "ash": np.array([0.30, 0.26, 0.22, 0.27]),
    "steam": np.array([0.74, 0.76, 0.80, 0.58]),
}
SOIL = np.array([0.12, 0.13, 0.15, 0.22])
VEG = np.array([0.04, 0.08, 0.05, 0.40])


def _frames(noise: float, seed: int = 0):
    """40 x 40 GEO cells over a soil/vegetation ground, a quarter of them mixed with the
    three materials (Dirichlet fractions, total cover 0.2..1), one pure cell of each."""
    rng = np.random.default_rng(seed)
    h = w = 40
    share = rng.uniform(0.0, 1.0, (h, w))
    bg = SOIL[:, None, None] * (1 - share)[None] + VEG[:, None, None] * share[None]
    f = np.zeros((3, h, w))
    hit = rng.random((h, w)) < 0.25
    for i, j in zip(*np.nonzero(hit), strict=True):
        f[:, i, j] = rng.dirichlet([0.4, 0.4, 0.4]) * rng.uniform(0.2, 1.0)
    for k in range(3):  # the pure cells N-FINDR assumes
        f[:, 0, 5 * k] = 0.0
        f[k, 0, 5 * k] = 1.0
    m = np.stack([TRUE[n] for n in ("cloud", "ash", "steam")])
    img = bg * (1 - f.sum(axis=0))[None] + np.einsum("khw,kb->bhw", f, m)
    img = img + rng.normal(0.0, noise, img.shape)
    return img, bg, f


def test_noise_free_frames_give_back_the_true_spectra_and_fractions():
    img, bg, f = _frames(0.0)
    members, names, info = estimate_members([img], bg)
    assert names == ["cloud", "ash", "steam"]
    for n, m in zip(names, members, strict=True):
        np.testing.assert_allclose(m, TRUE[n], atol=1e-9)  # the pure cells themselves
    np.testing.assert_allclose(unmix(img, bg, members), f, atol=1e-6)
    assert info["candidates"] > 100


@pytest.mark.parametrize("seed", range(5))
def test_fractions_recovered_within_tolerance_with_geo_noise(seed):
    # the imager's noise (0.005): with the noise no vertex is exactly pure; measured on
    # seeds 0..4: spectra within 0.013..0.097 of the truth, mean |fraction error|
    # 0.009..0.012 (0.008..0.009 with the true spectra on the same frames)
    img, bg, f = _frames(0.005, seed=seed)
    members, names, _ = estimate_members([img], bg)
    assert names == ["cloud", "ash", "steam"]
    for n, m in zip(names, members, strict=True):
        assert np.abs(m - TRUE[n]).max() < 0.1
    est = unmix(img, bg, members)
    assert float(np.abs(est - f).mean()) < 0.015
    plume = est[1] + est[2]
    assert float(np.abs(plume - (f[1] + f[2])).mean()) < 0.015


def test_nfindr_picks_the_corners_of_a_triangle_over_its_inside():
    rng = np.random.default_rng(0)
    corners = np.array([[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]])
    inside = rng.dirichlet([1, 1, 1], 200) @ corners * 0.9
    pts = np.concatenate([inside[:100], corners, inside[100:]])
    assert sorted(nfindr(pts, np.zeros(4), 3).tolist()) == [100, 101, 102]


def test_classify_names_by_shape_whatever_their_order_and_a_dim_mixture():
    v = np.stack([TRUE["steam"], TRUE["cloud"], TRUE["ash"]])
    assert classify(v, SOIL) == {"cloud": 1, "ash": 2, "steam": 0}
    # half-covered cells (mixtures with the ground) keep their names
    half = 0.5 * v + 0.5 * VEG
    assert classify(half, VEG) == {"cloud": 1, "ash": 2, "steam": 0}


def test_nothing_bright_gives_no_member_and_bad_input_is_refused():
    bg = np.full((4, 5, 5), 0.1)
    members, names, info = estimate_members([bg.copy()], bg)
    assert members.shape == (0, 4) and names == [] and info["candidates"] == 0
    with pytest.raises(InvalidParameterError, match="does not match"):
        estimate_members([np.zeros((4, 3, 3))], bg)
    with pytest.raises(InvalidParameterError, match="no GEO image"):
        estimate_members([], bg)
