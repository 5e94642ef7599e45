from __future__ import annotations

import numpy as np
import pytest

from dyntarget import InvalidParameterError, InvalidSceneError
from dyntarget.denoise import denoise
from dyntarget.masks import mask_to_polygons


def _mask(rows: list[str]) -> np.ndarray:
    return np.array([[c == "#" for c in r] for r in rows])


def test_two_blobs_merge_and_speck_dropped_by_hand():
    m = _mask(
        [
            "..........",
            ".###.###..",
            ".###.###..",
            ".###.###..",
            "..........",
            "..........",
            "........#.",
        ]
    )
    r = denoise(m, iterations=1, min_area=4)
    expected = _mask(
        [
            "..........",
            ".#######..",
            ".#######..",
            ".#######..",
            "..........",
            "..........",
            "..........",
        ]
    )
    np.testing.assert_array_equal(r.mask, expected)
    assert len(r.polygons) == 1


def test_without_merging_blobs_stay_separate():
    m = _mask([".###.###.", ".###.###.", ".###.###."])
    r = denoise(m, iterations=0, min_area=1)
    np.testing.assert_array_equal(r.mask, m)
    assert len(r.polygons) == 2


def test_gap_too_wide_to_close_stays_two_plumes():
    m = np.zeros((10, 20), bool)
    m[2:8, 2:7] = True
    m[2:8, 12:17] = True  # 5 px apart: needs 3 iterations to bridge
    assert len(denoise(m, iterations=2, min_area=1).polygons) == 2
    assert len(denoise(m, iterations=3, min_area=1).polygons) == 1


def test_area_filter_threshold_inclusive():
    m = np.zeros((10, 10), bool)
    m[1:3, 1:3] = True  # 4 px
    m[6:9, 6:9] = True  # 9 px
    np.testing.assert_array_equal(
        denoise(m, iterations=0, min_area=9).mask, m & (np.arange(10)[:, None] > 4)
    )
    assert denoise(m, iterations=0, min_area=4).mask.sum() == 13
    assert denoise(m, iterations=0, min_area_fraction=0.05).mask.sum() == 9  # 5 px of 100


def test_hole_kept_and_polygon_has_interior():
    m = np.ones((9, 9), bool)
    m[3:6, 3:6] = False  # 3x3 hole: a closing of 1 iteration fills only 1-2 px gaps
    r = denoise(m, iterations=1, min_area=1)
    np.testing.assert_array_equal(r.mask, m)
    (poly,) = r.polygons
    assert len(poly.interiors) == 1
    assert not poly.contains(poly.interiors[0].centroid)


def test_empty_mask():
    r = denoise(np.zeros((5, 5), bool))
    assert not r.mask.any() and r.polygons == []


def test_full_mask():
    r = denoise(np.ones((6, 7), bool), iterations=3, min_area=1)
    assert r.mask.all()
    (poly,) = r.polygons
    assert poly.bounds == (0.0, 0.0, 6.0, 5.0)


def test_single_pixel():
    m = np.zeros((5, 5), bool)
    m[2, 3] = True
    r = denoise(m, iterations=1, min_area=1)
    np.testing.assert_array_equal(r.mask, m)
    (poly,) = r.polygons
    assert poly.area == pytest.approx(1.0) and poly.contains(poly.centroid)
    assert poly.centroid.coords[0] == pytest.approx((3.0, 2.0))


def test_line_of_pixels_is_a_valid_polygon():
    m = np.zeros((5, 8), bool)
    m[2, 1:6] = True
    (poly,) = mask_to_polygons(m)
    assert poly.is_valid and poly.area == pytest.approx(5.0)


def test_blob_near_border_not_glued_to_it():
    m = np.zeros((8, 8), bool)
    m[1:4, 1:4] = True
    np.testing.assert_array_equal(denoise(m, iterations=2, min_area=1).mask, m)


def test_one_pixel_wide_ring_keeps_its_polygon():
    """Found by the denoise sweep: outer and hole contours coincide, so the polygon had no area."""
    m = np.zeros((9, 9), bool)
    m[2, 2:7] = m[6, 2:7] = m[2:7, 2] = m[2:7, 6] = True  # a hollow 5x5 square, one pixel wide
    r = denoise(m, iterations=0, min_area=1)
    (poly,) = r.polygons
    assert poly.area == pytest.approx(16.0) and poly.is_valid
    assert not poly.contains(poly.centroid)  # still hollow


@pytest.mark.slow
def test_one_pixel_ring_with_thick_corner_pieces():
    rng = np.random.default_rng(5)
    for _ in range(50):
        m = rng.uniform(size=(20, 20)) > 0.55
        for p in mask_to_polygons(m):
            assert not p.is_empty and p.area > 0


def test_plume_touching_border_not_eroded():
    m = np.zeros((8, 8), bool)
    m[:, :3] = True  # along the left border
    r = denoise(m, iterations=2, min_area=1)
    np.testing.assert_array_equal(r.mask, m)


def test_output_within_closing_and_input_untouched():
    rng = np.random.default_rng(0)
    m = rng.uniform(size=(40, 40)) > 0.7
    before = m.copy()
    import cv2

    padded = np.pad(m, 3).astype(np.uint8)
    closed = (
        cv2.morphologyEx(padded, cv2.MORPH_CLOSE, np.ones((3, 3), np.uint8), iterations=2)[
            3:-3, 3:-3
        ]
        > 0
    )
    r = denoise(m, iterations=2, min_area=10)
    assert not (r.mask & ~closed).any()
    np.testing.assert_array_equal(m, before)


def test_integer_mask_accepted():
    assert denoise(np.eye(4, dtype=np.uint8), iterations=1, min_area=1).mask.any()


@pytest.mark.parametrize(
    ("kw", "match"),
    [
        ({"iterations": -1}, "iterations"),
        ({"iterations": 1.5}, "iterations"),
        ({"min_area": -3}, "min_area"),
        ({"min_area_fraction": 2.0}, "min_area_fraction"),
    ],
)
def test_bad_parameters(kw, match):
    with pytest.raises(InvalidParameterError, match=match):
        denoise(np.zeros((4, 4), bool), **kw)


@pytest.mark.parametrize(
    "bad", [np.zeros((2, 2, 2), bool), np.zeros((0, 3), bool), np.zeros((3, 3), np.float32)]
)
def test_bad_masks(bad):
    with pytest.raises(InvalidSceneError, match="mask"):
        denoise(bad)


def test_min_area_fraction_bounds_inclusive():
    m = np.zeros((10, 10), bool)
    m[1:4, 1:4] = True
    m[8, 8] = True  # a one-pixel speck
    # 0: nothing is too small, the speck stays; 1: only a plume filling the image stays
    np.testing.assert_array_equal(denoise(m, iterations=0, min_area_fraction=0.0).mask, m)
    assert not denoise(m, iterations=0, min_area_fraction=1.0).mask.any()
    assert denoise(np.ones((4, 5), bool), iterations=0, min_area_fraction=1.0).mask.all()


def test_polygon_with_two_holes_keeps_both():
    m = np.ones((7, 11), bool)
    m[3, 3] = m[3, 7] = False  # two one-pixel holes
    (poly,) = mask_to_polygons(m)
    assert len(poly.interiors) == 2
    # by hand: the pixel-centre rectangle 10 x 6 less two diamonds of area 2 (the holes'
    # rings run through the centres of their four 4-neighbours)
    assert poly.area == pytest.approx(60 - 2 * 2)


@pytest.mark.parametrize("holed_on_top", [True, False])
def test_blob_with_a_hole_and_a_plain_blob_both_kept(holed_on_top):
    m = np.zeros((20, 10), bool)
    holed, plain = (slice(1, 8), slice(11, 15)) if holed_on_top else (slice(11, 18), slice(1, 5))
    m[holed, 1:8] = True
    m[holed.start + 3, 4] = False
    m[plain, 2:6] = True
    polys = mask_to_polygons(m)
    # by hand: 6 x 6 less the hole's diamond (2); the plain 4 x 4 block: 3 x 3
    assert [p.area for p in polys] == [pytest.approx(34.0), pytest.approx(9.0)]
    assert [len(p.interiors) for p in polys] == [1, 0]


def test_polygons_largest_first():
    m = np.zeros((20, 20), bool)
    m[1:3, 1:3] = True  # 2 x 2: unit squares, area 4
    m[5:9, 10:14] = True  # 4 x 4: pixel-centre square, area 9
    m[12:18, 2:8] = True  # 6 x 6: area 25
    assert [p.area for p in mask_to_polygons(m)] == [25.0, 9.0, 4.0]


def test_thin_rule_at_half_the_pixels_by_hand():
    # a 3 x 4 block: its pixel-centre rectangle (2 x 3 = 6) covers exactly half its 12 pixels,
    # not less, so it is kept; a 3 x 3 block's (2 x 2 = 4) covers less than half of 9, so the
    # block is described by its pixels' unit squares (area 9)
    m = np.zeros((10, 10), bool)
    m[1:4, 1:5] = True
    (poly,) = mask_to_polygons(m)
    assert poly.area == 6.0 and poly.bounds == (1.0, 1.0, 4.0, 3.0)
    m = np.zeros((10, 10), bool)
    m[1:4, 1:4] = True
    (poly,) = mask_to_polygons(m)
    assert poly.area == 9.0 and poly.bounds == (0.5, 0.5, 3.5, 3.5)


def _body_neck_lobe(w, h, lobe_h, lobe_w, lobe_top):
    """A w x h block, a 3 px neck out of its right side (row h // 2), a lobe at the neck's end."""
    m = np.zeros((h + 8, w + 12), bool)
    m[2 : 2 + h, 2 : 2 + w] = True
    r = 2 + h // 2
    m[r, 2 + w : 5 + w] = True
    m[r - lobe_top : r - lobe_top + lobe_h, 5 + w : 5 + w + lobe_w] = True
    return m


@pytest.mark.parametrize(
    ("shape", "areas"),
    [
        # the body's pixel-centre rectangle, plus the triangle of area 1 where the neck leaves
        # it; the neck has no area (out and back); the lobe: its pixel-centre rectangle plus the
        # triangle where the neck arrives (0.5 at a 2 x 2 lobe's corner, 1 at a 3 x 2 lobe's side)
        ((5, 8, 2, 2, 0), [4 * 7 + 1, 1 + 0.5]),  # lobe >= 1 px (> 1 % of 29): kept
        ((14, 24, 3, 2, 1), [13 * 23 + 1, 2 + 1]),  # lobe = 1 % of 300 exactly: kept
        ((14, 24, 2, 2, 0), [13 * 23 + 1]),  # lobe 1.5 < 1 % of 300: a sliver, dropped
    ],
)
def test_neck_lobes_kept_and_slivers_dropped_by_hand(shape, areas):
    assert [p.area for p in mask_to_polygons(_body_neck_lobe(*shape))] == areas


def test_check_mask_by_hand():
    from dyntarget.masks import check_mask

    np.testing.assert_array_equal(
        check_mask(np.array([[0, 2], [1, 0]])), [[False, True], [True, False]]
    )
    assert check_mask(np.ones((1, 5), np.uint8)).shape == (1, 5)  # one row, one column: fine
    assert check_mask(np.ones((5, 1), bool)).shape == (5, 1)
    with pytest.raises(InvalidSceneError, match=r"^mask: expected a non-empty 2-D mask"):
        check_mask(np.zeros((0, 3), bool))
    with pytest.raises(InvalidSceneError, match=r"^truth: expected a boolean"):
        check_mask(np.zeros((3, 3), np.float32), name="truth")
