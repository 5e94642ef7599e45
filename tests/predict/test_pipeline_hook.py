"""The pipeline plans on the predicted plume; with agility, each pointing at its own time."""

from __future__ import annotations

import numpy as np
import pytest

from dyntarget.errors import InvalidParameterError
from dyntarget.pipeline import plan_scene, schedule_on_prediction
from dyntarget.predict import Motion, Prediction
from dyntarget.schedule import OrbitGeometry

LOLA = ("trace-outline", "track-center", "diagonal-transect", "lawnmower-transect")


def _scene(size=96):
    image = np.full((4, size, size), 0.1, np.float32)
    mask = np.zeros((size, size), bool)
    mask[30:50, 20:44] = True
    mask[40:56, 30:40] = True
    image[:, mask] = 0.8
    return image, mask


@pytest.mark.parametrize("planner", LOLA)
def test_detached_prediction_moves_the_plan_with_the_plume(planner):
    image, mask = _scene()
    # 0.5 px/s to the east, 0.25 px/s to the south, 40 s ahead: (20, 10) px, whole pixels
    pred = Prediction(Motion((0.5, 0.25), regime="detached"), 40.0)
    moved = plan_scene(image, None, planner, mask=mask, prediction=pred)
    shifted_mask = np.zeros_like(mask)
    shifted_mask[10:, 20:] = mask[:-10, :-20]  # the same plume, moved by hand
    expected = plan_scene(image, None, planner, mask=shifted_mask)
    assert np.array_equal(moved.predicted_mask, shifted_mask)
    np.testing.assert_allclose(moved.trajectory.points, expected.trajectory.points, atol=1e-9)
    assert "predict" in moved.timings and any(p.startswith("predict:") for p in moved.path)


def test_calm_prediction_changes_nothing():
    image, mask = _scene()
    still = plan_scene(image, None, "lawnmower-transect", mask=mask)
    calm = plan_scene(
        image, None, "lawnmower-transect", mask=mask,
        prediction=Prediction(Motion((0.0, 0.0), regime="calm"), 90.0),
    )  # fmt: skip
    np.testing.assert_array_equal(still.trajectory.points, calm.trajectory.points)


def test_prediction_respects_nodata():
    image, mask = _scene()
    valid = np.ones_like(mask)
    valid[:, 60:] = False
    pred = Prediction(Motion((1.0, 0.0)), 30.0)  # pushes the plume into the nodata strip
    res = plan_scene(image, None, "trace-outline", mask=mask, valid=valid, prediction=pred)
    assert not res.predicted_mask[:, 60:].any()
    assert (res.trajectory.points[:, 0] < 60).all()


def test_prediction_under_a_deadline_is_kept():
    image, mask = _scene()
    pred = Prediction(Motion((0.5, 0.0)), 20.0)
    res = plan_scene(image, None, "track-center", mask=mask, prediction=pred, deadline_s=30.0)
    assert res.prediction is pred and res.predicted_mask is not None


def test_each_pointing_is_placed_for_its_own_scheduled_time():
    image, mask = _scene()
    v = np.array([0.4, -0.2])
    lead = 60.0
    pred = Prediction(Motion(tuple(v), regime="detached"), lead)
    planned = plan_scene(image, None, "lawnmower-transect", mask=mask, prediction=pred).trajectory
    geometry = OrbitGeometry(wfov_gsd_m=30.0, look_ahead_m=800e3, start_s=lead)
    sched = schedule_on_prediction(planned, mask.shape, geometry, "slow", pred)
    assert len(sched.kept) >= 3
    times = sched.times
    assert times[-1] - times[0] > 5.0  # the pointings really are spread over time
    # every flown pointing = its planned place + v (t - lead), within the stated residual
    flown = sched.trajectory.points
    want = planned.points[sched.kept] + np.outer(times - lead, v)
    tol = sched.trajectory.params["prediction_residual_px"] + 1e-9
    assert np.max(np.hypot(*(flown - want).T)) <= tol
    assert sched.trajectory.params["prediction_residual_px"] < 0.05 * np.hypot(*v) + 1e-9


def test_attached_plume_pointings_are_not_moved():
    image, mask = _scene()
    pred = Prediction(Motion((0.4, 0.0), regime="attached"), 30.0)
    planned = plan_scene(image, None, "track-center", mask=mask, prediction=pred).trajectory
    sched = schedule_on_prediction(planned, mask.shape, OrbitGeometry(start_s=30.0), "fast", pred)
    np.testing.assert_array_equal(sched.trajectory.points, planned.points[sched.kept])


def test_bad_prediction_arguments():
    with pytest.raises(InvalidParameterError, match="lead_s"):
        Prediction(Motion((1.0, 0.0)), -1.0)
    with pytest.raises(InvalidParameterError, match="motion"):
        Prediction((1.0, 0.0), 1.0)  # type: ignore[arg-type]
