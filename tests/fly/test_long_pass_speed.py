"""What makes long passes fast keeps results as they were: cached windows, throttled progress."""

from __future__ import annotations

import time

import numpy as np
import pytest

from dyntarget.cli import fly as cli_fly
from dyntarget.schedule import (
    AGILITY,
    OrbitGeometry,
    _reach_compute,
    look_vectors,
    off_nadir_deg,
    schedule,
    visibility_windows,
)
from dyntarget.trajectory import Trajectory


@pytest.mark.parametrize("preset", ["fast", "slow"])
def test_cached_windows_equal_computed_ones_whatever_was_asked_before(preset):
    g, agility = OrbitGeometry(), AGILITY[preset]
    rng = np.random.default_rng(3)
    cross = rng.choice(np.linspace(-250e3, 250e3, 41), 300)
    along = rng.uniform(0.0, 900e3, 300)
    first = visibility_windows(g, agility, along, cross)
    # a different batch first (other distances, some shared): the same windows after it
    visibility_windows(g, agility, along[::-1][:50], cross[::-1][:50] + 1.0)
    again = visibility_windows(g, agility, along, cross)
    seen, ahead, behind = _reach_compute(g, agility, cross)  # no cache: the bisection itself
    v = g.ground_speed
    for t_in, t_out in (first, again):
        np.testing.assert_array_equal(t_in, np.where(seen, (along - ahead) / v, np.inf))
        np.testing.assert_array_equal(t_out, np.where(seen, (along - behind) / v, -np.inf))
    # and the geometry itself: at t_in a visible point is on the field of regard's edge
    ok = np.isfinite(first[0])
    angle = off_nadir_deg(look_vectors(g, along[ok], cross[ok], first[0][ok]))
    np.testing.assert_allclose(angle, agility.field_of_regard_deg, atol=1e-6)


def test_an_empty_plan_has_empty_windows_and_an_empty_schedule():
    t_in, t_out = visibility_windows(OrbitGeometry(), AGILITY["fast"], np.zeros(0), np.zeros(0))
    assert t_in.shape == t_out.shape == (0,)
    s = schedule(Trajectory.empty("none", {}), (64, 64), OrbitGeometry(), "fast")
    assert len(s.kept) == 0 and s.planned == 0


def _frames(monkeypatch, write_s: float, frames: int) -> list[int]:
    """Frames (1/8 s apart, on a fake clock) after which the progress files were rewritten."""
    clock = [0.0]
    monkeypatch.setattr(time, "monotonic", lambda: clock[0])
    wrote: list[int] = []

    def write(frame):
        wrote.append(frame)
        clock[0] += write_s

    progress = cli_fly._Progress(write)
    for frame in range(frames):
        progress(frame)
        clock[0] += 0.125
    return wrote


def test_quick_rewrites_are_done_every_frame_or_so(monkeypatch):
    # a rewrite of 1/256 s: the next waits 20/256 s, less than a frame
    assert _frames(monkeypatch, 1 / 256, 10) == list(range(10))


def test_slow_rewrites_wait_twenty_times_as_long_as_they_took(monkeypatch):
    # a rewrite of 1/16 s, after frame 0 at t = 0: the next may come at 20/16 = 1.25 s;
    # frame k > 0 comes at 1/16 + k/8 s, so frame 10 (1.3125 s) is the first; and so on
    # (each wait 1.25 s from the rewrite's start: frame 20 at 2.625 s >= 2.5625 s)
    assert _frames(monkeypatch, 1 / 16, 25) == [0, 10, 20]
