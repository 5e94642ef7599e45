"""Spatially varying motion, moving grounds and the persistence fallback (issue 28).

The frames are made with ``scipy.ndimage.affine_transform`` (not OpenCV, which the
estimator uses) and the truth masks analytically: a point belongs to the cloud at
time t when its position carried back to t = 0 lies in the cloud's ellipse.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import ndimage

from dyntarget.predict import MotionField, estimate_motion, predict_mask
from dyntarget.predict.motion import Motion

N = 192
C = (N - 1) / 2


def _texture(seed, sigma=2.0):
    rng = np.random.default_rng(seed)
    t = ndimage.gaussian_filter(rng.random((N, N)), sigma)
    return (t - t.min()) / (t.max() - t.min())  # 0 to 1: texture the flow can follow


def _iou(a, b):
    return (a & b).sum() / max((a | b).sum(), 1)


def _inside(x0, y0):
    """The cloud at t = 0: an ellipse off the rotation centre."""
    return ((x0 - 80) / 45) ** 2 + ((y0 - 95) / 30) ** 2 <= 1


def _rotation_world(omega_deg_s, drift=(0.0, 0.0)):
    """Cloud layer rotating about the image centre at ``omega`` and drifting, over a still ground."""
    ground = 0.1 + 0.1 * _texture(1)
    layer = 0.55 + 0.4 * _texture(2)
    yy, xx = np.mgrid[0:N, 0:N].astype(float)

    def back(t):  # where the point (x, y) at t was at 0
        a = -math.radians(omega_deg_s * t)
        x, y = xx - C - drift[0] * t, yy - C - drift[1] * t
        return C + math.cos(a) * x - math.sin(a) * y, C + math.sin(a) * x + math.cos(a) * y

    def mask(t):
        return _inside(*back(t))

    def frame(t):
        a = math.radians(omega_deg_s * t)
        # affine_transform maps output (row, col) to input: input = M @ output + offset
        m = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])  # (row, col)
        out = np.array([C + drift[1] * t, C + drift[0] * t])
        offset = np.array([C, C]) - m @ out
        moved = ndimage.affine_transform(layer, m, offset=offset, order=1, mode="nearest")
        img = np.where(mask(t), moved, ground)
        return np.repeat(img[None], 4, 0).astype(np.float32)

    return frame, mask


def test_rotating_cloud_follows_the_dense_field_better_than_one_velocity():
    frame, mask = _rotation_world(0.3, drift=(0.2, 0.0))  # 3 degrees between the 10 s looks
    m = estimate_motion(frame(0), frame(10), 10.0, previous_mask=mask(0), current_mask=mask(10))
    assert m.reliable and m.dense is not None and m.ground == "fixed", m.summary()
    truth = mask(70)  # 60 s after the second look: 18 degrees more
    dense = _iou(predict_mask(mask(10), m, 60.0), truth)
    uniform = _iou(predict_mask(mask(10), Motion(m.velocity, regime="detached"), 60.0), truth)
    still = _iou(mask(10), truth)
    assert dense >= 0.85, (dense, uniform, still)
    assert dense > uniform + 0.05 and dense > still + 0.2, (dense, uniform, still)


def test_rotation_field_matches_the_analytic_velocity():
    frame, mask = _rotation_world(0.3)
    m = estimate_motion(frame(0), frame(10), 10.0, previous_mask=mask(0), current_mask=mask(10))
    ys, xs = np.nonzero(mask(10) & ~ndimage.binary_dilation(~mask(10), iterations=4))
    v = m.dense.sample(xs.astype(np.float32), ys.astype(np.float32))
    w = math.radians(0.3)  # rad/s; v = w x (r - c): (-w (y - c), w (x - c))
    truth = np.stack([-w * (ys - C), w * (xs - C)], axis=1)
    err = np.hypot(*(v - truth).T)
    assert np.median(err) < 0.1 * np.median(np.hypot(*truth.T)), np.median(err)


def _weather_look(field, plume, v, t):
    """The whole scene (ground and plume alike) carried by ``v`` px/s for ``t`` s, wrapping."""
    shift = (v[1] * t, v[0] * t)  # rows, cols
    img = ndimage.shift(0.2 + 0.6 * field, shift, order=1, mode="wrap")
    m = ndimage.shift(plume.astype(float), shift, order=0, mode="wrap") > 0.5
    return np.repeat(img[None], 4, 0).astype(np.float32), m


def test_moving_ground_is_found_and_not_removed():
    """The whole scene translates by (6, -3) px per 10 s look (weather): auto finds it moving."""
    field = _texture(3, 3.0)
    plume = field > np.percentile(field, 85)
    v = (0.6, -0.3)
    (a, ma), (b, mb) = (_weather_look(field, plume, v, t) for t in (0, 10))
    auto = estimate_motion(a, b, 10.0, previous_mask=ma, current_mask=mb)
    assert auto.ground == "moving" and any("ground auto -> moving" in n for n in auto.notes)
    assert auto.velocity == pytest.approx(v, abs=0.05), auto.summary()
    fixed = estimate_motion(a, b, 10.0, previous_mask=ma, current_mask=mb, ground="fixed")
    assert fixed.speed < 0.1, fixed.summary()  # the shift removed as misregistration


def test_fragment_beside_a_big_cloud_is_not_attached():
    """Issue 28: a small cloud next to a big one, both drifting 1 px/s, is carried, not held."""
    ground = 0.1 + 0.1 * _texture(4)
    layer = 0.55 + 0.4 * _texture(5)
    yy, xx = np.mgrid[0:N, 0:N]

    def look(t):
        dx = 1.0 * t
        big = ((xx - 70 - dx) / 40) ** 2 + ((yy - 90) / 50) ** 2 <= 1
        small = ((xx - 118 - dx) / 6) ** 2 + ((yy - 60) / 8) ** 2 <= 1
        m = big | small
        moved = ndimage.shift(layer, (0, dx), order=1, mode="nearest")
        return np.repeat(np.where(m, moved, ground)[None], 4, 0).astype(np.float32), m

    (a, ma), (b, mb) = look(0), look(10)
    m = estimate_motion(a, b, 10.0, previous_mask=ma, current_mask=mb)
    assert m.regime == "detached" and not m.attached, m.summary()
    _, truth = look(100)
    assert _iou(predict_mask(mb, m, 90.0), truth) > 0.9


def test_motion_field_samples_bilinearly_between_cells():
    # cells of 4 px whose centres lie at 1.5 + 4 i: v = (cell column, 0)
    vel = np.zeros((3, 5, 2), np.float32)
    vel[..., 0] = np.arange(5)[None, :]
    f = MotionField(vel, (0, 0), 4, (12, 20))
    got = f.sample(np.float32([1.5, 3.5, 5.5, 100.0]), np.float32([1.5, 1.5, 1.5, 1.5]))
    assert got[:, 0].tolist() == pytest.approx([0.0, 0.5, 1.0, 4.0])  # beyond: the edge cell


@pytest.mark.slow  # a 1024 px scene, three estimates: ~10 s on 2 loaded cores
def test_a_moving_background_gets_the_finer_flow_grid():
    """Issue 28: weather filling a 1024 px window; once the background is found moving the
    flow runs on at most FLOW_MAX_PX_MOVING = 384 px a side (1024 / 384 -> every 3 px),
    where a fixed ground keeps FLOW_MAX_PX = 256 (every 4 px)."""
    rng = np.random.default_rng(7)
    field = ndimage.gaussian_filter(rng.random((1024, 1024)), 4.0)
    field = (field - field.min()) / (field.max() - field.min())
    cells = ndimage.gaussian_filter(rng.random((1024, 1024)), 40.0)
    plume = cells > np.percentile(cells, 90)  # a few large cells, textured by the field
    v = (0.6, -0.3)
    (a, ma), (b, mb) = (_weather_look(field, plume, v, t) for t in (0, 10))
    auto = estimate_motion(a, b, 10.0, previous_mask=ma, current_mask=mb)
    assert auto.ground == "moving" and auto.dense is not None, auto.summary()
    assert auto.dense.scale == 3 and "1/3 grid" in auto.method, auto.method
    assert auto.velocity == pytest.approx(v, abs=0.05), auto.summary()
    given = estimate_motion(a, b, 10.0, previous_mask=ma, current_mask=mb, ground="moving")
    assert given.dense is not None and given.dense.scale == 3
    fixed = estimate_motion(a, b, 10.0, previous_mask=ma, current_mask=mb, ground="fixed")
    assert fixed.dense is None or fixed.dense.scale == 4, fixed.method
    assert "1/4 grid" in fixed.method or fixed.dense is None, fixed.method
