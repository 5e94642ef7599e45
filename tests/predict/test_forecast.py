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


def test_two_looks_put_their_dense_field_on_the_current_frames_grid(monkeypatch):
    # frames of a pass overlap: the motion is estimated on the rows both see (the previous
    # frame's first 32 rows = the current frame's last 32). A dense field found there lies
    # on those 32 rows; the current frame's masks are 64 rows, so the field is moved to the
    # current frame's grid: its cells 32 rows down, the grid 64 rows (issue found flying
    # --predict two-looks over a 3D strip).
    import numpy as np

    from dyntarget.predict import motion as m
    from dyntarget.predict.forecast import two_look_motion

    vel = np.zeros((2, 4, 2), np.float32)
    vel[1, 2] = (3.0, -1.0)  # one cell moving: rows 16-31, columns 32-47 of the overlap
    field = m.MotionField(vel, (0, 0), 16, (32, 64))
    est = m.Motion((1.0, 0.0), regime="detached", dense=field, source="two-looks")
    seen = {}

    def estimate(prev, cur, dt, **kw):
        seen["shapes"] = (prev.shape, cur.shape)
        return est

    monkeypatch.setattr(m, "estimate_motion", estimate)
    look = np.zeros((4, 64, 64), np.float32)
    mask = np.zeros((64, 64), bool)
    out = two_look_motion(look, look, 1.0, previous_mask=mask, current_mask=mask, offset_rows=32)
    assert seen["shapes"] == ((4, 32, 64), (4, 32, 64))
    assert out.dense.shape == (64, 64) and out.dense.origin == (0, 32)
    # the moving cell's centre: overlap (x 39.5, y 23.5) is the current frame's y 55.5
    assert out.dense.sample(np.array([39.5]), np.array([55.5]))[0].tolist() == [3.0, -1.0]
    assert out.dense.sample(np.array([39.5]), np.array([23.5]))[0].tolist() == [0.0, 0.0]
    # a mask of the current frame's shape can now be carried by it
    moved = m.Motion((1.0, 0.0), regime="detached", dense=out.dense)
    from dyntarget.predict import predict_mask

    assert predict_mask(mask, moved, 2.0).shape == (64, 64)
