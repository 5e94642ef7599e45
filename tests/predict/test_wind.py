"""Wind prior: meteorological convention to pixels, and the check of two looks against it."""

from __future__ import annotations

import math

import pytest
from affine import Affine

from dyntarget.errors import InvalidParameterError
from dyntarget.predict import Motion, check_against_prior, wind_motion, wind_to_pixels


@pytest.mark.parametrize(
    ("from_deg", "expected"),
    [
        (0.0, (0.0, 2.0)),  # from the north: blows south, down the rows of a north-up image
        (90.0, (-2.0, 0.0)),  # from the east: blows west, to smaller columns
        (180.0, (0.0, -2.0)),  # from the south: up the rows
        (270.0, (2.0, 0.0)),  # from the west: to larger columns
        (225.0, (math.sqrt(2), -math.sqrt(2))),  # from the south-west: to the north-east
    ],
)
def test_meteorological_direction_to_pixels_north_up(from_deg, expected):
    assert wind_to_pixels(10.0, from_deg, gsd_m=5.0) == pytest.approx(expected, abs=1e-9)
    north_up = Affine(5.0, 0.0, 500_000.0, 0.0, -5.0, 4_000_000.0)
    assert wind_to_pixels(10.0, from_deg, transform=north_up) == pytest.approx(expected, abs=1e-9)


def test_rotated_grid_uses_the_transform():
    # a grid whose columns run north (rotated 90 degrees): col -> +north, row -> +east, 4 m
    rotated = Affine(0.0, 4.0, 0.0, 4.0, 0.0, 0.0)
    # from the south at 8 m/s: 8 m/s northward = 2 columns per second, no rows
    assert wind_to_pixels(8.0, 180.0, transform=rotated) == pytest.approx((2.0, 0.0), abs=1e-9)


@pytest.mark.parametrize(
    ("kwargs", "text"),
    [
        ({"speed_mps": -1.0, "from_deg": 0.0, "gsd_m": 1.0}, "wind_mps"),
        ({"speed_mps": float("nan"), "from_deg": 0.0, "gsd_m": 1.0}, "wind_mps"),
        ({"speed_mps": 5.0, "from_deg": float("inf"), "gsd_m": 1.0}, "wind_from_deg"),
        ({"speed_mps": 5.0, "from_deg": 0.0}, "georeference"),
        ({"speed_mps": 5.0, "from_deg": 0.0, "gsd_m": 0.0}, "gsd_m"),
        ({"speed_mps": 5.0, "from_deg": 0.0, "transform": Affine(0, 0, 0, 0, 0, 0)}, "transform"),
    ],
)
def test_bad_wind_inputs(kwargs, text):
    with pytest.raises(InvalidParameterError, match=text):
        wind_to_pixels(**kwargs)


def test_calm_wind_prior_is_calm():
    m = wind_motion(0.0, 123.0, gsd_m=10.0)
    assert m.regime == "calm" and m.displacement(100.0) == (0.0, 0.0)


def test_two_looks_checked_against_the_prior():
    prior = Motion((1.0, 0.0), source="wind-prior")
    agree = check_against_prior(Motion((1.2, 0.1), source="two-looks", confidence=0.9), prior)
    assert agree.velocity == (1.2, 0.1) and "agrees" in agree.notes[-1]
    clash = check_against_prior(Motion((0.0, -1.0), source="two-looks", confidence=0.9), prior)
    assert clash.velocity == (0.0, -1.0) and "DISAGREES" in clash.notes[-1]
    weak = check_against_prior(Motion((5.0, 5.0), source="two-looks", confidence=0.1), prior)
    assert weak.velocity == (1.0, 0.0) and "wind prior used" in weak.notes[-1]
