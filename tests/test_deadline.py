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


class FakeClock:
    """``time.perf_counter`` stand-in that only moves when a classifier 'works'."""

    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


class ClockedClassifier(SlowClassifier):
    """Advances a fake clock by ``seconds_per_pixel`` per pixel instead of sleeping."""

    def __init__(self, seconds_per_pixel: float, clock: FakeClock) -> None:
        super().__init__(seconds_per_pixel)
        self.clock = clock

    def predict_proba(self, image):
        h, w = image.shape[1:]
        self.clock.now += self.spp * h * w
        return np.zeros((h, w), np.float32)


def test_estimate_extrapolates_from_a_probe(monkeypatch):
    # A fake clock makes the probe's duration exact, so machine load cannot move it.
    clock = FakeClock()
    monkeypatch.setattr(time, "perf_counter", clock)
    image = np.zeros((4, 256, 256), np.float32)
    slow = ClockedClassifier(1e-7, clock)
    estimate, probe = estimate_classify_s(slow, image)
    # The probe classifies a 128 x 128 crop: 1e-7 s/px x 16384 px = 1.6384 ms, by hand;
    # the 256 x 256 image has 4x the pixels, so 6.5536 ms.
    assert probe == pytest.approx(1.6384e-3, rel=1e-9)
    assert estimate == pytest.approx(6.5536e-3, rel=1e-9)
    again, probe2 = estimate_classify_s(slow, image)  # remembered: no second probe
    assert probe2 == 0.0 and again == estimate


@pytest.fixture
def clock(monkeypatch):
    """Deadline arithmetic on a fake ``time.perf_counter``: exact, whatever the machine's load."""
    fake = FakeClock()
    monkeypatch.setattr(time, "perf_counter", fake)
    return fake


def test_slow_classifier_falls_back_to_the_cheaper_one(tiny_scenes, clock):
    fast = make_classifier("band-threshold").fit(tiny_scenes[:3])  # costs 0 s on the fake clock
    image = np.repeat(np.repeat(tiny_scenes[3].image, 4, axis=1), 4, axis=2)  # 256 x 256
    slow = ClockedClassifier(2e-5, clock)
    r = plan_scene(image, slow, "track-center", deadline_s=0.8, fallback=fast)
    # By hand: the 128 x 128 probe takes 0.32768 s and predicts 4 x that = 1.31 s for the
    # image; 2 x 1.31 s (safety) is far over the 0.47 s left, so the fallback classifies.
    assert r.path[0] == "slow-test skipped: estimated 1.311 s, 0.472 s left"
    assert r.path[1:] == ["classify: band-threshold", "plan: track-center"]
    assert r.runtime == pytest.approx(0.32768) and r.deadline_met


def test_hopeless_deadline_still_returns_the_last_resort_in_time(tiny_scenes, clock):
    slow = ClockedClassifier(1e-5, clock)
    image = tiny_scenes[3].image
    estimate_classify_s(slow, image)  # calibrated at start-up: no probe under the deadline
    r = plan_scene(image, slow, "lawnmower-transect", deadline_s=0.03)
    # 64 x 64 px x 1e-5 s = 0.041 s estimated, over the 0.03 s deadline: the last resort.
    assert r.path[0].startswith("slow-test skipped: estimated 0.041 s")
    assert r.path[-1] == f"plan: {LAST_RESORT}" and len(r.trajectory) > 0
    assert r.deadline_met
    r = plan_scene(image, slow, "lawnmower-transect", deadline_s=0.001)  # not even a probe
    assert r.path == ["classify: none (no classifier fits the deadline)", f"plan: {LAST_RESORT}"]


def test_bad_deadline(tiny_scenes, fast):
    with pytest.raises(InvalidParameterError, match="deadline_s"):
        plan_scene(tiny_scenes[3].image, fast, "track-center", deadline_s=0.0)
