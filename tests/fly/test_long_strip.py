"""Pass-length strips: spread vents, rendered lazily, flown frame by frame."""

from __future__ import annotations

import json

import numpy as np
import pytest

from dyntarget.cli import main
from dyntarget.errors import InvalidParameterError
from dyntarget.fly import PassConfig, fly_pass
from dyntarget.synth.dynamic import World
from dyntarget.synth.strip import long_strip_spec
from dyntarget.synth.strip_world import LongStrip, load_world


def test_vents_follow_the_density_one_per_segment():
    spec, window = long_strip_spec(3, 1000.0, plumes_per_100km=0.2)
    assert window == (0, 0, 256, 125_000)  # 1000 km at 8 m
    assert len(spec.vents) == 2  # 0.2 per 100 km over 1000 km
    seg = 125_000 / 2
    for k, v in enumerate(spec.vents):  # 30-70 % into its own segment, 25-75 % across
        assert seg * (k + 0.3) <= v.y <= seg * (k + 0.7)
        assert 64 <= v.x <= 192
    assert len(long_strip_spec(3, 1000.0, plumes=7)[0].vents) == 7


@pytest.mark.parametrize(
    "kw", [{"length_km": 5.0}, {"length_km": 20.0, "plumes": 0}, {"length_km": 9e9}]
)
def test_bad_strips_are_refused(kw):
    with pytest.raises(InvalidParameterError):
        long_strip_spec(0, **kw)


def test_rows_render_as_the_whole_window_does():
    spec, window = long_strip_spec(1, 40.0, plumes=2, wind_mps=6.0)
    strip = LongStrip(spec, window, truth_step_s=0.0)
    v = spec.vents[0]
    top = int(v.y) - 100
    whole = World(spec).render(12.0, (0, top - 50, 256, 400))  # a larger window, other origin
    truth = strip.truth_rows(12.0, top, top + 200)
    assert truth.maps.label.shape == (200, 256)
    assert np.array_equal(truth.maps.label, whole.mask[50:250])
    assert truth.maps.label.any()
    # every plume pixel near vent 1 has its id (1); intensity = label x red reflectance
    assert set(np.unique(truth.ids[truth.maps.label])) == {1}
    red = whole.image[2, 50:250]
    assert np.allclose(truth.maps.intensity, truth.maps.label * red)


@pytest.mark.slow
def test_a_long_strip_flies_and_counts_its_vents(tmp_path):
    out = tmp_path / "s"
    assert main(["synth", "--strip", "--length-km", "20", "--plumes", "2", "--scenes", "1",
                 "--flat", "--out", str(out), "--quiet"]) == 0  # fmt: skip
    doc = json.loads((out / "strip-0000.world.json").read_text())
    assert doc["version"] == 2 and doc["window"] == [0, 0, 256, 2500]
    world = load_world(out / "strip-0000.tif")
    assert isinstance(world, LongStrip) and world.shape == (2500, 256)
    r = fly_pass(world, None, PassConfig(agility="unlimited", compute_budget_s=0.05))
    t = r.totals()
    # 2500 rows / 4 = 625 WFOV rows, 64-row frames every 32: (625 - 64) // 32 + 1 = 18
    assert t["frames"] == 18 and t["plumes_total"] == 2
    assert t["plumes_observed"] == 2


def test_synth_length_km_bad_value_exits_2(tmp_path, capsys):
    code = main(["synth", "--strip", "--length-km", "5", "--out", str(tmp_path / "x"), "--quiet"])
    assert code == 2
    assert "--length-km: expected km in 10..10000, got '5'" in capsys.readouterr().err
