from __future__ import annotations

import numpy as np
import pytest
from affine import Affine

from dyntarget import DynTargetError, InvalidParameterError, InvalidSceneError, Scene
from dyntarget.scene import block_mean


def test_scene_converts_to_float32_and_keeps_input():
    image = np.ones((4, 3, 5), np.float64)
    scene = Scene(image)
    assert scene.image.dtype == np.float32
    assert scene.shape == (3, 5)
    assert image.dtype == np.float64  # input not mutated
    assert scene.label is None and scene.gsd is None and not scene.georeferenced


@pytest.mark.parametrize("bands", [1, 3, 5])
def test_wrong_band_count(bands):
    with pytest.raises(InvalidSceneError, match=f"expected 4 bands.*got {bands} band"):
        Scene(np.zeros((bands, 4, 4), np.float32))


def test_wrong_ndim():
    with pytest.raises(InvalidSceneError, match="shape \\(4, H, W\\)"):
        Scene(np.zeros((4, 4), np.float32))


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite(bad):
    image = np.zeros((4, 4, 4), np.float32)
    image[2, 1, 1] = bad
    with pytest.raises(InvalidSceneError, match="1 value\\(s\\) are NaN or infinite"):
        Scene(image)


def test_integer_image_refused_with_hint():
    with pytest.raises(InvalidSceneError, match="scale integer digital numbers"):
        Scene(np.zeros((4, 4, 4), np.uint16))


def test_empty_image():
    with pytest.raises(InvalidSceneError, match="empty"):
        Scene(np.zeros((4, 0, 4), np.float32))


def test_label_shape_mismatch():
    with pytest.raises(InvalidSceneError, match="does not match"):
        Scene(np.zeros((4, 4, 4), np.float32), label=np.zeros((4, 5), bool))


def test_label_float_refused_and_int_accepted():
    with pytest.raises(InvalidSceneError, match="dtype float"):
        Scene(np.zeros((4, 2, 2), np.float32), label=np.zeros((2, 2), np.float32))
    s = Scene(np.zeros((4, 2, 2), np.float32), label=np.array([[0, 255], [1, 0]], np.uint8))
    assert s.label.tolist() == [[False, True], [True, False]]


@pytest.mark.parametrize("gsd", [0, -1, float("nan"), float("inf")])
def test_bad_gsd(gsd):
    with pytest.raises(InvalidParameterError, match="gsd"):
        Scene(np.zeros((4, 2, 2), np.float32), gsd=gsd)


def test_errors_share_one_root():
    assert issubclass(InvalidSceneError, DynTargetError) and issubclass(
        InvalidSceneError, ValueError
    )


def test_block_mean_by_hand():
    stack = np.arange(16, dtype=np.float32).reshape(1, 4, 4)
    np.testing.assert_array_equal(block_mean(stack, 2)[0], [[2.5, 4.5], [10.5, 12.5]])


def test_to_wfov_area_average_and_majority_label():
    image = np.zeros((4, 4, 6), np.float32)
    image[:, :2, :2] = 1.0
    image[:, 0, 2] = 1.0  # one of four pixels in block (0, 1)
    label = np.zeros((4, 6), bool)
    label[:2, :2] = True  # block (0,0): 4/4
    label[2:4, 2] = True  # block (1,1): 2/4 -> exactly one half -> plume
    label[0, 4] = True  # block (0,2): 1/4 -> not plume
    t = Affine(10.0, 0.0, 100.0, 0.0, -10.0, 500.0)
    s = Scene(image, label=label, gsd=10.0, crs="EPSG:32605", transform=t)
    w = s.to_wfov(2)
    assert w.shape == (2, 3)
    np.testing.assert_allclose(w.image[0], [[1.0, 0.25, 0.0], [0.0, 0.0, 0.0]])
    assert w.label.tolist() == [[True, False, False], [False, True, False]]
    assert w.gsd == 20.0
    assert w.transform == Affine(20.0, 0.0, 100.0, 0.0, -20.0, 500.0)
    assert w.crs == "EPSG:32605"
    # the WFOV pixel (1, 1) centre maps to the same ground point as the centre of its block
    assert w.transform @ (1.5, 1.5) == t @ (3.0, 3.0)


def test_to_wfov_drops_partial_blocks():
    s = Scene(np.ones((4, 7, 9), np.float32))
    assert s.to_wfov(2).shape == (3, 4)
    assert s.to_wfov(1) is s


@pytest.mark.parametrize("factor", [0, -2, 2.5, "2", True, 100])
def test_to_wfov_bad_factor(factor):
    s = Scene(np.ones((4, 8, 8), np.float32))
    with pytest.raises(InvalidParameterError, match="factor"):
        s.to_wfov(factor)


def test_crs_without_transform_refused():
    with pytest.raises(InvalidSceneError, match="without a transform"):
        Scene(np.ones((4, 2, 2), np.float32), crs="EPSG:4326")
