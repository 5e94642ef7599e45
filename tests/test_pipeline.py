"""The one Algorithm-1 path: segment -> plan_segmentation (-> schedule_plan) is plan_scene."""

from __future__ import annotations

import numpy as np
import pytest

from dyntarget import InvalidParameterError
from dyntarget.pipeline import (
    Kinematics,
    PipelineConfig,
    plan_scene,
    plan_segmentation,
    segment,
)
from dyntarget.plan import PLANNERS, geometric_planners, plan
from dyntarget.schedule import OrbitGeometry


def _scene():
    """A 64 px image with a 20 x 40 px plume, a 1-px speck, and a nodata column band."""
    image = np.full((4, 64, 64), 0.1, np.float32)
    mask = np.zeros((64, 64), bool)
    mask[20:40, 10:50] = True
    mask[5, 5] = True
    valid = np.ones((64, 64), bool)
    valid[:, 40:] = False
    return image, mask, valid


def test_segment_thresholds_keeps_valid_pixels_and_denoises():
    image, mask, valid = _scene()
    proba = np.where(mask, 0.5, 0.49).astype(np.float32)  # exactly at the threshold is plume
    seg = segment(image, probability=proba, valid=valid)
    # raw: plume pixels in valid columns (20 rows x 30 cols) plus the speck; denoised: no speck
    assert int(seg.raw_mask.sum()) == 20 * 30 + 1
    assert int(seg.mask.sum()) == 20 * 30 and len(seg.polygons) == 1
    higher = segment(image, probability=proba, valid=valid, config=PipelineConfig(threshold=0.6))
    assert not higher.raw_mask.any()


def test_plan_segmentation_matches_plan_scene_for_every_geometric_planner():
    image, mask, valid = _scene()
    seg = segment(image, mask=mask, valid=valid)
    for name in geometric_planners():
        a = plan_segmentation(seg, name)
        b = plan_scene(image, None, name, mask=mask, valid=valid).trajectory
        np.testing.assert_array_equal(a.points, b.points)
        cols = np.floor(a.points[:, 0] + 0.5).astype(int)
        assert (cols < 40).all()  # never a pointing on nodata


@pytest.mark.slow
def test_utility_max_is_a_registered_planner_that_needs_the_kinematics():
    image, mask, _ = _scene()
    assert "utility-max" in PLANNERS and "utility-max" not in geometric_planners()
    with pytest.raises(InvalidParameterError, match="give --agility"):
        plan("utility-max", mask)
    kin = Kinematics(OrbitGeometry(wfov_gsd_m=30.0), "fast", objective="plume")
    result = plan_scene(image, None, "utility-max", mask=mask, kinematics=kin)
    pts = result.trajectory.points
    assert len(pts) > 0
    # objective "plume" on a given mask: every pointing is on the plume
    assert mask[np.round(pts[:, 1]).astype(int), np.round(pts[:, 0]).astype(int)].all()
    # planned under the kinematics: flown as planned, nothing dropped
    assert len(result.schedule.kept) == len(result.trajectory)
