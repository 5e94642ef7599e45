"""dyntarget.predict.height: plume-top height and wind from looks, rise, plume disparity.

Synthetic looks are built here from the geometry written out by hand (view zenith from the
triangle centre-ground-spacecraft, first-order shift h tan(theta)) or from
dyntarget.parallax's forward model; the estimator inverts them.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from dyntarget import parallax
from dyntarget.errors import InvalidParameterError
from dyntarget.predict.height import Look, envelope_disparity, fit_height, fit_rise, plume_disparity

R = 6_371_008.7714
H = 500e3
V_GROUND = parallax.ground_speed(H)  # 7062 m/s at 500 km


def _tan_hand(d: float) -> float:
    """tan(view zenith) D from the nadir: (R + H) sin g / ((R + H) cos g - R), g = D / R."""
    g = d / R
    return (R + H) * math.sin(g) / ((R + H) * math.cos(g) - R)


def _looks(h, wind, ahead_km, *, sigma=30.0, rng=None, cross=0.0):
    """Looks of a feature at height h drifting with ``wind`` (east, north), flying north.

    The spacecraft's nadir moves north at the ground speed; look i is taken when the
    feature is ``ahead_km[i]`` ahead. Positions from parallax.py's exact forward model."""
    out = []
    for a in ahead_km:
        t = (ahead_km[0] - a) * 1e3 / V_GROUND
        x, y = cross + wind[0] * t, wind[1] * t
        ny = y - a * 1e3
        rx, ry = x, y - ny
        d = math.hypot(rx, ry)
        s = float(parallax.parallax_shift(H, d, h))
        ax, ay = x + s * rx / d, y + s * ry / d
        if rng is not None:
            ax, ay = ax + rng.normal(0, sigma), ay + rng.normal(0, sigma)
        out.append(Look(t, ax, ay, 0.0, ny, H, sigma))
    return out


def test_two_looks_with_a_prior_match_the_hand_formula():
    # 500 km then 300 km ahead (28.3 s): the shift (away from the nadir, +y) falls, so the
    # along-track apparent motion is dy = v dt - h (tan 500 - tan 300); with the true wind
    # as prior, first order h = (v dt - dy) / (tan 500 - tan 300), within 3 % (the
    # curvature adds ~2 %)
    h, wind = 10e3, (0.0, 8.0)
    a, b = _looks(h, wind, [500, 300])
    dt = b.t_s - a.t_s
    h_hand = (wind[1] * dt - (b.y_m - a.y_m)) / (_tan_hand(500e3) - _tan_hand(300e3))
    fit = fit_height([a, b], wind_prior=wind)
    assert fit.ok and fit.wind_prior
    assert fit.height_m == pytest.approx(h, abs=1.0)  # exact model: recovered to 1 m
    assert h_hand == pytest.approx(h, rel=0.03)  # the hand first-order formula agrees
    assert fit.wind_mps == pytest.approx(wind, abs=1e-3)


def test_two_looks_without_a_prior_are_reported_degenerate():
    fit = fit_height(_looks(10e3, (0.0, 8.0), [500, 300]))
    assert not fit.ok
    assert math.isnan(fit.height_m)
    assert fit.reason.startswith("degenerate") and "wind prior" in fit.reason


def test_looks_from_one_angle_are_degenerate_even_with_many():
    # the feature stays at the same place relative to the nadir: tan(theta) constant,
    # so the parallax is one constant offset, indistinguishable from the position
    looks = [Look(float(t), 0.0, 11_500.0 + 5 * t, 0.0, -500e3 + 5 * t, H) for t in range(4)]
    fit = fit_height(looks)
    assert not fit.ok and "linearly" in fit.reason


def test_a_wrong_prior_biases_the_height_by_the_hand_amount():
    # a prior 2 m/s too slow along track (6 instead of 8): over dt = 28.3 s the drift
    # explains 2 dt = 56.6 m less of the forward motion, which is read as less fall of the
    # parallax: the height comes out 56.6 / 0.468 = 121 m low. The prior is soft (3 m/s),
    # but two looks say nothing about the along-track v, so the prior holds entirely.
    a, b = _looks(10e3, (0.0, 8.0), [500, 300])
    fit = fit_height([a, b], wind_prior=(0.0, 6.0))
    dt = b.t_s - a.t_s
    expected = 10e3 - 2.0 * dt / (_tan_hand(500e3) - _tan_hand(300e3))
    assert expected == pytest.approx(9879.0, abs=2.0)
    assert fit.height_m == pytest.approx(expected, abs=5.0)  # first order vs exact: 2 % of 121 m


@pytest.mark.slow
def test_noise_rmse_bias_and_reported_sigma():
    # 5 looks 500 -> 300 km ahead, 30 m position noise, a wind prior of +-3 m/s drawn
    # around the truth. Expected standard deviation, by hand: the prior dominates,
    # 3 m/s x 28.3 s / 0.468 = 181 m, the positions add ~ 30 / 0.468 / sqrt(5/2) = 41 m:
    # about 190 m. Bounds: RMSE <= 260 m, |bias| <= 3 x 190 / sqrt(300) = 33 m -> 40 m.
    rng = np.random.default_rng(7)
    errs, sigmas = [], []
    for _ in range(300):
        h = rng.uniform(2e3, 15e3)
        wind = (rng.uniform(-20, 20), rng.uniform(-20, 20))
        looks = _looks(h, wind, [500, 450, 400, 350, 300], rng=rng, cross=rng.uniform(-50e3, 50e3))
        prior = (wind[0] + rng.normal(0, 3.0), wind[1] + rng.normal(0, 3.0))
        fit = fit_height(looks, wind_prior=prior, wind_prior_sigma_mps=3.0)
        assert fit.ok
        errs.append(fit.height_m - h)
        sigmas.append(fit.height_sigma_m)
    errs_a = np.asarray(errs)
    rmse = float(np.sqrt(np.mean(errs_a**2)))
    assert 120.0 < rmse <= 260.0
    assert abs(float(errs_a.mean())) <= 40.0
    # the reported sigma is honest: within 25 % of the measured RMSE
    assert float(np.sqrt(np.mean(np.square(sigmas)))) == pytest.approx(rmse, rel=0.25)


def test_the_reported_sigma_does_not_depend_on_a_millimetre_of_position():
    # Looks moved by a millimetre are the same problem: the same sigma. Before, the
    # covariance used MINPACK's Jacobian, which steps an unknown by a fraction of its own
    # value: an unknown fitted at about zero (the cross-track position and drift here)
    # got a step of ~1e-17 m and a column of rounding noise, and the sigma came out
    # anywhere between 158 and 198 m for these five, and 170 or 190 m on two CPUs.
    sigmas = []
    for dx, dy in [(0.0, 0.0), (1e-3, 0.0), (0.0, 1e-3), (1e-3, -1e-3), (0.0, 0.0)]:
        looks = [
            Look(lk.t_s, lk.x_m + dx, lk.y_m + dy, lk.nadir_x_m, lk.nadir_y_m, H, 30.0)
            for lk in _looks(10e3, (0.0, 10.0), [500.0, 400.0, 300.0])
        ]
        fit = fit_height(looks, wind_prior=(0.0, 10.0))
        assert fit.ok and fit.height_m == pytest.approx(10e3, abs=1.0)
        sigmas.append(fit.height_sigma_m)
    assert max(sigmas) - min(sigmas) < 0.01 * min(sigmas) / 100  # within 0.01 %
    assert 150.0 < sigmas[0] < 250.0  # the scale of test_noise_rmse_bias_and_reported_sigma's


def test_cross_track_wind_is_measured_without_a_prior_on_it():
    # a plume 100 km right of the track: the parallax is nearly along track, the cross
    # drift (12 m/s) is read from the looks; the prior on it is loose (50 m/s)
    looks = _looks(6e3, (12.0, 5.0), [500, 400, 300], cross=0.0)
    fit = fit_height(looks, wind_prior=(0.0, 5.0), wind_prior_sigma_mps=50.0)
    assert fit.wind_mps[0] == pytest.approx(12.0, abs=0.05)


def test_rise_fit_on_a_column_rising_then_level():
    # 25 m/s from 1.5 km at t = 0 to 9 km (reached at 300 s), then flat; 100 m noise
    rng = np.random.default_rng(3)
    t = np.arange(0.0, 601.0, 30.0)
    h = np.minimum(1500.0 + 25.0 * t, 9000.0) + rng.normal(0, 100.0, t.size)
    f = fit_rise(t, h)
    assert f.levelled
    assert f.rise_mps == pytest.approx(25.0, rel=0.05)
    assert f.top_height_m == pytest.approx(9000.0, abs=80.0)
    assert f.reach_s == pytest.approx(300.0, abs=30.0)
    assert f.rise_sigma_mps < 2.0


def test_rise_fit_still_rising():
    t = np.arange(0.0, 121.0, 20.0)
    f = fit_rise(t, 2000.0 + 40.0 * t)
    assert not f.levelled
    assert f.rise_mps == pytest.approx(40.0, abs=1e-6)


def _textured(shape, seed=0):
    import cv2

    rng = np.random.default_rng(seed)
    base = cv2.GaussianBlur(rng.random(shape).astype(np.float32), (0, 0), 2.0)
    return np.repeat(base[None], 4, axis=0)


def test_disparity_with_a_guess_reaches_large_shifts():
    # the plume moved 61 px right and 2 px up; a guess of 58 px (from a prior height)
    a = _textured((160, 256))
    b = np.roll(a, (-2, 61), axis=(1, 2))
    m = np.zeros((160, 256), bool)
    m[40:120, 60:140] = True
    d, why = plume_disparity(a, b, m, guess_px=(58.0, 0.0))
    assert why == ""
    assert (d.dx_px, d.dy_px) == pytest.approx((61.0, -2.0), abs=0.3)
    assert d.quality > 0.8
    assert d.pixels == 72 * 72  # 80 x 80 eroded by 4 px on each side


def test_disparity_coarse_search_finds_a_shift_the_flow_alone_cannot():
    # 90 px right, 7 px down, no guess: the masked template search finds it within 120 px
    a = _textured((200, 320), seed=2)
    b = np.roll(a, (7, 90), axis=(1, 2))
    m = np.zeros((200, 320), bool)
    m[60:130, 40:120] = True
    d, why = plume_disparity(a, b, m, search_px=120)
    assert why == ""
    assert (d.dx_px, d.dy_px) == pytest.approx((90.0, 7.0), abs=0.3)


def test_disparity_refuses_thin_and_textureless_plumes():
    a = _textured((96, 96))
    thin = np.zeros((96, 96), bool)
    thin[40:46, :] = True  # 6 px wide: nothing left 4 px from both edges
    d, why = plume_disparity(a, a, thin)
    assert d is None and why.startswith("plume too small or thin: 0 px")
    flat = np.full((4, 96, 96), 0.5, np.float32)
    block = np.zeros((96, 96), bool)
    block[20:80, 20:80] = True
    d, why = plume_disparity(flat, flat, block)
    assert d is None and "texture" in why


def test_bad_looks_are_refused():
    with pytest.raises(InvalidParameterError):
        Look(0.0, math.nan, 0.0, 0.0, 0.0, H)
    with pytest.raises(InvalidParameterError):
        Look(0.0, 0.0, 0.0, 0.0, 0.0, H, sigma_m=0.0)
    with pytest.raises(InvalidParameterError):
        fit_height([Look(0.0, 0.0, 0.0, 0.0, -5e5, H)])
    with pytest.raises(InvalidParameterError):
        fit_rise([0, 1], [1, 2])


# -- the envelope (masked NCC of the masks) and a rising top ---------------------------------


def _disc(shape, cx, cy, r, ss=8):
    """A disc's area fraction per pixel (supersampled ss x ss): sub-pixel edges, by hand."""
    h, w = shape
    o = (np.arange(ss) + 0.5) / ss - 0.5
    yy = np.arange(h)[:, None, None, None] + o[None, None, :, None]
    xx = np.arange(w)[None, :, None, None] + o[None, None, None, :]
    return (((xx - cx) ** 2 + (yy - cy) ** 2) <= r * r).mean(axis=(2, 3))


@pytest.mark.parametrize(("dx", "dy"), [(0.3, 17.6), (-1.7, 24.25), (2.0, -5.5)])
def test_envelope_disparity_recovers_a_sub_pixel_shift(dx, dy):
    # a 4 px radius disc (about 50 px) moved by a known sub-pixel amount; the second frame
    # holds a second plume 20 px away that the search must not take; 0.15 px allowed
    a = _disc((64, 64), 20.0, 20.0, 4.0)
    b = _disc((64, 64), 20.0 + dx, 20.0 + dy, 4.0) + _disc((64, 64), 44.0, 40.0, 4.0)
    weight = np.zeros((64, 64), bool)
    weight[10:31, 10:31] = True
    d, why = envelope_disparity(a, b, weight=weight, guess_px=(0.0, dy - 2.6), search_px=(4, 6))
    assert why == "" and d.quality > 0.9
    assert abs(d.dx_px - dx) <= 0.15 and abs(d.dy_px - dy) <= 0.15


def test_envelope_disparity_refuses_what_it_cannot_measure():
    a = _disc((32, 32), 10.0, 10.0, 0.6)  # about 1 px: too small
    assert envelope_disparity(a, a)[1].startswith("plume too small")
    big = _disc((32, 32), 10.0, 10.0, 3.0)
    far = _disc((32, 32), 10.0, 22.0, 3.0)  # 12 px down, searched within 4 px
    why = envelope_disparity(big, far, search_px=(4, 4))[1]
    assert "edge" in why or "do not match" in why
    with pytest.raises(InvalidParameterError, match="shape"):
        envelope_disparity(big, big[:30])


def test_a_rising_top_is_fitted_with_its_rise():
    # a top at 6 km rising 40 m/s, still (a vent-attached envelope), seen 500, 400 and 300 km
    # ahead: positions from parallax.py's exact forward model with the height of each look's
    # time. A fit without the rise is biased low (the rise moves the top away from the
    # nadir while the approach moves it closer); with it, h(t0) and w come back.
    t = np.array([0.0, 100e3, 200e3]) / V_GROUND
    looks = []
    for ti in t:
        h = 6000.0 + 40.0 * ti
        d = 500e3 - V_GROUND * ti  # the feature's true distance ahead at ti
        s = float(parallax.parallax_shift(H, d, h))
        looks.append(Look(float(ti), 0.0, float(s), 0.0, float(-d), H, 10.0))
    flat = fit_height(looks, wind_prior=(0.0, 0.0), wind_prior_sigma_mps=1.0)
    rising = fit_height(looks, wind_prior=(0.0, 0.0), wind_prior_sigma_mps=1.0, rise=True)
    assert flat.ok and flat.height_m < 6000.0 - 500.0 and flat.rise_mps is None
    assert rising.ok and abs(rising.height_m - 6000.0) < 20.0
    assert abs(rising.rise_mps - 40.0) < 1.0 and rising.rms_residual_m < 1.0


@pytest.mark.parametrize("rise", [False, True])
def test_looks_no_height_below_100_km_explains_give_a_fit_that_is_not_ok(rise):
    # the feature appears to jump 150 km back and 100 km forth between looks 14 s apart:
    # the search walks past the 100 km the geometry accepts; the fit says so, never raises
    from dyntarget.predict.height import Look, fit_height

    v = 7062.0
    looks = [
        Look(0.0, 0.0, 500e3, 0.0, 0.0, 500e3, 30.0),
        Look(14.0, 0.0, 350e3, 0.0, 14 * v, 500e3, 30.0),
        Look(28.0, 0.0, 450e3, 0.0, 28 * v, 500e3, 30.0),
    ]
    fit = fit_height(looks, wind_prior=(0.0, 0.0), wind_prior_sigma_mps=1.0, rise=rise)
    assert not fit.ok and math.isnan(fit.height_m)
    assert fit.reason.startswith("the fit diverged")
