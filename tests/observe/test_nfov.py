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
