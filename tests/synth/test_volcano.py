from __future__ import annotations

import numpy as np
import pytest

from dyntarget import InvalidParameterError
from dyntarget.synth import fractal_noise, generate_scene, generate_scenes, sample_params
from dyntarget.synth.volcano import plume_coordinates


def test_same_seed_same_scene_different_seed_differs():
    a, pa = generate_scene(3, 5, size=64)
    b, pb = generate_scene(3, 5, size=64)
    c, _ = generate_scene(4, 5, size=64)
    assert pa == pb
    np.testing.assert_array_equal(a.image, b.image)
    np.testing.assert_array_equal(a.label, b.label)
    assert not np.array_equal(a.image, c.image)


def test_scene_i_independent_of_set_size():
    first = [s for s, _ in generate_scenes(3, size=32, seed=1)]
    alone, _ = generate_scene(1, 2, size=32)
    np.testing.assert_array_equal(first[2].image, alone.image)


def test_image_and_label_conventions(tiny_scene):
    assert tiny_scene.image.shape == (4, 64, 64) and tiny_scene.image.dtype == np.float32
    assert 0.0 <= tiny_scene.image.min() and tiny_scene.image.max() <= 1.0
    assert tiny_scene.label.dtype == bool
    assert tiny_scene.georeferenced and tiny_scene.gsd == 8.0


def test_parameter_ranges_documented():
    rng = np.random.default_rng(0)
    draws = [sample_params(rng, size=512, gsd=8.0) for _ in range(400)]
    ws = np.array([p.wind_speed for p in draws])
    assert ws.min() >= 2.0 and ws.max() <= 15.0
    assert all(0.0 <= p.water_fraction <= 0.3 for p in draws)
    assert all(0.25 <= p.label_optical_depth <= 0.5 for p in draws)
    assert all(102 <= p.vent_x <= 410 and 102 <= p.vent_y <= 410 for p in draws)
    assert all(0.05 <= p.spread <= 0.4 for p in draws)
    curved = np.mean([p.curvature != 0 for p in draws])
    cloudy = np.mean([p.cloud_cover > 0 for p in draws])
    assert 0.25 < curved < 0.45  # ~35 % curved plumes
    assert 0.6 < cloudy < 0.8  # ~70 % with cumulus


def test_every_scene_has_a_plume_of_reasonable_size():
    fractions = [s.label.mean() for s, _ in generate_scenes(12, size=128, seed=0)]
    assert min(fractions) > 0.005 and max(fractions) < 0.5


def test_plume_brighter_and_label_is_thresholded_optical_depth():
    from dyntarget.synth.volcano import render

    rng = np.random.default_rng(7)
    p = sample_params(rng, size=128, gsd=8.0)
    image, label, tau = render(p, rng)
    np.testing.assert_array_equal(label, tau > p.label_optical_depth)
    # thick plume is brighter in blue than the clear surface on average
    clear = tau < 0.05
    assert image[2][tau > 1.5].mean() > image[2][clear].mean()


def test_straight_plume_coordinates_by_hand():
    p = sample_params(np.random.default_rng(0), size=100, gsd=1.0)
    from dataclasses import replace

    p = replace(p, vent_x=10.0, vent_y=20.0, wind_direction=0.0, curvature=0.0)
    s, d = plume_coordinates(p, np.array([13.0]), np.array([24.0]))
    assert s[0] == pytest.approx(3.0) and d[0] == pytest.approx(4.0)


def test_curved_plume_coordinates_follow_the_arc():
    from dataclasses import replace

    p = replace(
        sample_params(np.random.default_rng(0), size=100, gsd=1.0),
        vent_x=0.0,
        vent_y=0.0,
        wind_direction=0.0,
        curvature=0.01,
    )  # radius 100, turning +y
    # a point a quarter circle along the arc (centre at (0, 100)) lies at (100, 100)
    s, d = plume_coordinates(p, np.array([100.0]), np.array([100.0]))
    assert s[0] == pytest.approx(100 * np.pi / 2) and d[0] == pytest.approx(0.0, abs=1e-9)


def test_fractal_noise_normalised_and_anisotropic():
    rng = np.random.default_rng(0)
    f = fractal_noise(rng, (128, 128), beta=2.4, stretch=6.0, angle=0.0)
    assert abs(f.mean()) < 1e-5 and f.std() == pytest.approx(1.0, abs=1e-5)
    # stretched along x: neighbours along x are more alike than along y
    dx = np.abs(np.diff(f, axis=1)).mean()
    dy = np.abs(np.diff(f, axis=0)).mean()
    assert dx < dy


@pytest.mark.parametrize(
    ("kw", "match"), [({"size": 0}, "size"), ({"size": 8}, "size"), ({"gsd": -1.0}, "gsd")]
)
def test_bad_parameters(kw, match):
    with pytest.raises(InvalidParameterError, match=match):
        generate_scene(0, 0, **kw)


def test_bad_scene_count():
    with pytest.raises(InvalidParameterError, match="scenes"):
        list(generate_scenes(0))
