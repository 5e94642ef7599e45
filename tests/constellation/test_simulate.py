"""Overflights, GEO detection, the board and whole days through the CLI."""

from __future__ import annotations

import csv
import json
import math
from datetime import UTC, datetime

import numpy as np
import pytest

from dyntarget.constellation.geometry import ENC_FIELDS, overflights
from dyntarget.constellation.orbits import ecef_to_geodetic, propagate, walker
from dyntarget.constellation.simulate import Board, geo_detections
from dyntarget.constellation.world import Eruptions

START = "2026-06-01T00:00:00Z"
T0 = datetime(2026, 6, 1, tzinfo=UTC)


def _eruption(onset=0.0, end=86400.0, wind=5.0) -> Eruptions:
    one = np.array
    return Eruptions(
        one([0]),
        one([onset]),
        one([end]),
        one([wind]),
        one([90.0]),
        one([80.0]),
        one([0.1]),
        one([600.0]),
        one([8000.0]),
        one([3.0]),
    )


def test_overflight_of_a_volcano_under_the_track_by_hand():
    sats = walker(1, 1, 0, altitude_km=500.0, inclination_deg=53.0, epoch=T0)
    t0 = 3000.0
    r, _ = propagate(sats, T0, np.array([t0]))
    lat, lon, _ = ecef_to_geodetic(r[0])
    res = overflights(
        {"satellites": [[s.name, s.line1, s.line2, list(s.elements)] for s in sats]},
        start=START,
        seconds=6000.0,
        eruptions=_eruption().to_json(),
        volcano=[[float(lat[0]), float(lon[0]), 0.0]],
        tracks=False,
        settings={"step_s": 20.0, "agility": "fast", "look_ahead_m": 500e3, "swath_m": 30e3},
    )
    rows = [dict(zip(ENC_FIELDS, row, strict=True)) for row in res[0]["rows"]]
    row = min(rows, key=lambda x: abs(x["t_ref"] - t0))
    # by hand: a 30 deg field of regard at ~505 km reaches a central angle
    # asin(6876/6371 sin 30) - 30 = 2.66 deg = 296 km ahead; at 7.06 km/s that is 42 s
    assert row["t_out"] - row["t_in"] == pytest.approx(42.0, abs=1.5)
    # the summit is at nadir at t0 (the window ends there); the NFOV, ready long before,
    # takes it as soon as it enters the field of regard: 42 s before t0, 30 deg off nadir
    # in the schedule's spherical model; the exact WGS 84 angle is smaller (away from the
    # equator the ground lies ~7 km below the sphere the model's altitude is taken from,
    # and 296 km away at ~505 km that is -0.05 deg per km: within 1.5 deg)
    assert row["t_obs"] == pytest.approx(t0 - 42.0, abs=1.5)
    assert 28.5 <= row["off_nadir"] <= 30.0
    # the look-ahead (500 km ahead) passes over it 500 / 7.06 = 71 s before
    assert row["look_hit"] == 1.0
    assert t0 - row["t_look"] == pytest.approx(71.0, abs=1.5)


def test_geo_is_blind_beyond_its_view_and_sees_within():
    er = Eruptions(
        *(
            np.concatenate([getattr(_eruption(), f)] * 2)
            for f in Eruptions.__dataclass_fields__
            if not f.startswith("episode")  # the episode model
        )
    )
    cloud = np.zeros((2, 10))
    # (0 N, 0 E) under Meteosat; (0 N, 70 E): 70 deg from Meteosat and Himawari, zenith ~78 deg
    dets = geo_detections(
        er, np.array([0.0, 0.0]), np.array([0.0, 70.0]), cloud, seconds=86400.0, seed=0
    )
    seen = {e for e, *_ in dets}
    assert seen == {0}
    _, t_img, t_use, g = dets[0]
    # the first full-disk image after onset (Meteosat: every 900 s; a 5 m/s plume covers the
    # 2 km cell in minutes), usable 300 s later
    assert g == 2 and t_img in (900.0, 1800.0) and t_use == t_img + 300.0


def test_ground_relay_by_hand():
    board = Board("ground", 30.0, [np.array([100.0, 5000.0]), np.array([50.0, 3000.0, 9000.0])])
    # sat 0 detects at 200: downlink at its next contact 5000; sat 1 hears at its next, 9000
    assert board.heard(0, 200.0, 1) == 9000.0
    assert board.heard(0, 200.0, 0) == 200.0
    assert board.heard(-1, 2000.0, 1) == 3000.0  # a GEO post reaches sat 1 at its next contact
    assert math.isinf(board.heard(1, 9500.0, 0))
    cross = Board("crosslink", 30.0, [np.array([100.0]), np.array([400.0])])
    assert cross.heard(0, 10.0, 1) == 40.0 and cross.heard(-1, 150.0, 0) == 430.0


def _day(run_cli, tmp_path, name, *extra):
    out = tmp_path / name
    argv = [
        "constellation",
        "--walker",
        "6/3/1",
        "--hours",
        "6",
        "--volcanoes",
        str(extra[0]),
        "--out",
        str(out),
        "--quiet",
        "--no-html",
        *extra[1:],
    ]
    return run_cli(argv), out


def test_day_outputs_columns_and_summary_keys(cli, tmp_path, gvp, capsys):
    rc, out = _day(
        cli,
        tmp_path,
        "a",
        gvp,
        "--cueing",
        "cross+geo",
        "--eruption-model",
        "episodes",
        "--eruptions-per-day",
        "80",
    )
    assert rc == 0
    with open(out / "observations.csv") as f:
        rows = list(csv.DictReader(f))
    assert list(rows[0]) if rows else True
    header = (out / "observations.csv").read_text().splitlines()[0].split(",")
    assert header[:5] == ["satellite", "volcano_number", "time_utc", "off_nadir_deg", "utility"]
    eh = (out / "eruptions.csv").read_text().splitlines()[0].split(",")
    assert eh == [
        "volcano_number",
        "onset_utc",
        "end_utc",
        "first_detection_utc",
        "first_observation_utc",
        "observations",
    ]
    s = json.loads((out / "summary.json").read_text())
    for key in (
        "satellites",
        "eruptions",
        "eruptions_observed",
        "observed_within_6h",
        "median_onset_to_first_obs_s",
        "p90_onset_to_first_obs_s",
        "observations_per_eruption_6h",
        "median_revisit_s",
        "utility",
        "duplicates",
        "observations",
        "options",
    ):
        assert key in s
    assert s["satellites"] == 6 and s["options"]["walker"] == "6/3/1"
    assert "scheduler" not in s["options"]
    for r in rows:
        assert r["satellite"].startswith("W") and r["time_utc"].endswith("Z")
        assert 0.0 <= float(r["off_nadir_deg"]) <= 31.0  # the 30 deg field of regard
    assert (out / "constellation.png").stat().st_size > 10_000


@pytest.mark.slow
def test_same_bytes_serial_and_dask(cli, tmp_path, gvp):
    rc1, a = _day(cli, tmp_path, "serial", gvp, "--cueing", "cross+geo")
    rc2, b = _day(cli, tmp_path, "dask", gvp, "--cueing", "cross+geo", "--scheduler", "local")
    assert rc1 == rc2 == 0
    for name in ("observations.csv", "eruptions.csv", "summary.json", "constellation.png"):
        assert (a / name).read_bytes() == (b / name).read_bytes(), name


BAD_TLE = (
    "SAT\n1 00005U 58002B   00179.78495062  .00000023  00000-0  28098-4 0  4755\n"
    "2 00005  34.2682 348.7242 1859667 331.7664  19.3264 10.82419157413667\n"
)


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--tle", "BAD"], "line 2: checksum '5' does not match"),
        (["--tle", "OLD"], "epoch is 25.9 years before --start"),
        (["--walker", "0/1/0"], "empty constellation"),
        (["--walker", "6/3/1", "--hours", "0"], "--hours"),
        (["--walker", "6/3/1", "--hours", "-3"], "--hours"),
        (
            ["--walker", "6/3/1", "--volcanoes", "CAT"],
            "line 3: longitude 999 is outside [-180, 180]",
        ),
        (["--walker", "6/3/1", "--volcanoes", "MISSING"], "nope.csv"),
        (["--walker", "6/3/1", "--agility", "unlimited"], "needs a field of regard"),
        (
            ["--walker", "6/3/1", "--eruptions-per-day", "80"],
            "--eruptions-per-day applies to --eruption-model episodes, not eruptions",
        ),
        (
            ["--walker", "6/3/1", "--eruption-model", "episodes", "--episodes-per-day", "2"],
            "--episodes-per-day applies to --eruption-model eruptions, not episodes",
        ),
        (["--walker", "6/3/1", "--episode-median-h", "100"], "--episode-median-h"),
        pytest.param(
            [
                "--walker",
                "60/12/1",
                "--allocation",
                "bound",
                "--hours",
                "24",
                "--cueing",
                "cross+geo",
                "--eruption-model",
                "episodes",
                "--eruptions-per-day",
                "2000",
            ],
            "more than the exact solver's",
            marks=pytest.mark.slow,
        ),
    ],
)
def test_bad_input_one_line_exit_2(cli, tmp_path, gvp, capsys, args, message):
    (tmp_path / "bad.tle").write_text(BAD_TLE)
    good = BAD_TLE.replace("4755", "4753")
    (tmp_path / "old.tle").write_text(good)
    (tmp_path / "cat.csv").write_text(
        "volcano_number,latitude,longitude,elevation_m,last_known_eruption\n"
        "1,10,20,0,2020 CE\n2,10,999,0,2020 CE\n"
    )
    sub = {
        "BAD": str(tmp_path / "bad.tle"),
        "OLD": str(tmp_path / "old.tle"),
        "CAT": str(tmp_path / "cat.csv"),
        "MISSING": str(tmp_path / "nope.csv"),
    }
    args = [sub.get(a, a) for a in args]
    if "--volcanoes" not in args:
        args += ["--volcanoes", str(gvp)]
    if sub["BAD"] in args:  # a start near the epoch: the checksum is what is wrong
        args += ["--start", "2000-06-27T00:00:00Z"]
    rc = cli(["constellation", *args, "--out", str(tmp_path / "o"), "--quiet"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2
    assert len(err) == 1 and err[0].startswith("dyntarget: error:")
    assert message in err[-1]
    assert not (tmp_path / "o" / "summary.json").exists()


def test_chunking_and_resume_give_the_same_day(tmp_path, gvp):
    from dyntarget.constellation.orbits import walker as make_walker
    from dyntarget.constellation.simulate import Settings, run_day
    from dyntarget.constellation.world import read_catalog

    cat = read_catalog(gvp)
    sats = make_walker(6, 3, 1, altitude_km=500.0, inclination_deg=97.4, epoch=T0)
    kw = {"start": START, "hours": 6.0, "seed": 2, "settings": Settings(cueing="cross+geo")}
    one = run_day(sats, cat, chunk=1, **kw)
    parts = tmp_path / "parts"
    many = run_day(sats, cat, chunk=4, parts=parts, **kw)
    assert len(list(parts.glob("*.json"))) == 2  # 6 satellites in tasks of 4: two parts
    again = run_day(sats, cat, chunk=4, parts=parts, **kw)  # resumed from the parts
    assert one.summary == many.summary == again.summary
    assert one.observations == many.observations == again.observations


@pytest.mark.slow
def test_sweep_on_a_local_cluster_matches_serial(gvp):
    from dyntarget.constellation.run import sweep
    from dyntarget.constellation.world import read_catalog

    cat = read_catalog(gvp)
    configs = [
        {
            "walker": w,
            "altitude_km": 500.0,
            "inclination_deg": "sso",
            "start": START,
            "hours": 3.0,
            "seed": 1,
            "cueing": m,
            "allocation": "distributed",
        }
        for w in ("1/1/0", "6/3/1")
        for m in ("none", "cross+geo")
    ]
    serial = sweep(configs, cat)
    local = sweep(configs, cat, scheduler="local")
    assert json.dumps(serial, sort_keys=True) == json.dumps(local, sort_keys=True)
    assert [s["options"]["walker"] for s in serial] == ["1/1/0", "1/1/0", "6/3/1", "6/3/1"]


def test_two_level_day_keeps_in_progress_eruptions_out_of_onset_figures(cli, tmp_path, gvp):
    rc, out = _day(cli, tmp_path, "two", gvp, "--cueing", "cross+geo")
    assert rc == 0
    s = json.loads((out / "summary.json").read_text())
    assert s["options"]["eruption_model"] == "eruptions"
    assert s["eruptions"] == s["eruptions_in_progress_at_start"] + s["eruptions_started"]
    assert s["eruptions_in_progress_at_start"] > 10  # mean 45
    assert s["observed_within_6h"] <= s["eruptions_started"]
    assert s["episodes_observed_within_6h"] <= s["episodes_observed"] <= s["episodes_started"]
    with open(out / "eruptions.csv") as f:
        rows = list(csv.DictReader(f))
    before = [r for r in rows if r["onset_utc"] < "2026-06-01"]
    assert len(before) == s["eruptions_in_progress_at_start"]  # onsets before the start


def test_geo_sees_a_plume_only_during_an_episode():
    one = np.array
    base = _eruption(onset=-1e6, end=1e6, wind=8.0)
    kw = {f: getattr(base, f) for f in base.__dataclass_fields__ if not f.startswith("episode")}
    quiet = Eruptions(**kw, episode_eruption=one([0]), episode_onset_s=one([-5000.0]),
                      episode_end_s=one([-1000.0]))  # fmt: skip
    lat, lon = one([0.0]), one([-75.2])
    assert geo_detections(quiet, lat, lon, np.zeros((1, 3)), seconds=7200.0, seed=0) == []
    busy = Eruptions(**kw, episode_eruption=one([0]), episode_onset_s=one([3000.0]),
                     episode_end_s=one([7000.0]))  # fmt: skip
    (d,) = geo_detections(busy, lat, lon, np.zeros((1, 3)), seconds=7200.0, seed=0)
    assert d[1] >= 3000.0 and d[1] % 600.0 == 0.0  # a GOES-East image in the episode


def test_an_eruption_without_an_episode_has_no_plume():
    # an eruption whose plume episodes all fall outside the period has none listed; asking
    # for its latest episode read one past the end of the episode arrays (an IndexError on
    # a 6 h cross+geo day of the bound benchmark)
    one = np.array
    base = _eruption(onset=-1e6, end=1e6, wind=8.0)
    kw = {f: getattr(base, f) for f in base.__dataclass_fields__ if not f.startswith("episode")}
    none = Eruptions(**kw, episode_eruption=one([], np.int64), episode_onset_s=one([]),
                     episode_end_s=one([]))  # fmt: skip
    assert none.plume_onset_s(one([0, 0]), one([100.0, 5000.0])).tolist() == [np.inf, np.inf]
    lat, lon = one([0.0]), one([-75.2])
    assert geo_detections(none, lat, lon, np.zeros((1, 3)), seconds=7200.0, seed=0) == []


@pytest.mark.slow
def test_without_a_board_predicting_the_others_looks_removes_duplicates_not_observations(
    gvp, monkeypatch
):
    # 500 satellites, 6 h, no cueing: satellites of one plane pass over a vent minutes
    # apart and each sees the plume with its own look-ahead. The same day flown with no
    # prediction (the allocation before it) is the reference
    from dyntarget.constellation import simulate
    from dyntarget.constellation.run import config_day
    from dyntarget.constellation.world import read_catalog

    catalog = read_catalog(gvp)
    cfg = {
        "walker": "500/25/1",
        "altitude_km": 500.0,
        "inclination_deg": "sso",
        "start": "2026-06-01T00:00:00Z",
        "hours": 6.0,
        "seed": 1,
        "cueing": "none",
        "allocation": "distributed",
    }
    day, _ = config_day(cfg, catalog)
    monkeypatch.setattr(simulate, "_predicted_looks", lambda *a, **k: None)
    before, _ = config_day(cfg, catalog)

    def kept(d):
        return {
            (o["satellite"], o["eruption"], o["time_s"])
            for o in d.observations
            if not o["duplicate"]
        }

    assert before.summary["duplicates"] >= 5  # the duplicates a board-less day makes
    assert day.summary["duplicates"] < before.summary["duplicates"] / 3
    assert kept(day) == kept(before) and len(kept(day)) > 40  # no observation lost
    assert day.summary["utility"] == before.summary["utility"]
