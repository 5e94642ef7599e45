"""Property-based tests (Hypothesis) of denoise, the planners and the metrics."""

from __future__ import annotations

import cv2
import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from dyntarget.denoise import close, denoise
from dyntarget.evaluate.metrics import Confusion
from dyntarget.plan import PlanConfig, geometric_planners, plan

masks = st.integers(4, 40).flatmap(
    lambda h: st.integers(4, 40).flatmap(lambda w: arrays(np.bool_, (h, w), elements=st.booleans()))
)
blobby = masks.map(lambda m: cv2.dilate(m.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0)
iterations = st.integers(0, 3)
areas = st.integers(0, 40)


@given(masks, iterations, areas)
def test_denoise_within_closing(mask, it, area):
    out = denoise(mask, iterations=it, min_area=area).mask
    closed = close(mask.astype(np.uint8), it) > 0 if it else mask
    assert not (out & ~closed).any()


@given(masks, iterations, areas)
def test_denoise_idempotent(mask, it, area):
    once = denoise(mask, iterations=it, min_area=area).mask
    twice = denoise(once, iterations=it, min_area=area).mask
    np.testing.assert_array_equal(once, twice)


@given(masks, iterations, areas, areas)
def test_area_filter_monotone(mask, it, a, b):
    lo, hi = sorted((a, b))
    assert not (
        denoise(mask, iterations=it, min_area=hi).mask
        & ~denoise(mask, iterations=it, min_area=lo).mask
    ).any()


@given(masks, iterations, areas)
def test_kept_components_large_enough_and_polygons_valid(mask, it, area):
    r = denoise(mask, iterations=it, min_area=area)
    _, _, stats, _ = cv2.connectedComponentsWithStats(r.mask.astype(np.uint8), connectivity=8)
    assert (stats[1:, cv2.CC_STAT_AREA] >= area).all()
    assert all(p.is_valid and not p.is_empty for p in r.polygons)
    assert (len(r.polygons) == 0) == (not r.mask.any())


@settings(max_examples=40)
@given(blobby, st.sampled_from(geometric_planners()), st.floats(0.5, 5.0))
def test_planners_inside_finite_deterministic(mask, name, step):
    cleaned = denoise(mask, iterations=1, min_area=1)
    config = PlanConfig(step=step)
    t = plan(name, cleaned.mask, cleaned.polygons, config)
    h, w = mask.shape
    assert np.isfinite(t.points).all()
    if len(t):
        assert t.points[:, 0].min() >= 0 and t.points[:, 0].max() <= w - 1
        assert t.points[:, 1].min() >= 0 and t.points[:, 1].max() <= h - 1
    again = plan(name, cleaned.mask, cleaned.polygons, config)
    np.testing.assert_array_equal(t.points, again.points)
    np.testing.assert_array_equal(t.part, again.part)


counts = st.integers(0, 10_000)


@given(counts, counts, counts, counts)
def test_metrics_bounded_and_symmetric(tp, fp, fn, tn):
    c = Confusion(tp, fp, fn, tn)
    m = c.metrics()
    assert all(0.0 <= v <= 1.0 for v in m.values())
    assert c.swapped().swapped() == c
    assert m["accuracy"] == c.swapped().metrics()["accuracy"]
    assert m["iou"] <= min(m["precision"], m["recall"]) + 1e-12
    assert m["iou_background"] == c.swapped().metrics()["iou"]


@given(masks)
def test_metrics_of_identical_masks_are_perfect(mask):
    m = Confusion.from_masks(mask, mask).metrics()
    assert m["accuracy"] == m["precision"] == m["recall"] == m["iou"] == 1.0
