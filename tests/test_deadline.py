"""plan_scene under a deadline: always a plan, in time, and the path taken is reported."""

from __future__ import annotations

import time

import numpy as np
import pytest

from dyntarget import InvalidParameterError
from dyntarget.perceive import make_classifier
from dyntarget.pipeline import LAST_RESORT, estimate_classify_s, plan_scene


class SlowClassifier:
    """Takes ``seconds_per_pixel`` per pixel, like a heavy network; predicts a centre blob."""

    name = "slow-test"

    def __init__(self, seconds_per_pixel: float) -> None:
        self.spp = seconds_per_pixel

    def work_units(self, shape):
        return float(shape[0] * shape[1])

    def predict_proba(self, image):
        h, w = image.shape[1:]
        time.sleep(self.spp * h * w)
        p = np.zeros((h, w), np.float32)
        p[h // 4 : 3 * h // 4, w // 4 : 3 * w // 4] = 1.0
        return p


@pytest.fixture(scope="module")
def fast(tiny_scenes):
    return make_classifier("band-threshold").fit(tiny_scenes[:3])


def test_generous_deadline_takes_the_full_path(tiny_scenes, fast):
    image = tiny_scenes[3].image
    r = plan_scene(image, fast, "track-center", deadline_s=10.0)
    assert r.path == ["classify: band-threshold", "plan: track-center"] and r.deadline_met
    plain = plan_scene(image, fast, "track-center")
    np.testing.assert_array_equal(r.trajectory.points, plain.trajectory.points)


def test_estimate_extrapolates_from_a_probe():
    image = np.zeros((4, 256, 256), np.float32)
    slow = SlowClassifier(1e-7)  # 6.6 ms for 256 x 256
    estimate, probe = estimate_classify_s(slow, image)
    assert probe == pytest.approx(1e-7 * 128 * 128, rel=0.5, abs=0.01)
    assert estimate == pytest.approx(4 * probe)
    again, probe2 = estimate_classify_s(slow, image)  # remembered: no second probe
    assert probe2 == 0.0 and again == estimate


def test_slow_classifier_falls_back_to_the_cheaper_one(tiny_scenes, fast):
    image = np.repeat(np.repeat(tiny_scenes[3].image, 4, axis=1), 4, axis=2)  # 256 x 256
    slow = SlowClassifier(2e-5)  # 0.33 s for the 128 px probe, 1.3 s for the image
    r = plan_scene(image, slow, "track-center", deadline_s=0.8, fallback=fast)
    assert r.path[0].startswith("slow-test skipped: estimated")
    assert r.path[1:] == ["classify: band-threshold", "plan: track-center"]
    assert r.deadline_met and r.runtime <= 0.8


def test_hopeless_deadline_still_returns_the_last_resort_in_time(tiny_scenes):
    slow = SlowClassifier(1e-5)
    image = tiny_scenes[3].image
    estimate_classify_s(slow, image)  # calibrated at start-up: no probe under the deadline
    r = plan_scene(image, slow, "lawnmower-transect", deadline_s=0.03)
    assert r.path[0].startswith("slow-test skipped")
    assert r.path[-1] == f"plan: {LAST_RESORT}" and len(r.trajectory) > 0
    assert r.deadline_met
    r = plan_scene(image, slow, "lawnmower-transect", deadline_s=0.001)  # not even a probe
    assert r.path == ["classify: none (no classifier fits the deadline)", f"plan: {LAST_RESORT}"]


def test_bad_deadline(tiny_scenes, fast):
    with pytest.raises(InvalidParameterError, match="deadline_s"):
        plan_scene(tiny_scenes[3].image, fast, "track-center", deadline_s=0.0)
