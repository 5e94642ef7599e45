"""Scoring pointings as lines of sight in a 3D world (:class:`dyntarget.observe.Sight`).

Where a line of sight meets a plume top comes from plain 3D vector algebra here (a ray
from the spacecraft through the ground point crosses the sphere ``R + h``), not from
:mod:`dyntarget.parallax`, which the module uses.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from dyntarget.errors import InvalidParameterError
from dyntarget.observe import Sight, score_pointings

R = 6_371_008.7714  # WGS 84 mean radius (2a + b) / 3
ALT = 500e3
G = 250.0  # metres per WFOV pixel
SHAPE = (200, 41)
PLUME = (150, 20)  # (row, col) of the 10 km plume's true ground position
NADIR = (20.0, 150.0 + 500e3 / G)  # 500 km behind it


def _sc() -> np.ndarray:
    return np.array([0.0, 0.0, R + ALT])


def _point(along: float, cross: float, radius: float) -> np.ndarray:
    """The point ``radius`` from the centre above (along, cross) of the nadir's map."""
    d, phi = math.hypot(along, cross), math.atan2(cross, along)
    g = d / R
    return radius * np.array(
        [math.sin(g) * math.cos(phi), math.sin(g) * math.sin(phi), math.cos(g)]
    )


def _ray_to(s: np.ndarray, through: np.ndarray, radius: float) -> np.ndarray:
    """First point where the ray from ``s`` through ``through`` meets the sphere ``radius``."""
    u = (through - s) / np.linalg.norm(through - s)
    b, c = float(s @ u), float(s @ s) - radius**2
    return s + (-b - math.sqrt(b * b - c)) * u


def _map(p: np.ndarray) -> tuple[float, float]:
    """(along, cross) of the foot of ``p`` on the nadir's map (arc distance, azimuth)."""
    arc = R * math.atan2(math.hypot(p[0], p[1]), p[2])
    phi = math.atan2(p[1], p[0])
    return arc * math.cos(phi), arc * math.sin(phi)


def _px(nadir: tuple[float, float], along: float, cross: float) -> tuple[float, float]:
    """(x, y) WFOV px of a map position."""
    return nadir[0] + cross / G, nadir[1] - along / G


def _seen_at(nadir: tuple[float, float], row: int, col: int, h: float) -> tuple[float, float]:
    """(x, y) where a feature ``h`` above the pixel (row, col) appears on the ground."""
    along, cross = (nadir[1] - row) * G, (col - nadir[0]) * G
    hit = _ray_to(_sc(), _point(along, cross, R + h), R)
    return _px(nadir, *_map(hit))


def _crossing(nadir: tuple[float, float], x: float, y: float, h: float) -> tuple[float, float]:
    """(x, y) under where the line of sight to the ground point (x, y) crosses height ``h``."""
    along, cross = (nadir[1] - y) * G, (x - nadir[0]) * G
    hit = _ray_to(_sc(), _point(along, cross, R), R + h)
    return _px(nadir, *_map(hit))


def _maps(*plumes: tuple[int, int, int, float]) -> SimpleNamespace:
    """Footprint maps with plume ``pid`` of fraction ``v`` at (row, col)."""
    plume = np.zeros(SHAPE)
    ids = np.zeros(SHAPE, np.int64)
    for r, c, pid, v in plumes:
        plume[r, c], ids[r, c] = v, pid
    return SimpleNamespace(
        plume=plume,
        intensity=plume * 2,
        gradient=plume * 3,
        ids=ids,
        valid=np.ones(SHAPE, bool),
    )


def _sight(heights: list[float], nadir=lambda t: NADIR) -> Sight:
    return Sight(nadir, G, ALT, lambda t: np.array(heights))


def _round(v: float) -> int:
    assert abs(v - math.floor(v) - 0.5) > 0.05, f"{v} too near a pixel edge for this test"
    return math.floor(v + 0.5)


def test_a_10km_plume_is_seen_where_its_line_of_sight_meets_it():
    maps = _maps((*PLUME, 1, 0.8))
    x, y = _seen_at(NADIR, *PLUME, 10e3)
    # by hand: 500 km ahead from 500 km up, tan(theta) = 1.125 (48.37 deg): 10 km top
    # displaced 11.25 km to first order, 11.50 km with the curvature: 46.0 px of 250 m
    assert (x, 150 - y) == (pytest.approx(20.0), pytest.approx(11_501.4 / G, abs=0.01))
    pts = np.array([[x, y], [20.0, 150.0], [x, y + 2.0]])
    got = score_pointings(pts, [0.0] * 3, 0, SHAPE, lambda t, r: (maps, 0), sight=_sight([0, 10e3]))
    # aimed at the top: observed; at its ground position: the ground under it; 2 px off: nothing
    assert got.plume_id == [1, 0, 0]
    assert got.plume == [0.8, 0.0, 0.0] and got.intensity == [1.6, 0.0, 0.0]
    assert got.rows.tolist() == [104, 150, 106]  # the pixels aimed at, as without a sight
    # without a sight: today's numbers, the truth under the aim
    flat = score_pointings(pts, [0.0] * 3, 0, SHAPE, lambda t, r: (maps, 0))
    assert flat.plume_id == [0, 1, 0] and flat.plume == [0.0, 0.8, 0.0]
    again = score_pointings(pts, [0.0] * 3, 0, SHAPE, lambda t, r: (maps, 0), None)
    assert (again.plume, again.intensity, again.gradient, again.plume_id) == (
        flat.plume,
        flat.intensity,
        flat.gradient,
        flat.plume_id,
    )


def test_a_plume_across_track_is_seen_radially_displaced():
    nadir = (20.0 - 100e3 / G, NADIR[1])  # the plume 500 km ahead, 100 km to the right
    maps = _maps((*PLUME, 1, 0.5))
    x, y = _seen_at(nadir, *PLUME, 10e3)
    assert (x - 20.0) / (150.0 - y) == pytest.approx(100e3 / 500e3)  # away from the nadir
    top = 90  # a frame whose top row is 90 on the strip
    got = score_pointings(
        np.array([[x, y - top], [20.0, 150.0 - top]]),
        [0.0, 0.0],
        top,
        SHAPE,
        lambda t, r: (maps, 0),
        sight=_sight([0, 10e3], lambda t: nadir),
    )
    assert got.plume_id == [1, 0] and got.plume == [0.5, 0.0]


def test_the_highest_layer_met_is_observed():
    x, y = 20.0, 104.0  # the aimed ground point
    # where its line of sight crosses 10 km and 5 km (vectors): there the two plumes lie
    x10, y10 = _crossing(NADIR, x, y, 10e3)
    x5, y5 = _crossing(NADIR, x, y, 5e3)
    hi = (_round(y10), _round(x10))
    lo = (_round(y5), _round(x5))
    assert hi == PLUME and lo[0] == 127  # 5 km: 23.2 px back towards the nadir
    pts, t = np.array([[x, y]]), [0.0]
    both = _maps((*hi, 1, 0.9), (*lo, 2, 0.4))
    got = score_pointings(pts, t, 0, SHAPE, lambda *_: (both, 0), sight=_sight([0, 10e3, 5e3]))
    assert got.plume_id == [1] and got.plume == [0.9]
    lower = _maps((*lo, 2, 0.4))  # the 10 km plume elsewhere: the 5 km one is met
    got = score_pointings(pts, t, 0, SHAPE, lambda *_: (lower, 0), sight=_sight([0, 10e3, 5e3]))
    assert got.plume_id == [2] and got.plume == [0.4]
    # heights swapped: neither plume lies where the line crosses its height; the ground is clear
    got = score_pointings(pts, t, 0, SHAPE, lambda *_: (both, 0), sight=_sight([0, 5e3, 10e3]))
    assert got.plume_id == [0] and got.plume == [0.0]


def test_a_ground_plume_is_observed_where_it_lies_and_each_pointing_at_its_own_time():
    # plume 1 on the ground at 0 km, plume 2 raised 10 km at PLUME
    ground = (60, 10)
    maps = _maps((*ground, 1, 0.3), (*PLUME, 2, 0.7))

    def nadir(t: float) -> tuple[float, float]:  # 10 km/s: 100 km nearer after 10 s
        return (NADIR[0], NADIR[1] - 40.0 * t)

    x0, y0 = _seen_at(nadir(0.0), *PLUME, 10e3)
    x1, y1 = _seen_at(nadir(10.0), *PLUME, 10e3)
    # by hand, 400 km ahead: tan(theta) = 0.886, 10 km x 0.886 plus ~2 % = 9.05 km: 36.2 px
    assert 150 - y1 == pytest.approx(36.2, abs=0.1)
    pts = np.array([[10.0, 60.0], [x0, y0], [x0, y0], [x1, y1]])
    got = score_pointings(
        pts, [0.0, 0.0, 10.0, 10.0], 0, SHAPE, lambda t, r: (maps, 0), _sight([0, 0, 10e3], nadir)
    )
    assert got.plume_id == [1, 2, 0, 2] and got.plume == [0.3, 0.7, 0.0, 0.7]


def test_a_long_strip_band_holding_the_crossing_is_asked_for():
    band = 64
    full = _maps((*PLUME, 1, 0.6))
    asked = []

    def truth_at(t: float, r: int):
        asked.append(r // band)
        first = (r // band) * band
        return SimpleNamespace(
            **{k: getattr(full, k)[first : first + band] for k in vars(full)}
        ), first

    x, y = _seen_at(NADIR, *PLUME, 10e3)
    got = score_pointings(np.array([[x, y]]), [0.0], 0, SHAPE, truth_at, sight=_sight([0, 10e3]))
    assert got.plume_id == [1] and got.plume == [0.6]
    assert asked == [150 // band]  # the band of the crossing (row 150), not of the aim (104)


def test_off_the_strip_or_on_nodata_nothing_is_observed():
    maps = _maps((*PLUME, 1, 0.6))
    x, y = _seen_at(NADIR, *PLUME, 10e3)
    maps.valid[PLUME] = False
    pts = np.array([[x, y], [-3.0, 5.0]])
    got = score_pointings(pts, [0.0, 0.0], 0, SHAPE, lambda *_: (maps, 0), sight=_sight([0, 10e3]))
    assert got.plume_id == [0, 0] and got.inside.tolist() == [True, False]


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"gsd_m": 0.0}, "sight gsd_m: expected metres > 0"),
        ({"altitude_m": float("nan")}, "sight altitude_m: expected metres > 0"),
        ({"altitude_m": 1e9}, "sight altitude_m: expected at most"),
        ({"heights": 3.0}, "sight heights: expected a callable"),
    ],
)
def test_a_bad_sight_is_refused_with_one_line(kwargs, message):
    args = {"nadir": lambda t: NADIR, "gsd_m": G, "altitude_m": ALT, "heights": lambda t: [0.0]}
    with pytest.raises(InvalidParameterError, match=message):
        Sight(**{**args, **kwargs})


@pytest.mark.parametrize(
    ("nadir", "heights", "message"),
    [
        (lambda t: (float("nan"), 0.0), [0.0, 1e3], "sight nadir at t=0 s: not finite"),
        (lambda t: NADIR, [0.0, float("nan")], "sight heights at t=0 s: expected a 1-D"),
        (lambda t: NADIR, [0.0, -5.0], "sight heights at t=0 s: expected a 1-D"),
        (lambda t: NADIR, [0.0], "sight heights at t=0 s: 1 values, but the truth has plume id 1"),
    ],
)
def test_bad_nadirs_and_heights_are_refused(nadir, heights, message):
    maps = _maps((*PLUME, 1, 0.6))
    sight = Sight(nadir, G, ALT, lambda t: np.array(heights))
    with pytest.raises(InvalidParameterError, match=message):
        score_pointings(np.array([[20.0, 150.0]]), [0.0], 0, SHAPE, lambda *_: (maps, 0), sight)
