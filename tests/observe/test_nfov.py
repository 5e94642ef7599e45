from __future__ import annotations

import numpy as np
import pytest

from dyntarget import InvalidParameterError, InvalidSceneError, Scene
from dyntarget.observe import UtilityMaps, observe, observed_pixels
from dyntarget.plan import Trajectory


def scene_8x8():
    image = np.full((4, 8, 8), 0.1, np.float32)
    image[2, :4, :4] = 0.5  # blue brighter in the top-left block
    label = np.zeros((8, 8), bool)
    label[:4, :4] = True  # plume = top-left 4x4 block = WFOV pixel (0, 0) at factor 4
    label[4:6, 4:8] = True  # half of WFOV pixel (1, 1)
    return Scene(image, label=label)


def traj(*pts):
    return Trajectory(np.array(pts, float), np.zeros(len(pts), np.int64), "test")


def test_intensity_normalised_label_over_blue():
    maps = UtilityMaps.from_scene(scene_8x8())
    assert maps.intensity.max() == pytest.approx(1.0)
    assert maps.intensity[0, 0] == pytest.approx(1.0) and maps.intensity[5, 5] == pytest.approx(0.2)
    assert maps.intensity[7, 0] == 0.0
    assert maps.gradient.max() == pytest.approx(1.0) and maps.gradient.min() >= 0.0


def test_observe_by_hand():
    s = scene_8x8()
    m = observe(traj((0, 0), (1, 1), (1.2, 0.9), (0, 1)), s, factor=4)
    assert m.pixels_observed == 3  # (1, 1) and (1.2, 0.9) are the same WFOV pixel: counted once
    assert m.ratio_plume == pytest.approx((1.0 + 0.5 + 0.0) / 3)
    assert m.intensity == pytest.approx((1.0 + 0.5 * 0.2 + 0.0) / 3)


def test_outside_points_dropped_and_empty_scores_zero():
    s = scene_8x8()
    assert observe(traj((-3, 0), (9, 9)), s, factor=4).pixels_observed == 0
    assert observe(Trajectory.empty("x"), s, factor=4).as_dict() == {
        "pixels_observed": 0,
        "ratio_plume": 0.0,
        "intensity": 0.0,
        "gradient": 0.0,
    }


def test_footprint_averages_neighbours():
    s = scene_8x8()
    one = observe(traj((0, 0)), s, factor=4, footprint=1)
    three = observe(traj((0, 0)), s, factor=4, footprint=3)
    # the 3x3 footprint at the corner covers the 4 WFOV pixels that exist: (1 + 0 + 0 + 0.5) / 4
    assert one.ratio_plume == 1.0 and three.ratio_plume == pytest.approx(1.5 / 4)


def test_observed_pixels_order_and_rounding():
    # 1.5 rounds half up to column 2; (0.0, 0.49) is pixel (0, 0) again; first-visit order kept
    rc = observed_pixels(traj((0.4, 0.4), (1.5, 0.0), (0.0, 0.49)), (2, 3))
    assert rc.tolist() == [[0, 0], [0, 2]]
    assert observed_pixels(traj((1.5, 0.0)), (2, 2)).tolist() == []


def test_bad_inputs():
    s = scene_8x8()
    with pytest.raises(InvalidParameterError, match="footprint"):
        observe(traj((0, 0)), s, factor=4, footprint=2)
    with pytest.raises(InvalidParameterError, match="factor"):
        observe(traj((0, 0)), s, factor=0)
    with pytest.raises(InvalidSceneError, match="no label"):
        observe(traj((0, 0)), Scene(s.image), factor=4)


def _impulse_scene(size=17, at=(8, 8)):
    """A one-pixel plume of blue reflectance 0.5 on a dark background (intensity: an impulse)."""
    image = np.full((4, size, size), 0.1, np.float32)
    image[2][at] = 0.5
    label = np.zeros((size, size), bool)
    label[at] = True
    return Scene(image, label=label)


# The paper's gradient: Sobel with a 5x5 kernel. OpenCV's 5x5 Sobel x-kernel is the outer
# product of the smoothing row s = [1, 4, 6, 4, 1] (across) and the derivative row
# d = [-1, -2, 0, 2, 1] (along x); the y-kernel is its transpose. On a unit impulse the
# response at offset (dr, dc) is the (flipped) kernel entry, so by hand, with
# s(0)=6, s(1)=4, s(2)=1 and |d|(0)=0, |d|(1)=2, |d|(2)=1:
#   |G(dr, dc)| = hypot(s(dr) * d(dc), d(dr) * s(dc))
#   (0,0)=0  (0,1)=12  (0,2)=6  (1,1)=8*sqrt(2)  (1,2)=(2,1)=sqrt(20)  (2,2)=sqrt(2)
# normalised by the peak 12. (A 3x3 Sobel gives (0,2)=0 and (1,1)/(0,1)=sqrt(2)/2 instead.)
_SOBEL5_BY_HAND = (
    np.array(
        [
            [2**0.5, 20**0.5, 6.0, 20**0.5, 2**0.5],
            [20**0.5, 8 * 2**0.5, 12.0, 8 * 2**0.5, 20**0.5],
            [6.0, 12.0, 0.0, 12.0, 6.0],
            [20**0.5, 8 * 2**0.5, 12.0, 8 * 2**0.5, 20**0.5],
            [2**0.5, 20**0.5, 6.0, 20**0.5, 2**0.5],
        ]
    )
    / 12.0
)


def test_gradient_is_the_5x5_sobel_by_hand():
    maps = UtilityMaps.from_scene(_impulse_scene())
    np.testing.assert_allclose(maps.gradient[6:11, 6:11], _SOBEL5_BY_HAND, atol=1e-6)
    outside = np.ones((17, 17), bool)
    outside[6:11, 6:11] = False
    assert not maps.gradient[outside].any()  # a 5x5 kernel reaches exactly 2 pixels out


def test_observed_gradient_and_intensity_of_impulse_by_hand():
    s = _impulse_scene()
    # pointings (x, y): the impulse itself, one and two columns right, one diagonal, far away
    m = observe(traj((8, 8), (9, 8), (10, 8), (9, 9), (14, 14)), s, factor=1)
    assert m.pixels_observed == 5
    assert m.ratio_plume == pytest.approx(1 / 5)
    assert m.intensity == pytest.approx(1 / 5)
    assert m.gradient == pytest.approx((0.0 + 1.0 + 0.5 + 8 * 2**0.5 / 12 + 0.0) / 5)


def test_gradient_averaged_over_the_wfov_footprint_by_hand():
    # factor 2: WFOV pixel (row 4, col 4) covers high-res rows/cols 8..9, holding the impulse at
    # (8, 8) and its neighbours (8, 9), (9, 8), (9, 9): gradients 0, 1, 1, 8*sqrt(2)/12
    s = _impulse_scene(size=18)
    m = observe(traj((4, 4)), s, factor=2)
    assert m.ratio_plume == pytest.approx(1 / 4)
    assert m.gradient == pytest.approx((0 + 1 + 1 + 8 * 2**0.5 / 12) / 4)


def test_unlabelled_plume_free_scene_scores_zero_not_nan():
    s = Scene(np.full((4, 8, 8), 0.3, np.float32), label=np.zeros((8, 8), bool))
    maps = UtilityMaps.from_scene(s)
    assert not maps.intensity.any() and not maps.gradient.any()  # 0 / 0 would give NaN
    m = observe(traj((0, 0), (1, 1)), s, factor=4)
    assert m.as_dict() == {
        "pixels_observed": 2,
        "ratio_plume": 0.0,
        "intensity": 0.0,
        "gradient": 0.0,
    }


def test_nodata_is_never_observed():
    s = scene_8x8()
    valid = np.ones((8, 8), bool)
    valid[0, 3] = False  # one nodata high-res pixel spoils WFOV pixel (0, 0) at factor 4
    s = Scene(s.image, label=s.label, valid=valid)
    m = observe(traj((0, 0), (1, 1), (0, 1)), s, factor=4)
    # only (1, 1) and (0, 1) are observed: plume fractions 0.5 and 0
    assert m.pixels_observed == 2 and m.ratio_plume == pytest.approx(0.25)
    assert UtilityMaps.from_scene(s).valid is not None


def test_footprint_three_in_the_interior_by_hand():
    # 12 x 12 high-res, factor 4: a 3 x 3 WFOV grid; plume fractions per WFOV pixel by hand
    label = np.zeros((12, 12), bool)
    label[0:4, 0:4] = True  # WFOV (0, 0): 1
    label[4:6, 4:8] = True  # WFOV (1, 1): 0.5
    label[8:12, 8:9] = True  # WFOV (2, 2): 0.25
    s = Scene(np.full((4, 12, 12), 0.2, np.float32), label=label)
    m = observe(traj((1, 1)), s, factor=4, footprint=3)
    assert m.ratio_plume == pytest.approx((1 + 0.5 + 0.25) / 9)  # all 9 WFOV pixels exist
    edge = observe(traj((2, 1)), s, factor=4, footprint=3)  # right column: 6 pixels exist
    assert edge.ratio_plume == pytest.approx((0.5 + 0.25) / 6)
    with pytest.raises(InvalidParameterError, match="footprint"):
        observe(traj((1, 1)), s, factor=4, footprint=True)


def test_observed_pixels_round_half_up_and_drop_outside():
    # -0.5 rounds to 0 (inside); -0.51 to -1 (outside); 2.49 to 2; 2.5 to 3 (outside a 3 x 3 grid)
    pts = traj((-0.5, 0), (-0.51, 0), (2.49, 2.49), (2.5, 0), (0, 2.5), (1, 1))
    assert observed_pixels(pts, (3, 3)).tolist() == [[0, 0], [2, 2], [1, 1]]
    assert observed_pixels(Trajectory.empty("x"), (3, 3)).shape == (0, 2)


def test_precomputed_maps_score_like_the_scene_and_footprint_validated():
    s = scene_8x8()
    t = traj((0, 0), (1, 1))
    assert observe(t, UtilityMaps.from_scene(s), factor=4) == observe(t, s, factor=4)
    for bad in (-1, 3.0, True):
        with pytest.raises(InvalidParameterError, match="footprint"):
            observe(t, s, factor=4, footprint=bad)


def test_observed_pixels_distinct_on_a_tall_grid():
    # on a 4 x 2 grid, pixel (row 0, col 1) and (row 2, col 0) are different pixels
    rc = observed_pixels(traj((1, 0), (0, 2), (1, 0)), (4, 2))
    assert rc.tolist() == [[0, 1], [2, 0]] and rc.dtype == np.int64
    assert observed_pixels(Trajectory.empty("x"), (3, 3)).dtype == np.int64


def test_gradient_normalised_even_when_faint_and_maps_float32():
    # a plume filling the image with blue rising gently left to right: the raw 5x5 Sobel
    # response is small (the ramp is 0.001 per pixel), yet the map is still scaled to peak 1
    image = np.full((4, 16, 16), 0.1, np.float32)
    image[2] = 0.5 + 0.001 * np.arange(16, dtype=np.float32)[None, :]
    maps = UtilityMaps.from_scene(Scene(image, label=np.ones((16, 16), bool)))
    assert maps.gradient.max() == pytest.approx(1.0)
    assert maps.intensity.dtype == np.float32 and maps.gradient.dtype == np.float32
