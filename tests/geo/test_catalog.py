"""The catalog baseline (dyntarget.geo.catalog): reading a catalog, placing it on a strip.

Expected values come from elsewhere: the catalog's README (counts), pyproj on its own
(projected coordinates), the pass loop's and the GEO code's own ground coordinates, and
hand arithmetic.
"""

from __future__ import annotations

import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from affine import Affine

from dyntarget.errors import DataFileError, InvalidSceneError
from dyntarget.geo import Target, plan_blueprint
from dyntarget.geo.catalog import (
    NEED_MAX,
    PRIOR_RADIUS_M,
    PRIOR_VALUE,
    Volcano,
    catalog_targets,
    eruption_year,
    locate,
    prior_targets,
    read_catalog,
    strip_vents,
)
from dyntarget.schedule import OrbitGeometry
from helpers import shared_data

HEADER = "volcano_number,volcano_name,last_known_eruption,latitude,longitude\n"


def _gvp() -> Path:
    root = shared_data()
    path = None if root is None else root / "gvp-holocene" / "volcanoes.csv"
    if path is None or not path.is_file():
        pytest.skip("the GVP Holocene catalog (../shared/data/gvp-holocene) is not here")
    return path


def test_reads_the_gvp_holocene_catalog_with_the_counts_its_readme_gives():
    path = _gvp()
    assert len(read_catalog(path)) == 1250
    # README: "229 volcanoes have a last known eruption in 2000 CE or later; 54 in 2025 CE"
    assert len(read_catalog(path, active_since=2000)) == 229
    assert len(read_catalog(path, active_since=2025)) == 54
    kilauea = [v for v in read_catalog(path) if v.name == "Kilauea"]
    assert kilauea == [Volcano("Kilauea", 19.421, -155.287, 332010, 2025)]


def test_eruption_years_bce_ce_and_unknown():
    assert eruption_year("1801 CE") == 1801
    assert eruption_year("1 BCE") == 0  # astronomical: no year 0 in the calendar
    assert eruption_year("8300 BCE") == -8299
    assert eruption_year(" Unknown ") is None
    assert eruption_year("") is None
    with pytest.raises(ValueError, match="2025 CE"):
        eruption_year("about 1900")


@pytest.mark.parametrize(
    ("row", "message"),
    [
        ("7,Bad,2025 CE,,10", r"line 3 \(Bad\): latitude is missing"),
        ("7,Bad,2025 CE,95,10", r"line 3 \(Bad\): latitude 95 is outside \[-90, 90\]"),
        ("7,Bad,2025 CE,10,-180.5", r"line 3 \(Bad\): longitude -180.5 is outside \[-180, 180\]"),
        ("7,Bad,2025 CE,ten,10", r"line 3 \(Bad\): latitude 'ten' is not a number"),
        ("7,Bad,2025 CE,10,nan", r"line 3 \(Bad\): longitude nan is outside"),
        ("7,Bad,last week,10,10", r"line 3 \(Bad\): last_known_eruption: expected a year"),
        ("x7,Bad,2025 CE,10,10", r"line 3 \(Bad\): volcano_number 'x7' is not an integer"),
    ],
)
def test_a_malformed_row_is_named_with_its_field(tmp_path, row, message):
    p = tmp_path / "cat.csv"
    p.write_text(HEADER + "1,Good,2020 CE,10,10\n" + row + "\n")
    with pytest.raises(DataFileError, match=message) as err:
        read_catalog(p)
    assert "\n" not in str(err.value)
    assert str(p) in str(err.value)


def test_a_catalog_without_coordinates_or_not_text_is_refused(tmp_path):
    p = tmp_path / "cat.csv"
    p.write_text("volcano_name,lat,lon\nA,1,2\n")
    with pytest.raises(DataFileError, match="no 'latitude' or 'longitude' column"):
        read_catalog(p)
    p.write_bytes(b"latitude,longitude\n\xff\xfe,1\n")
    with pytest.raises(DataFileError, match="not UTF-8"):
        read_catalog(p)
    with pytest.raises(DataFileError, match="cannot read"):
        read_catalog(tmp_path / "missing.csv")


def test_locate_agrees_with_pyproj():
    pyproj = pytest.importorskip("pyproj")
    t = Affine(30.0, 0.0, 200_000.0, 0.0, -30.0, 2_250_000.0)
    vs = [Volcano("Kilauea", 19.421, -155.287), Volcano("Mauna Loa", 19.475, -155.608)]
    rows, cols = locate(vs, "EPSG:32605", t)
    tr = pyproj.Transformer.from_crs(4326, 32605, always_xy=True)
    for v, r, c in zip(vs, rows, cols, strict=True):
        e, n = tr.transform(v.lon, v.lat)
        assert c == pytest.approx((e - 200_000.0) / 30.0, abs=1e-6)
        assert r == pytest.approx((2_250_000.0 - n) / 30.0, abs=1e-6)


def test_locate_needs_a_georeferenced_strip():
    with pytest.raises(InvalidSceneError, match="georeferenced"):
        locate([Volcano("A", 0.0, 0.0)], None, None)


def _frames(hw: int, ww: int, frame_px: int, gsd_w: float):
    return SimpleNamespace(
        wfov_shape=(hw, ww),
        frame_px=frame_px,
        geometry=OrbitGeometry(look_ahead_m=500e3, wfov_gsd_m=gsd_w),
    )


def test_the_hawaiian_volcanoes_over_a_strip_are_the_ones_inside_it():
    pyproj = pytest.importorskip("pyproj")
    path = _gvp()
    # a strip over the Big Island in UTM 5N: 70 km across (x 200-270 km), 120 km along
    # (y 2080-2200 km), 32 m pixels; WFOV 128 m (factor 4)
    gsd, factor = 32.0, 4
    w_px, h_px = 2188, 3750
    t = Affine(gsd, 0.0, 200_000.0, 0.0, -gsd, 2_200_000.0)
    world = SimpleNamespace(crs="EPSG:32605", transform=t, shape=(h_px, w_px))
    frames = _frames(h_px // factor, w_px // factor, 64, gsd * factor)
    radius = PRIOR_RADIUS_M
    ts, info = prior_targets(path, world, frames, factor)
    # independent: every catalogued volcano's UTM position (pyproj), inside the box
    # widened by the prior's radius
    tr = pyproj.Transformer.from_crs(4326, 32605, always_xy=True)
    expect = []
    for v in read_catalog(path):
        e, n = tr.transform(v.lon, v.lat)
        if 200e3 - radius <= e <= 270e3 + radius and 2080e3 - radius <= n <= 2200e3 + radius:
            expect.append(v.name)
    assert sorted(info["names"]) == sorted(expect)
    assert {"Kilauea", "Mauna Loa", "Hualalai"} <= set(expect)
    assert "Haleakala" not in expect  # Maui, ~90 km beyond
    assert info["in_footprint"] == len(ts) == len(expect)
    assert [t.along_m for t in ts] == sorted(t.along_m for t in ts)  # along-track order


def test_target_geometry_matches_the_loop_and_the_geo_code():
    from dyntarget.fly import PassConfig
    from dyntarget.geo.targets import along_of_row
    from dyntarget.passes.record import frame_plan
    from dyntarget.scene import Scene
    from dyntarget.synth.worlds import StaticWorld

    img = np.zeros((4, 1024, 256), np.float32)
    world = StaticWorld(Scene(img, label=np.zeros((1024, 256), bool), gsd=16.0))
    frames = frame_plan(world, PassConfig(factor=4))  # WFOV 64 m, 256 x 64, frames of 64
    # a volcano at high-res pixel centre (row 401.5, col 101.5) -> WFOV (100.125, 25.125)
    ts, idx = catalog_targets(
        np.array([402.0]), np.array([102.0]), frames.wfov_shape, frames.frame_px,
        frames.geometry, 4, radius_m=640.0,
    )  # fmt: skip
    assert idx.tolist() == [0]
    (t,) = ts
    row = 402.0 / 4 - 0.5
    assert t.along_m == pytest.approx(float(along_of_row(frames, np.array([row]))[0]))
    # the scheduler's own ground coordinates: in frame k's pixels, nadir at t_k
    k = 2
    top = frames.tops[k]
    along, cross = frames.geometry.ground(
        np.array([[102.0 / 4 - 0.5, row - top]]), (frames.frame_px, frames.wfov_shape[1])
    )
    assert t.along_m == pytest.approx(
        float(along[0]) + frames.geometry.ground_speed * k * frames.cadence_s
    )
    assert t.cross_m == pytest.approx(float(cross[0]))
    assert t.span == pytest.approx((row - 10.0, row + 10.0))  # 640 m = 10 WFOV px each way
    assert t.value == PRIOR_VALUE
    assert t.need == min(NEED_MAX, round(4e6 / 64.0**2))  # 977 -> capped


def test_volcanoes_beyond_the_radius_are_left_out_and_edges_clipped():
    f = _frames(100, 20, 32, 100.0)
    # high-res rows/cols at factor 1: WFOV (r, c) = (x - 0.5); radius 5 px (500 m)
    rows = np.array([-5.0, -6.0, 50.5, 104.5, 50.5])
    cols = np.array([10.5, 10.5, 24.5, 10.5, 26.0])
    ts, idx = catalog_targets(rows, cols, f.wfov_shape, 32, f.geometry, 1, radius_m=500.0)
    # -5.5 is within 5 px of -0.5; -6.5 is not; col 24 is 4.5 px beyond 19.5 (kept),
    # col 25.5 is 6 beyond (dropped); row 104 is 4.5 beyond 99.5 (kept)
    assert sorted(idx.tolist()) == [0, 2, 3]
    for t in ts:
        assert 0.0 <= t.span[0] <= t.span[1] <= 99.0
        assert abs(t.cross_m) <= 9.5 * 100.0 + 1e-9


def test_a_synthetic_strips_vents_are_its_catalog():
    from dyntarget.fly import PassConfig
    from dyntarget.passes.record import frame_plan
    from dyntarget.synth.strip import strip_spec
    from dyntarget.synth.strip_world import MovingStrip

    spec, window = strip_spec(4, width=128, length=576, plumes=3)
    w = MovingStrip(spec, window)
    vs = strip_vents(w)
    assert len(vs) == 3
    rows, cols = locate(vs, w.crs, w.transform)  # back through the CRS: the vents' pixels
    c0, r0 = window[:2]
    assert rows == pytest.approx([v.y - r0 for v in spec.vents], abs=1e-6)
    assert cols == pytest.approx([v.x - c0 for v in spec.vents], abs=1e-6)
    frames = frame_plan(w, PassConfig(factor=4))
    ts, info = prior_targets("vents", w, frames, 4)
    on = [0 <= v.y - r0 < 576 and 0 <= v.x - c0 < 128 for v in spec.vents]
    assert all(on)  # strip_spec puts every vent on the strip
    assert info["volcanoes"] == 3 and len(ts) == 3
    with pytest.raises(InvalidSceneError, match="synthetic"):
        # a strip with no synthetic world (a GeoTIFF): no vents to list
        strip_vents(
            SimpleNamespace(
                id="x", crs="EPSG:32605", transform=Affine.identity(), vent_pixels=lambda: None
            )
        )


@pytest.mark.slow
def test_catalog_targets_plan_a_blueprint_and_fly_a_pass(monkeypatch):
    """The targets are the GEO blueprint's own type: planned and refined unchanged."""
    import dataclasses

    import dyntarget.passes.geo as fg
    from dyntarget.fly import PassConfig, fly_pass
    from dyntarget.geo.refine import BlueprintGate
    from dyntarget.schedule import get_agility
    from dyntarget.synth.strip import strip_spec
    from dyntarget.synth.strip_world import MovingStrip

    # 18 km: the vents' targets lie far enough from the strip's top for the look-ahead to
    # see them whole (the gate releases a target then, or when its window opens)
    spec, window = strip_spec(4, width=128, length=2304, plumes=3)
    world = MovingStrip(spec, window)
    cfg = PassConfig(agility="fast", compute_budget_s=0.05)

    blind = fg.prepare  # the loop's own preparation, without a blueprint ...

    def prepare(world, frames, config, settings):  # ... given the catalog's instead
        targets, info = prior_targets("vents", world, frames, config.factor)
        assert all(isinstance(t, Target) for t in targets)
        horizon = frames.n_frames * frames.cadence_s + frames.geometry.look_ahead_m / (
            frames.geometry.ground_speed
        )
        agility = get_agility(config.agility)
        bp = plan_blueprint(
            targets, dataclasses.replace(frames.geometry, start_s=0.0), agility,
            horizon_s=horizon, reserve=settings.reserve,
        )  # fmt: skip
        out = list(blind(world, frames, config, fg.GeoSettings(blind=True)))
        out[0] = BlueprintGate(bp, frames, agility)
        out[1] = {**out[1], **info, "targets": len(bp.targets), "targets_chosen": len(bp.chosen)}
        return tuple(out)

    monkeypatch.setattr(fg, "prepare", prepare)
    r = fly_pass(world, None, cfg, geo=fg.GeoSettings())
    assert r.geo["catalog"] == "vents"
    assert r.geo["targets"] == 3 and r.geo["targets_chosen"] >= 1
    assert r.geo["targets_released_blueprint"] >= 1
    assert r.totals()["utility"] > 0
    assert math.isfinite(r.totals()["utility"])


def test_the_blueprint_gate_takes_catalog_targets_unchanged():
    import dataclasses

    from dyntarget.fly import PassConfig
    from dyntarget.geo.refine import BlueprintGate
    from dyntarget.passes.record import frame_plan
    from dyntarget.scene import Scene
    from dyntarget.schedule import get_agility
    from dyntarget.synth.worlds import StaticWorld

    img = np.zeros((4, 4096, 256), np.float32)
    world = StaticWorld(Scene(img, label=np.zeros((4096, 256), bool), gsd=16.0))
    frames = frame_plan(world, PassConfig(factor=4))  # WFOV 64 m: 1024 x 64
    # two volcanoes at WFOV rows 300 and 700 (high-res 1202, 2802), radius 640 m = 10 rows
    ts, _ = catalog_targets(
        np.array([1202.0, 2802.0]), np.array([130.0, 130.0]), frames.wfov_shape,
        frames.frame_px, frames.geometry, 4, radius_m=640.0, area_m2=20 * 64.0**2,
    )  # fmt: skip
    assert [t.need for t in ts] == [20, 20]
    agility = get_agility("fast")
    bp = plan_blueprint(
        ts, dataclasses.replace(frames.geometry, start_s=0.0), agility, horizon_s=200.0
    )
    assert (bp.budget > 0).all() and len(bp.targets) == 2
    gate = BlueprintGate(bp, frames, agility)
    # rows within 10 of a vent belong to its target; others to none (targets in along order:
    # row 700 is nearer nadir, so it comes first)
    got = gate.target_of(np.array([290.0, 300.0, 310.0, 311.0, 689.0, 700.0, 710.0, 500.0]))
    assert got.tolist() == [1, 1, 1, -1, -1, 0, 0, -1]
