"""GEO foresight: detection, nowcast, the blueprint DP (against brute force), the gate, the CLI."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from dyntarget.cli import main
from dyntarget.errors import InvalidParameterError
from dyntarget.fly import PassConfig, fly_pass
from dyntarget.fly.geo import BlueprintGate, GeoSettings, image_times
from dyntarget.fly.strip import MovingStrip, strip_spec
from dyntarget.geo import Blueprint, Target, detect, nowcast, plan_blueprint
from dyntarget.geo.blueprint import pointing_s
from dyntarget.schedule import (
    OrbitGeometry,
    angle_between_deg,
    get_agility,
    look_vectors,
    visibility_windows,
)


def test_detect_against_a_background_by_hand():
    bg = np.array([[0.1, 0.2], [0.3, 0.1]])
    img = bg + np.array([[0.0, 0.05], [0.02, 0.5]])
    mask, anomaly = detect(img, 0.03, bg)
    assert mask.tolist() == [[False, True], [False, True]]
    assert anomaly[1, 1] == pytest.approx(0.5)


def test_nowcast_carries_a_blob_at_its_speed():
    y, x = np.mgrid[0:40, 0:80]

    def blob(cx, cy):
        return np.exp(-((x - cx) ** 2 + (y - cy) ** 2) / 10.0)

    # 3 px right and 1 px down per 600 s: after 1200 s more, at (30 + 6, 20 + 2)
    fields = [blob(24, 18), blob(27, 19), blob(30, 20)]
    out, v = nowcast(fields, 600.0, [0.0, 1200.0])
    assert np.unravel_index(np.argmax(out[0]), out[0].shape) == (20, 30)
    assert np.unravel_index(np.argmax(out[1]), out[1].shape) == (22, 36)
    assert v[0, 20, 30] == pytest.approx(3 / 600, rel=0.1)


def test_image_times_and_latency():
    # images every 600 s at multiples of it; usable from t + latency
    assert image_times(GeoSettings(latency_s=0), 0.0) == [-1200.0, -600.0, 0.0]
    assert image_times(GeoSettings(latency_s=650), 0.0) == [-2400.0, -1800.0, -1200.0]
    assert image_times(GeoSettings(latency_s=900, history_s=1000), 0.0) == []


@pytest.mark.parametrize(
    "kw", [{"latency_s": -1.0}, {"cadence_s": 0.0}, {"gsd_m": float("nan")}, {"reserve": 0.95}]
)
def test_bad_geo_settings(kw):
    with pytest.raises(InvalidParameterError):
        GeoSettings(**kw)
    with pytest.raises(InvalidParameterError, match="not coarser"):
        GeoSettings(gsd_m=30.0).check_against(32.0)


def _brute_force(targets, geometry, agility, horizon, reserve):
    """Every subset, in along-track order, with every pointing count: the best value."""
    ts = sorted(targets, key=lambda t: t.along_m)
    c = pointing_s(agility, geometry)
    slot = c / (1 - reserve)
    T = math.ceil(horizon / slot) + 1
    along = np.array([t.along_m for t in ts])
    cross = np.array([t.cross_m for t in ts])
    t_in, t_out = visibility_windows(geometry, agility, along, cross)
    lo = [max(0, math.ceil(max(a, 0.0) / slot)) for a in t_in]
    hi = [math.floor(min(b, horizon) / slot) for b in t_out]
    when = np.maximum(t_in, 0.0)

    def move(j, i):
        a = look_vectors(geometry, along[i], cross[i], when[i])
        b = np.array([0, 0, -1.0]) if j < 0 else look_vectors(geometry, along[j], cross[j], when[i])
        ang = float(angle_between_deg(b, a))
        return math.ceil((agility.slew_time_one(ang) + agility.settle_s) / slot - 1e-9)

    best = 0.0
    n = len(ts)
    for counts in itertools.product(*[range(t.need + 1) for t in ts]):
        free, prev, value, ok = 0, -1, 0.0, True
        for i, k in enumerate(counts):
            if k == 0:
                continue
            a = max(free + move(prev, i), lo[i])  # arrive as early as possible
            if a + k - 1 > min(hi[i], T - 1) or a + k >= T:
                ok = False
                break
            free, prev, value = a + k, i, value + ts[i].value * k
        if ok:
            best = max(best, value)
    assert n == len(counts)
    return best


@pytest.mark.parametrize("seed", range(4))
def test_blueprint_dp_matches_brute_force(seed):
    rng = np.random.default_rng(seed)
    g = OrbitGeometry(wfov_gsd_m=64.0)
    agility = get_agility("slow")
    targets = [
        Target(float(rng.uniform(150e3, 400e3)), float(rng.uniform(-800, 800)),
               float(rng.uniform(0.2, 2.0)), int(rng.integers(1, 5)))
        for _ in range(4)
    ]  # fmt: skip
    bp = plan_blueprint(targets, g, agility, horizon_s=60.0, reserve=0.1)
    assert bp.value == pytest.approx(_brute_force(targets, g, agility, 60.0, 0.1))
    # its budgets add up to its value
    assert bp.value == pytest.approx(
        sum(t.value * k for t, k in zip(bp.targets, bp.budget, strict=True))
    )


def test_gate_budgets_reserve_and_given_up_by_hand():
    ts = [Target(0, 0, 1, 5, (10, 20)), Target(0, 0, 1, 5, (40, 50))]
    bp = Blueprint(ts, np.array([2, 0]), np.zeros(2), np.zeros(2), 1, 2.0, 1.0)
    gate = BlueprintGate(bp)
    # rows: 3 on target 0 (budget 2), 1 on target 1 (given up), 2 outside (reserve 1)
    keep = gate.filter(np.array([12, 13, 14, 45, 80, 90]))
    assert keep.tolist() == [True, True, False, False, True, False]
    gate.spend(np.array([12, 80]))
    assert gate.left.tolist() == [1, 0] and gate.reserve_left == 0
    assert gate.filter(np.array([15, 16, 85])).tolist() == [True, False, False]


def test_no_geo_image_in_time_degrades_to_look_ahead_only():
    spec, window = strip_spec(0, width=64, length=512, plumes=2, wind_mps=5.0)
    world = MovingStrip(spec, window)
    cfg = PassConfig(agility="slow", compute_budget_s=0.05)
    plain = fly_pass(world, None, cfg)
    geo = fly_pass(world, None, cfg, geo=GeoSettings(latency_s=5000.0, history_s=1000.0))
    assert geo.geo["degraded"].startswith("no GEO image")
    assert geo.totals() == plain.totals()
    assert plain.geo is None


@pytest.mark.parametrize(
    ("opts", "message"),
    [
        (["--geo-latency-s", "10"], "give --geo"),
        (["--geo", "--geo-latency-s", "-5"], "latency_s"),
        (["--geo", "--geo-cadence-s", "0"], "cadence_s: expected > 0"),
        (["--geo", "--geo-gsd-m", "20"], "not coarser"),
        (["--geo"], "no world to render"),
    ],
)
def test_cli_bad_geo_values_exit_2(tmp_path, capsys, opts, message):
    from dyntarget.io import write_scene
    from dyntarget.scene import Scene

    lab = np.zeros((512, 64), bool)
    img = np.random.default_rng(0).uniform(0.05, 0.2, (4, 512, 64)).astype(np.float32)
    write_scene(Scene(img, label=lab, gsd=8.0, id="s"), tmp_path)
    base = ["fly", "--scene", str(tmp_path / "s.tif"), "--truth", "--out", str(tmp_path / "o")]
    assert main([*base, *opts, "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1
