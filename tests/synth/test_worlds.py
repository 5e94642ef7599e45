"""What a pass reads of a world on its WFOV grid (issue 39: moved out of the loop into synth)."""

from __future__ import annotations

import numpy as np
import pytest

from dyntarget.errors import InvalidSceneError
from dyntarget.scene import Scene
from dyntarget.synth.worlds import StaticWorld, Truth, TruthBands, WorldBase, wfov_look
from dyntarget.utility import UtilityMaps


def _world(valid=None):
    img = np.zeros((4, 8, 8), np.float32)
    img[:, :2, :2] = [[1.0, 3.0], [5.0, 7.0]]  # WFOV pixel (0, 0) at factor 2: mean 4.0
    lab = np.zeros((8, 8), bool)
    lab[2, 0:2] = True  # WFOV (1, 0): 2 of 4 pixels plume -> exactly LABEL_FRACTION: plume
    lab[2, 2] = True  # WFOV (1, 1): 1 of 4 -> not plume
    return StaticWorld(Scene(img, label=lab, gsd=8.0, valid=valid))


def test_a_look_is_the_block_mean_and_the_oracle_mask_is_half_plume():
    image, valid, mask = wfov_look(_world(), 0.0, 0, 2, 2, 4, oracle=True)
    assert image.shape == (4, 2, 4) and image.dtype == np.float32
    assert image[:, 0, 0].tolist() == [4.0, 4.0, 4.0, 4.0]  # (1 + 3 + 5 + 7) / 4
    assert valid is None
    assert mask.tolist() == [[False, False, False, False], [True, False, False, False]]


def test_a_look_without_the_oracle_has_no_mask_and_a_nodata_pixel_spoils_its_block():
    valid = np.ones((8, 8), bool)
    valid[3, 5] = False  # under WFOV (1, 2)
    _, v, mask = wfov_look(_world(valid), 0.0, 0, 2, 2, 4, oracle=False)
    assert mask is None
    assert v.tolist() == [[True] * 4, [True, True, False, True]]


def test_a_look_of_rows_further_up_starts_at_its_top():
    image, _, mask = wfov_look(_world(), 0.0, 1, 2, 2, 4, oracle=True)
    assert image[:, 0, 0].tolist() == [0.0] * 4  # WFOV row 1: no bright block
    assert mask[0].tolist() == [True, False, False, False]  # WFOV row 1 is now the first


def test_a_world_returning_a_wrong_shape_is_refused_in_one_line():
    class Short(StaticWorld):
        def image_at(self, t, top, bottom):
            return np.zeros((4, bottom - top - 1, 8), np.float32)

    w = Short(Scene(np.zeros((4, 8, 8), np.float32), label=np.zeros((8, 8), bool), gsd=8.0))
    with pytest.raises(InvalidSceneError, match=r"frame 3 image has shape \(4, 3, 8\)"):
        wfov_look(w, 0.0, 0, 2, 2, 4, oracle=False, what="frame 3")


def test_the_rows_of_a_whole_truth_are_its_rows():
    rows = _world().truth_rows(0.0, 2, 4)
    assert rows.maps.label.shape == (2, 8) and rows.ids.shape == (2, 8)
    assert rows.maps.label[0].tolist() == [True, True, True] + [False] * 5
    assert rows.maps.label[1].tolist() == [False] * 8
    assert sorted(np.unique(rows.ids).tolist()) == [0, 1]  # one plume (8-connected)


class _Tower(WorldBase):
    """A world with one plume at WFOV (2, 2) (factor 1) whose top rises 10 m a second."""

    shape, gsd, crs, transform, valid, id = (5, 5), 100.0, None, None, None, "tower"
    is_3d = True

    def __init__(self) -> None:
        lab = np.zeros((5, 5), bool)
        lab[2, 2] = True
        z = np.zeros((5, 5), np.float32)
        self._truth = Truth(UtilityMaps(lab, z, z), lab.astype(np.int32))

    def truth_at(self, t):
        return self._truth

    def heights_at(self, t):
        return np.array([0.0, 1000.0 + 10.0 * t])


def test_the_true_top_under_the_nadir_is_the_plume_s_at_the_look_or_at_the_pointing_s_time():
    bands = TruthBands(_Tower(), 1, 1)
    pts = np.array([[2.0, 2.0], [0.0, 0.0]])  # (x, y): the plume, then bare ground
    kw = {"nadir": (2.0, 2.0), "altitude_m": 500e3, "gsd_m": 100.0}
    # seen straight down, the top is where the plume is; 5 s later it is 50 m higher
    later = bands.true_heights(pts, np.array([5.0, 5.0]), 0.0, 0, **kw)
    assert later[0] == 1050.0 and np.isnan(later[1])
    at_look = bands.true_heights(pts, np.array([5.0, 5.0]), 0.0, 0, look=True, **kw)
    assert at_look[0] == 1000.0 and np.isnan(at_look[1])


def test_a_flat_world_has_no_true_top_anywhere():
    bands = TruthBands(_world(), 2, 1)
    h = bands.true_heights(
        np.zeros((2, 2)), np.zeros(2), 0.0, 0, nadir=(0.0, 0.0), altitude_m=5e5, gsd_m=16.0
    )
    assert np.isnan(h).all()
