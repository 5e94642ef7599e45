"""The predict stage's entry point and its one pysteps Lucas-Kanade wrapper (issue 39)."""

from __future__ import annotations

import builtins

import cv2
import numpy as np
import pytest

from dyntarget.errors import InvalidParameterError
from dyntarget.predict import lucas_kanade, plume_motion, wind_motion


def _looks(shift: int):
    rng = np.random.default_rng(0)
    tex = cv2.GaussianBlur(rng.random((96, 96)).astype(np.float32), (0, 0), 2)
    ground = np.repeat(0.1 + 0.1 * tex[None], 4, 0)

    def frame(x0):
        img, m = ground.copy(), np.zeros((96, 96), bool)
        m[30:60, x0 : x0 + 30] = True
        img[:, m] = 0.6 + 0.6 * np.roll(tex, x0 - 20, axis=1)[m]
        return img, m

    (a, ma), (b, mb) = frame(20), frame(20 + shift)
    return a, b, ma, mb


def test_one_look_is_the_prior_and_no_prior_is_no_motion():
    prior = wind_motion(16.0, 0.0, gsd_m=8.0)  # from the north: 2 px/s south (+rows)
    assert plume_motion(prior) is prior
    assert plume_motion(prior).velocity == pytest.approx((0.0, 2.0))
    assert plume_motion(None) is None


def test_two_looks_give_the_cloud_shift_over_the_interval():
    # a textured cloud 6 px further east 3 s later: 2 px/s east
    m = plume_motion(None, _looks(6), 3.0)
    assert m is not None and m.source == "two-looks"
    assert m.velocity[0] == pytest.approx(2.0, abs=0.2)
    assert abs(m.velocity[1]) < 0.2


@pytest.mark.slow  # importing pysteps takes seconds
def test_lucas_kanade_finds_a_blob_moving_two_pixels():
    y, x = np.mgrid[0:32, 0:64]

    def blob(c):
        return np.exp(-((x - c) ** 2 + (y - 16) ** 2) / 8.0)

    v = lucas_kanade(np.stack([blob(20), blob(22), blob(24)]), needs="pysteps")
    assert v.shape == (2, 32, 64) and v.dtype == np.float64
    assert v[0, 16, 22] == pytest.approx(2.0, abs=0.1)  # u: 2 px per step along columns
    assert abs(v[1, 16, 22]) < 0.1
    assert np.isfinite(v).all()


def test_lucas_kanade_without_pysteps_says_what_needs_it(monkeypatch):
    real = builtins.__import__

    def no_pysteps(name, *args, **kwargs):
        if name == "pysteps" or name.startswith("pysteps."):
            raise ImportError(name)
        return real(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_pysteps)
    with pytest.raises(InvalidParameterError, match="^GEO nowcast needs pysteps$"):
        lucas_kanade(np.zeros((2, 8, 8)), needs="GEO nowcast needs pysteps")
