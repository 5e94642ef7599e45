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


def test_progress_files_are_rewritten_at_most_once_a_second(monkeypatch):
    clock = [100.0]
    monkeypatch.setattr(time, "monotonic", lambda: clock[0])
    wrote = []
    progress = cli_fly._Progress(wrote.append)
    for frame in range(24):  # 24 frames 1/8 s apart: 3 s
        progress(frame)
        clock[0] += 0.125
    assert wrote == [0, 8, 16]  # the first frame, then once a second


def test_a_slow_rewrite_is_done_less_often(monkeypatch):
    clock = [0.0]
    monkeypatch.setattr(time, "monotonic", lambda: clock[0])

    def write(frame):  # each rewrite takes 0.5 s: next one 5 s later (at most 10 % of the time)
        wrote.append(frame)
        clock[0] += 0.5

    wrote: list[int] = []
    progress = cli_fly._Progress(write)
    for frame in range(100):
        progress(frame)
        clock[0] += 0.125
    # frame 0 at t = 0 (done at 0.5 s); frame k > 0 comes at 0.5 + k / 8 s: frame 36 at 5 s,
    # its rewrite ends at 5.5 s, and frame 72 comes at 10 s
    assert wrote == [0, 36, 72]
