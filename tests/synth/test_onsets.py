"""Eruptions that start (and stop) during the pass: the world, its GEO images, ``synth``."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from dyntarget.errors import InvalidParameterError
from dyntarget.synth.dynamic import VentSpec, Wind, World, WorldSpec, sample_world, with_onsets
from dyntarget.synth.geoimager import GeoStream
from dyntarget.synth.strip import long_strip_spec, strip_spec


def _one_vent(**vent):
    # wind from the west at 10 m/s on 8 m pixels: 1.25 px/s towards +x (east)
    # no turbulence, little diffusion: a puff keeps about its 60 m (7.5 px) radius
    v = VentSpec(x=20.0, y=64.0, gustiness=0.0, meander=0.0, pulsation=0.0, turbulence=0.0,
                 diffusivity_m2s=1.0, **vent)  # fmt: skip
    return World(
        WorldSpec(seed=3, size=256, gsd=8.0, wind=Wind(10.0, 270.0), vents=(v,), clouds=())
    )


def _downwind_end(mask: np.ndarray) -> int:
    cols = np.flatnonzero(mask.any(axis=0))
    return int(cols.max()) if len(cols) else -1


def test_no_plume_before_the_onset_then_a_plume_growing_at_the_wind_speed():
    w = _one_vent(eruption_age_s=-100.0)  # onset at t = +100 s on the pass clock
    col = _one_vent(eruption_age_s=-100.0, top_height_m=9000.0, rise_mps=30.0)
    # the column: nothing before the onset, 30 m/s x 60 s = 1800 m a minute after it
    assert col.column_height(0, 50.0) == 0.0 and col.column_height(0, 160.0) == 1800.0
    for t in (0.0, 50.0, 99.0):
        mask, tau = w.truth(t)
        assert not mask.any() and float(tau.max()) == 0.0
    # 60 s and 120 s after the onset the head has travelled 10 m/s x 60 s = 600 m = 75 px
    # and 150 px from the vent (x = 20): its end within three puff radii (23 px) of that
    for age, travelled in ((60.0, 75.0), (120.0, 150.0)):
        end = _downwind_end(w.truth(100.0 + age)[0])
        assert 20 + travelled - 23 <= end <= 20 + travelled + 23, (age, end)


def test_an_eruption_that_stops_leaves_the_vent_and_its_plume_drifts_away():
    w = _one_vent(eruption_age_s=600.0, end_s=0.0, fade_s=3000.0)
    near_vent = (slice(54, 75), slice(15, 26))
    assert w.truth(0.0)[0][near_vent].any()  # still at the vent when it stops
    later = w.truth(100.0)[0]  # 100 s later the tail is 1000 m (125 px) downwind
    assert not later[near_vent].any()
    cols = np.flatnonzero(later.any(axis=0))
    assert cols.min() >= 20 + 125 - 15  # the plume's upwind end has left with the wind


def test_the_steady_world_keeps_its_spec_and_json_without_end_times():
    spec = sample_world(4, 0, size=64)
    assert with_onsets(spec, 0.0) is spec
    assert "end_s" not in spec.to_json()
    on = with_onsets(spec, 1.0, window_s=(-1800.0, 600.0), duration_s=(300.0, 600.0), seed=2)
    v = on.vents[0]
    assert -1800.0 <= -v.eruption_age_s <= 600.0
    assert 300.0 <= v.end_s + v.eruption_age_s <= 600.0  # duration after the onset
    assert WorldSpec.from_json(on.to_json()) == on
    # the other draws untouched: only the vents' ages and end times differ
    assert on.vents[0].x == spec.vents[0].x and on.clouds == spec.clouds


def test_onset_fields_are_validated_in_one_line():
    with pytest.raises(InvalidParameterError, match="end_s: 5.0 is not after the onset"):
        VentSpec(1.0, 1.0, eruption_age_s=-10.0, end_s=5.0)
    with pytest.raises(InvalidParameterError, match="eruption_age_s"):
        VentSpec(1.0, 1.0, eruption_age_s=-1e6)
    with pytest.raises(InvalidParameterError, match="onset fraction"):
        with_onsets(sample_world(0, 0, size=32), 1.5)
    with pytest.raises(InvalidParameterError, match="onset window"):
        with_onsets(sample_world(0, 0, size=32), 0.5, window_s=(10.0, -10.0))


def test_each_geo_image_shows_the_world_at_its_own_time():
    # one vent erupting at t = -900 s: the GEO image of -1200 s shows nothing of it, the
    # image of 0 s its 15-minute-old plume (a stale image misses a young plume)
    spec, window = strip_spec(0, width=64, length=512, plumes=1, wind_mps=8.0)
    spec = with_onsets(spec, 1.0, window_s=(-900.0, -899.0))
    s = GeoStream(spec, window, 1000.0, 0.0)
    bg = s.background()
    old = float(np.abs(s.image(-1200.0) - bg).max())
    new = float(np.abs(s.image(0.0) - bg).max())
    assert old < 1e-6 and new > 0.01  # (noise-free images: exactly the background before)


@pytest.mark.slow
def test_synth_strip_draws_onsets_and_refuses_bad_options(tmp_path):
    def synth(*args):
        return subprocess.run(
            [sys.executable, "-m", "dyntarget", "synth", "--quiet", *args],
            capture_output=True, text=True,
        )  # fmt: skip

    out = tmp_path / "s"
    r = synth("--strip", "--length-km", "20", "--plumes", "3", "--scenes", "1", "--seed", "1",
              "--onset-fraction", "1", "--onset-window-min=-30,10", "--flat",
              "--out", str(out))  # fmt: skip
    assert r.returncode == 0, r.stderr
    doc = json.loads((out / "strip-0001.world.json").read_text())
    onsets = [-v["eruption_age_s"] for v in doc["world"]["vents"]]
    assert len(onsets) == 3 and all(-1800.0 <= t <= 600.0 for t in onsets)
    spec, _ = long_strip_spec(1, 20.0, plumes=3)
    assert WorldSpec.from_dict(doc["world"]) == with_onsets(spec, 1.0, window_s=(-1800, 600))
    for bad, msg in (
        (["--onset-fraction", "0.5"], "onsets apply to strips"),
        (["--strip", "--onset-fraction", "2"], "expected a fraction"),
        (["--strip", "--onset-window-min", "0,5"], "give --onset-fraction too"),
        (["--strip", "--onset-fraction", "1", "--onset-window-min", "5,0"], "LO < HI"),
    ):
        r = synth(*bad, "--out", str(tmp_path / "bad"))
        assert r.returncode == 2 and msg in r.stderr and "Traceback" not in r.stderr
        assert len(r.stderr.strip().splitlines()) == 1
        assert not (tmp_path / "bad").exists()
