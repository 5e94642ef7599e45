"""GEO foresight: detection, nowcast, the blueprint DP (against brute force), the gate, the CLI."""

from __future__ import annotations

import itertools
from dataclasses import replace

import numpy as np
import pytest

from dyntarget.cli import main
from dyntarget.errors import InvalidParameterError
from dyntarget.fly import PassConfig, fly_pass
from dyntarget.geo import Blueprint, Target, detect, nowcast, plan_blueprint
from dyntarget.geo.blueprint import step_s
from dyntarget.geo.refine import BlueprintGate
from dyntarget.geo.targets import image_times
from dyntarget.passes.geo import GeoSettings
from dyntarget.schedule import OrbitGeometry, get_agility, schedule
from dyntarget.synth.strip import strip_spec
from dyntarget.synth.strip_world import MovingStrip
from dyntarget.trajectory import Trajectory


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
    from dyntarget.predict import lucas_kanade

    out, v = nowcast(fields, 600.0, [0.0, 1200.0], lambda st: lucas_kanade(st, needs="pysteps"))
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


def _flown_value(ts, counts, g, agility):
    """Fly ``counts[i]`` pointings on each target (2 px apart, along-track order) through the
    loop's own scheduler and add up the gains of those it keeps."""
    pts, who = [], []
    for i, (t, k) in enumerate(zip(ts, counts, strict=True)):
        for m in range(k):
            pts.append(
                [t.cross_m / g.wfov_gsd_m, -(t.along_m + 2 * m * g.wfov_gsd_m) / g.wfov_gsd_m]
            )
            who.append(i)
    if not pts:
        return 0.0
    traj = Trajectory(np.array(pts), np.zeros(len(pts)), "test")
    sched = schedule(traj, (1, 1), g, agility)
    taken = [0] * len(ts)
    value = 0.0
    for j in sched.kept:
        i = who[j]
        value += ts[i].gains()[taken[i]]
        taken[i] += 1
    return value


def _targets(seed, n=3):
    rng = np.random.default_rng(seed)
    return [
        Target(float(rng.uniform(150e3, 450e3)), float(rng.uniform(-800, 800)), 0.0,
               int(rng.integers(1, 4)), curve=tuple(rng.uniform(0.1, 2.0, 3)))
        for _ in range(n)
    ]  # fmt: skip


@pytest.mark.parametrize("seed", range(5))
@pytest.mark.parametrize("preset", ["slow", "fast"])
def test_blueprint_is_flown_whole_by_the_loops_scheduler(seed, preset):
    # the blueprint's pointings, flown by dyntarget.schedule.schedule (the loop's kinematics),
    # are all kept: its value is what the loop's own timer achieves with those counts
    g = OrbitGeometry(wfov_gsd_m=64.0, look_ahead_m=0.0)
    agility = get_agility(preset)
    ts = _targets(seed)
    bp = plan_blueprint(ts, g, agility, horizon_s=90.0, reserve=0.0)
    assert _flown_value(bp.targets, bp.budget.tolist(), g, agility) == pytest.approx(bp.value)
    # and no choice of counts flown through the scheduler does better than it by much
    # (the programme rounds every time up to its slots)
    best = max(
        _flown_value(bp.targets, list(c), g, agility)
        for c in itertools.product(*[range(t.need + 1) for t in bp.targets])
    )
    assert bp.value <= best + 1e-9
    assert bp.value >= 0.75 * best


def test_blueprint_leaves_a_poor_target_for_a_rich_one_by_hand():
    # two targets 20 km apart: both windows close at nadir 3 s apart, and the slow preset's
    # 1 deg/s cannot serve both fully: the richer one (2 per pointing) takes the time
    g = OrbitGeometry(wfov_gsd_m=64.0)
    ts = [Target(300e3, 0.0, 1.0, 40), Target(320e3, 0.0, 2.0, 40)]
    bp = plan_blueprint(ts, g, get_agility("slow"), horizon_s=80.0, reserve=0.0)
    assert bp.budget[0] == 0 and bp.budget[1] > 0
    assert bp.value == pytest.approx(2.0 * bp.budget[1])


def test_target_gains_best_first():
    t = Target(0.0, 0.0, 9.0, 3, curve=(0.2, 0.7, 0.1, 0.5))
    assert t.gains().tolist() == [0.7, 0.5, 0.2]


def _gate(budget=(), starts=(), spans=(), preset="slow"):
    from dyntarget.passes.record import FramePlan

    g = OrbitGeometry(wfov_gsd_m=64.0)
    frames = FramePlan((4000, 32), 32, 16, 16 * 64.0 / g.ground_speed, (0,), g)
    ts = [Target(0.0, 0.0, 1.0, 10, sp) for sp in spans]
    n = len(ts)
    bp = Blueprint(ts, np.array(budget, np.int64), np.array(starts, float), np.full(n, np.nan),
                   0, 0.0, 1.0)  # fmt: skip
    return BlueprintGate(bp, frames, get_agility(preset))


def test_gate_pools_a_target_and_flies_its_best_pixels_once_seen_whole():
    gate = _gate()
    rows = np.array([3000, 3000, 3001, 3002, 3002])
    cols = np.array([4, 5, 4, 4, 9])
    vals = np.array([0.1, 0.9, 0.5, 0.8, 0.2])
    # the look-ahead has not passed the plume yet (frame top 2990 > 3000 - MERGE_ROWS): pooled
    assert gate.route(0.0, 2990, rows, cols, vals, 0.0).shape == (0, 2)
    assert gate.stats["pointings_pooled"] == 5
    # seen whole: all five fit the slow preset's 41 s window, nearest the sensor first
    # (largest row), serpentine across
    out = gate.route(0.1, 2980, rows[:0], cols[:0], vals[:0], 0.0)
    assert out.tolist() == [[3002, 9], [3002, 4], [3001, 4], [3000, 5], [3000, 4]]
    # a pixel already flown is never pooled again
    assert gate.route(0.2, 2970, rows, cols, vals, 0.0).shape == (0, 2)


def test_gate_takes_the_top_k_when_time_is_short():
    gate = _gate()
    rows = np.full(6, 3000)
    cols = np.arange(6)
    vals = np.array([0.3, 0.9, 0.1, 0.8, 0.5, 0.2])
    gate.route(0.0, 2990, rows, cols, vals, 0.0)
    # the sensor tracks the plume and is free 3.2 pointings before its window closes;
    # starting again costs a settle (1 s, no slew): two pointings fit
    _, t_out, along, cross = gate._window(len(gate.t_lo) - 1)
    step = step_s(gate.geometry, gate.agility, np.array([along]), np.array([cross]),
                 np.array([t_out]))[0]  # fmt: skip
    gate.booked_at = (along, cross)
    out = gate.route(0.1, 2980, rows[:0], cols[:0], vals[:0], t_out - 3.2 * step)
    assert sorted(out[:, 1].tolist()) == [1, 3]  # the two best


def test_gate_caps_for_the_next_chosen_target_and_lifts_the_cap_when_it_is_refuted():
    # a chosen blueprint target on rows 2700-2710, planned to start 5 s into the plume's window
    gate = _gate(budget=[3], starts=[0.0], spans=[(2700.0, 2710.0)])
    rows = np.full(40, 3000)
    cols = np.arange(40) % 32
    rows[32:] = 3001
    vals = np.linspace(1.0, 0.1, 40)
    gate.route(0.0, 2990, rows, cols, vals, 0.0)
    t_in = gate._window(1)[0]
    gate.planned_start[0] = t_in + 5.0
    first = gate.route(0.1, 2980, rows[:0], cols[:0], vals[:0], 0.0)
    assert gate.cap_by == {1: 0} and 1 <= len(first) <= 5
    # the look-ahead passes the chosen target's rows and finds nothing there: the cap goes
    more = gate.route(0.2, 2600, rows[:0], cols[:0], vals[:0], 0.0)
    assert gate.cap_by == {} and gate.stats["caps_lifted"] == 1
    assert len(first) + len(more) > 5
    # the extra pointings are the next best ones
    got = {tuple(rc) for rc in np.concatenate([first, more]).tolist()}
    ranked = [
        (int(r), int(c))
        for r, c in zip(rows[np.argsort(-vals)], cols[np.argsort(-vals)], strict=True)
    ]
    assert got == set(ranked[: len(got)])


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
        (["--geo", "--geo-latency-s", "-5"], "--geo-latency-s: expected seconds in 0..86400"),
        (["--geo", "--geo-cadence-s", "0"], "--geo-cadence-s: expected seconds in (0, 86400]"),
        (["--geo", "--geo-gsd-m", "20"], "not coarser"),
        (["--geo"], "no world to render"),
        (["--geo-omniscient", "--geo-blind"], "exclude each other"),
        (["--geo-no-stage"], "--geo-no-stage: give --geo too"),
        (["--geo-detection", "unmix"], "--geo-detection: give --geo too"),
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


def test_unmix_recovers_cloud_and_plume_fractions_built_by_hand():
    from dyntarget.geo import unmix
    from dyntarget.synth.volcano import ASH_PLUME, CLOUD, STEAM

    members = np.array([CLOUD, ASH_PLUME, STEAM])
    ground = np.array([0.05, 0.08, 0.06, 0.30])  # vegetation: bright in the NIR
    bg = np.repeat(ground[:, None, None], 3, axis=2)
    img = bg.copy()
    # cell 0: 30 % cloud; cell 1: 20 % ash + 10 % steam; cell 2: clear
    img[:, 0, 0] = ground + 0.3 * (np.array(CLOUD) - ground)
    img[:, 0, 1] = ground + 0.2 * (np.array(ASH_PLUME) - ground) + 0.1 * (np.array(STEAM) - ground)
    f = unmix(img, bg, members)
    assert f[:, 0, 0] == pytest.approx([0.3, 0.0, 0.0], abs=1e-9)
    assert f[:, 0, 1] == pytest.approx([0.0, 0.2, 0.1], abs=1e-9)
    assert f[:, 0, 2] == pytest.approx([0.0, 0.0, 0.0], abs=1e-12)


def test_plume_field_ignores_a_cloud_that_brightness_takes_for_a_plume():
    from dyntarget.geo.targets import CONTRAST, plume_field
    from dyntarget.synth.volcano import ASH_PLUME, CLOUD, STEAM

    ground = np.array([0.05, 0.08, 0.06, 0.30])
    bg = np.repeat(ground[:, None, None], 2, axis=2)
    img = bg.copy()
    img[:, 0, 0] = ground + 0.2 * (np.array(CLOUD) - ground)  # a fifth of the cell cloudy
    img[:, 0, 1] = ground + 0.4 * (np.array(ASH_PLUME) - ground)  # 40 % ash
    unmixed = plume_field(img, bg, GeoSettings(), np.array([CLOUD, ASH_PLUME, STEAM]))
    bright = plume_field(img, bg, GeoSettings(detection="brightness"))
    # brightness: the cloud's anomaly (0.2 x (0.8075 - 0.1225) = 0.137) beats the ash's
    assert bright[0, 0] == pytest.approx(0.2 * (np.mean(CLOUD) - ground.mean()))
    assert bright[0, 0] > bright[0, 1]
    # unmixed: no plume under the cloud, the ash cell at 0.4 x CONTRAST
    assert unmixed[0, 0] == pytest.approx(0.0, abs=1e-9)
    assert unmixed[0, 1] == pytest.approx(0.4 * CONTRAST)
    with pytest.raises(InvalidParameterError, match="detection"):
        GeoSettings(detection="classifier")


def _staging_gate(look_ahead_m, stage=True):
    """A strip 8000 WFOV rows long seen 16 rows a frame; one chosen target on rows 990-1010."""
    from dyntarget.passes.record import FramePlan

    g = OrbitGeometry(wfov_gsd_m=64.0, look_ahead_m=look_ahead_m)
    tops = tuple(range(8000 - 32, -1, -16))
    frames = FramePlan((8000, 32), 32, 16, 16 * 64.0 / g.ground_speed, tops, g)
    bp = Blueprint([Target(0.0, 0.0, 1.0, 10, (990.0, 1010.0))], np.array([10]),
                   np.array([0.0]), np.array([np.nan]), 0, 0.0, 1.0)  # fmt: skip
    return BlueprintGate(bp, frames, get_agility("slow"), stage=stage), frames


def _fly_idle(gate, frames):
    """Route every frame with nothing seen until the look-ahead reaches the target."""
    sent = []
    for k, top in enumerate(frames.tops):
        if top <= 1010:
            break
        t_k = frames.acquired_s(k)
        out = gate.route(t_k, top, np.zeros(0, int), np.zeros(0, int), np.zeros(0), t_k)
        sent += [(k, tuple(rc)) for rc in out.tolist()]
    return sent


def test_idle_sensor_is_sent_ahead_just_in_time_for_a_target_the_look_ahead_sees_too_late():
    # look-ahead 150 km: the target (about 600 km ahead at t = 0) enters the slow
    # preset's 30-degree field of regard ~290 km ahead of nadir, before any frame shows it
    gate, frames = _staging_gate(150e3)
    sent = _fly_idle(gate, frames)
    assert len(sent) == 1 and sent[0][1] == (1000, 16)  # one pointing, the target's centre
    k = sent[0][0]
    # flown through the loop's scheduler: from frame k the sensor (idle at nadir) is on the
    # target when its window opens; from frame k + 1 it would be late
    g = frames.geometry

    def start(kk):
        traj = Trajectory(np.array([[16.0, 1000.0 - (8000 - 32)]]), np.zeros(1), "anchor")
        sch = schedule(traj, (32, 32), replace(g, start_s=frames.acquired_s(kk)), "slow")
        return float(sch.times[0])

    from dyntarget.schedule import visibility_windows

    along, cross = g.ground(np.array([[16.0, 1000.0 - (8000 - 32)]]), (32, 32))
    t_in = float(visibility_windows(g, get_agility("slow"), along, cross)[0][0])
    assert start(k) == pytest.approx(t_in, abs=1e-6)
    assert start(k + 1) > t_in
    assert gate.stats["staged"] == 1


def test_no_staging_when_the_look_ahead_sees_the_target_in_time_or_when_ablated():
    gate, frames = _staging_gate(500e3)  # seen whole ~30 s before its window opens
    assert _fly_idle(gate, frames) == []
    gate, frames = _staging_gate(150e3, stage=False)
    assert _fly_idle(gate, frames) == []


def test_gate_under_unlimited_agility_flies_every_pooled_pixel():
    # unlimited agility: no field of regard (every window is open) and a pointing takes no
    # time (its step is 0 s), so a target is released at once with its whole pool (the
    # release divided by the step: ZeroDivisionError)
    gate = _gate(preset="unlimited")
    rows = np.array([3000, 3000, 3001, 3002, 3002, 3003])
    cols = np.array([4, 5, 4, 4, 9, 1])
    vals = np.array([0.1, 0.9, 0.5, 0.8, 0.2, 0.05])
    out = gate.route(0.0, 2990, rows, cols, vals, 0.0)
    # nearest the sensor first (largest row), serpentine: odd rows left to right
    want = [[3003, 1], [3002, 9], [3002, 4], [3001, 4], [3000, 5], [3000, 4]]
    assert out.tolist() == want


@pytest.mark.slow
@pytest.mark.parametrize("geo", [["--geo-omniscient"], ["--geo-prior", "vents"]])
def test_cli_geo_reference_flies_under_unlimited_agility(tmp_path, capsys, geo):
    import json

    from dyntarget.synth.strip import write_strip

    spec, window = strip_spec(0, width=64, length=512, plumes=2, wind_mps=5.0)
    tif = next(p for p in write_strip(spec, window, tmp_path) if p.name == f"{spec.id}.tif")
    out = tmp_path / "o"
    argv = ["fly", "--scene", str(tif), "--truth", *geo, "--agility", "unlimited",
            "--compute-budget-s", "0.05", "--no-picture", "--out", str(out), "--quiet"]  # fmt: skip
    assert main(argv) == 0, capsys.readouterr().err
    doc = json.loads((out / "summary.json").read_text())
    assert doc["agility"] == "unlimited" and doc["pointings_flown"] > 0
    # the catalog prior: one target per vent of the strip (2); the truth: at least one plume
    assert doc["geo"]["targets"] == 2 if "--geo-prior" in geo else doc["geo"]["targets"] >= 1


def test_plume_field_with_named_members_counts_every_member_but_cloud():
    from dyntarget.geo.targets import CONTRAST, plume_field

    ground = np.array([0.05, 0.08, 0.06, 0.30])
    cloud, steam = np.array([0.8, 0.8, 0.8, 0.8]), np.array([0.75, 0.75, 0.75, 0.56])
    bg = np.repeat(ground[:, None, None], 2, axis=2)
    img = bg.copy()
    img[:, 0, 0] = ground + 0.5 * (cloud - ground)
    img[:, 0, 1] = ground + 0.25 * (steam - ground)
    # two members found (no ash), in an order of their own
    field = plume_field(img, bg, GeoSettings(), np.stack([steam, cloud]), ["steam", "cloud"])
    assert field[0] == pytest.approx([0.0, 0.25 * CONTRAST], abs=1e-9)
    assert plume_field(img, bg, GeoSettings(), np.zeros((0, 4)), []).tolist() == [[0.0, 0.0]]


@pytest.mark.slow
def test_geo_settings_endmembers_and_persistence_validated_and_left_out_when_default():
    with pytest.raises(InvalidParameterError, match="end-members: expected one of"):
        GeoSettings(endmembers="library")
    with pytest.raises(InvalidParameterError, match="persistence"):
        GeoSettings(persistence=1)  # type: ignore[arg-type]
    spec, window = strip_spec(0, width=64, length=512, plumes=2, wind_mps=5.0)
    world = MovingStrip(spec, window)
    cfg = PassConfig(agility="slow", compute_budget_s=0.05)
    plain = fly_pass(world, None, cfg, geo=GeoSettings(latency_s=0.0))
    assert "endmembers" not in plain.geo["settings"]
    assert "persistence" not in plain.geo["settings"]
    est = fly_pass(world, None, cfg, geo=GeoSettings(latency_s=0.0, endmembers="estimated"))
    assert est.geo["settings"]["endmembers"] == "estimated"
    assert set(est.geo["endmembers"]["members"]) <= {"cloud", "ash", "steam"}
