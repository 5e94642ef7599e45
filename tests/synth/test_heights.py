"""3D worlds: heights in the spec, the oblique look-ahead, the plume truth GeoJSON, the CLI."""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import replace

import numpy as np
import pytest

from dyntarget.cli import main
from dyntarget.errors import InvalidParameterError
from dyntarget.synth.dynamic import (
    CloudSpec,
    VentSpec,
    Wind,
    World,
    WorldSpec,
    sample_world,
    with_heights,
)

R = 6_371_008.7714


def _synth(capsys, *argv) -> tuple[int, str]:
    rc = main([str(a) for a in argv])
    return rc, capsys.readouterr().err


# -------------------------------------------------------------------- the flat world


@pytest.mark.slow
def test_flat_spec_json_has_no_height_keys_and_the_recorded_bytes(tmp_path, capsys):
    # sha256 of strip-0000.world.json of `synth --strip --scenes 1 --size 256 --seed 0`,
    # recorded before worlds had heights (the same on any machine: plain JSON of floats)
    # (moving worlds are 3D by default since; --flat gives these bytes)
    rc, _ = _synth(capsys, "synth", "--strip", "--scenes", 1, "--size", 256, "--seed", 0,
                   "--flat", "--out", tmp_path / "s", "--quiet")  # fmt: skip
    assert rc == 0
    text = (tmp_path / "s" / "strip-0000.world.json").read_bytes()
    assert hashlib.sha256(text).hexdigest() == (
        "cf49acbb57a6c9c21acb17c0b523a435d17ccc2cc8dca1a7c01745b0b9d0b3f4"
    )
    assert b"height" not in text and b"rise" not in text
    assert not (tmp_path / "s" / "strip-0000.plumes.geojson").exists()


def _files(root) -> dict[str, bytes]:
    return {
        str(p.relative_to(root)): p.read_bytes()
        for p in sorted(root.rglob("*"))
        if p.is_file() and p.name != ".dyntarget-output"
    }


def test_flat_frames_are_the_flat_generators_bytes(tmp_path, capsys):
    # synth --frames --flat writes what the (flat) Python generator and writer write
    from dyntarget.io import write_sequence
    from dyntarget.synth import generate_sequences

    rc, _ = _synth(capsys, "synth", "--frames", 2, "--scenes", 2, "--size", 32, "--seed", 3,
                   "--flat", "--out", tmp_path / "cli", "--quiet")  # fmt: skip
    assert rc == 0
    for seq in generate_sequences(2, size=32, seed=3, frames=2):
        write_sequence(seq, tmp_path / "lib")
    cli, lib = _files(tmp_path / "cli"), _files(tmp_path / "lib")
    assert len(cli) == 2 * (2 * 2 + 1)  # per sequence: 2 frames, 2 masks, sequence.json
    assert cli == lib
    assert not any(name.endswith(".plumes.geojson") for name in cli)


def test_flat_strip_is_the_flat_generators_bytes(tmp_path, capsys):
    from dyntarget.synth.strip import strip_spec, write_strip

    rc, _ = _synth(capsys, "synth", "--strip", "--scenes", 1, "--size", 64, "--length", 256,
                   "--plumes", 2, "--seed", 3, "--flat", "--out", tmp_path / "cli",
                   "--quiet")  # fmt: skip
    assert rc == 0
    write_strip(*strip_spec(3, width=64, length=256, plumes=2), tmp_path / "lib")
    cli = _files(tmp_path / "cli")
    assert sorted(cli) == ["strip-0003.tif", "strip-0003.world.json", "strip-0003_mask.tif"]
    assert cli == _files(tmp_path / "lib")


# -------------------------------------------------------------------- 3D by default


def _strip_heights(world: dict) -> dict:
    """The world spec without its height keys (what a flat world writes)."""
    flat = json.loads(json.dumps(world))
    for v in flat["vents"]:
        del v["top_height_m"], v["rise_mps"]
    for c in flat["clouds"]:
        del c["height_m"]
    return flat


def _check_3d(world: dict, plumes_geojson) -> None:
    """Every vent and cloud has a height in the default ranges; the truth file has each vent."""
    assert world["vents"]
    for v in world["vents"]:
        assert 2000.0 <= v["top_height_m"] <= 15000.0 and 10.0 <= v["rise_mps"] <= 100.0
    for c in world["clouds"]:
        assert 1000.0 <= c["height_m"] <= 12000.0
    doc = json.loads(plumes_geojson.read_text())
    assert doc["type"] == "FeatureCollection"
    props = [f["properties"] for f in doc["features"]]
    assert [p["plume_id"] for p in props] == list(range(len(world["vents"])))
    assert [p["top_height_m"] for p in props] == pytest.approx(
        [v["top_height_m"] for v in world["vents"]], abs=1e-6
    )
    assert [p["rise_mps"] for p in props] == pytest.approx(
        [v["rise_mps"] for v in world["vents"]], abs=1e-6
    )
    assert all(f["geometry"]["type"] == "Point" for f in doc["features"])


def test_strip_is_3d_by_default_and_only_its_heights_differ_from_flat(tmp_path, capsys):
    common = ("--strip", "--scenes", 1, "--size", 64, "--length", 256, "--plumes", 3,
              "--seed", 5, "--quiet")  # fmt: skip
    assert _synth(capsys, "synth", *common, "--out", tmp_path / "d")[0] == 0
    assert _synth(capsys, "synth", *common, "--flat", "--out", tmp_path / "f")[0] == 0
    d = json.loads((tmp_path / "d" / "strip-0005.world.json").read_text())
    f = json.loads((tmp_path / "f" / "strip-0005.world.json").read_text())
    assert len(d["world"]["vents"]) == 3 and d["world"]["clouds"]
    _check_3d(d["world"], tmp_path / "d" / "strip-0005.plumes.geojson")
    # the same world, vent for vent and cloud for cloud, with heights added, and a northern
    # margin as long as the parallax of its highest top 500 km ahead from 500 km up
    # (tan 48.37 deg = 1.125, 2.2 % more with the curvature at this angle: checked in
    # tests/test_parallax.py), its vents moved down by as many rows
    from dyntarget.parallax import parallax_shift

    top = max(v["top_height_m"] for v in d["world"]["vents"])
    margin = d["window"][3] - f["window"][3]
    assert margin == math.ceil(float(parallax_shift(500e3, 500e3, top)) / 8.0)
    assert 1.125 * top / 8.0 < margin < 1.16 * top / 8.0
    flat3 = _strip_heights(d["world"])
    moved = [*flat3["vents"], *(c for c in flat3["clouds"] if c.get("volcanic", True))]
    before = [*f["world"]["vents"], *(c for c in f["world"]["clouds"] if c.get("volcanic", True))]
    for a, b in zip(moved, before, strict=True):
        assert a["y"] - margin == pytest.approx(b["y"], abs=1e-9)
        a["y"] = b["y"]
    assert flat3 == f["world"] and d["window"][:3] == f["window"][:3]
    assert not (tmp_path / "f" / "strip-0005.plumes.geojson").exists()


def test_pass_length_strip_is_3d_by_default(tmp_path, capsys):
    rc, _ = _synth(capsys, "synth", "--strip", "--length-km", 20, "--plumes", 2, "--scenes", 1,
                   "--clouds-per-100km", 30, "--seed", 1, "--out", tmp_path / "l",
                   "--quiet")  # fmt: skip
    assert rc == 0
    doc = json.loads((tmp_path / "l" / "strip-0001.world.json").read_text())
    assert len(doc["world"]["vents"]) == 2 and doc["world"]["clouds"]
    _check_3d(doc["world"], tmp_path / "l" / "strip-0001.plumes.geojson")


def test_frames_are_3d_by_default_and_only_their_heights_differ_from_flat(tmp_path, capsys):
    common = ("--frames", 1, "--scenes", 2, "--size", 32, "--seed", 2, "--quiet")
    assert _synth(capsys, "synth", *common, "--out", tmp_path / "d")[0] == 0
    assert _synth(capsys, "synth", *common, "--flat", "--out", tmp_path / "f")[0] == 0
    for sid in ("dyn-0002-0000", "dyn-0002-0001"):
        d = json.loads((tmp_path / "d" / sid / "sequence.json").read_text())["meta"]["world"]
        f = json.loads((tmp_path / "f" / sid / "sequence.json").read_text())["meta"]["world"]
        _check_3d(d, tmp_path / "d" / f"{sid}.plumes.geojson")
        assert _strip_heights(d) == f
        assert not (tmp_path / "f" / f"{sid}.plumes.geojson").exists()


def test_static_scenes_stay_flat_and_flat_changes_nothing(tmp_path, capsys):
    for name, extra in (("a", []), ("b", ["--flat"])):
        rc, _ = _synth(capsys, "synth", "--scenes", 2, "--size", 32, "--seed", 4,
                       "--out", tmp_path / name, "--quiet", *extra)  # fmt: skip
        assert rc == 0
    a = _files(tmp_path / "a")
    assert sorted(a) == [
        "synth-0004-0000.tif",
        "synth-0004-0000_mask.tif",
        "synth-0004-0001.tif",
        "synth-0004-0001_mask.tif",
    ]
    assert a == _files(tmp_path / "b")


def test_flat_world_looks_the_same_from_any_angle():
    w = World(sample_world(0, 0, size=48, wind_mps=6.0))
    a = w.render(20.0)
    b = w.render_look(20.0, nadir_px=(24.0, 60_000.0), altitude_m=500e3)
    assert np.array_equal(a.image, b.image) and np.array_equal(a.mask, b.mask)


# -------------------------------------------------------------------- heights in the spec


def test_with_heights_draws_in_range_and_leaves_the_rest():
    flat = sample_world(4, 2, size=64)
    flat = replace(flat, clouds=(*flat.clouds, CloudSpec(5.0, 5.0, volcanic=False)))
    w3 = with_heights(flat, plume_height_km=(2, 15), cloud_height_km=(1, 12))
    assert w3.is_3d and not flat.is_3d
    for v in w3.vents:
        assert 2000.0 <= v.top_height_m <= 15000.0 and 10.0 <= v.rise_mps <= 100.0
    for c in w3.clouds:
        assert 1000.0 <= c.height_m <= 12000.0
    # stripping the heights gives the flat spec back, field for field
    back = replace(
        w3,
        vents=tuple(replace(v, top_height_m=None, rise_mps=None) for v in w3.vents),
        clouds=tuple(replace(c, height_m=None) for c in w3.clouds),
    )
    assert back == flat
    assert with_heights(flat) == with_heights(flat)  # deterministic
    assert WorldSpec.from_json(w3.to_json()) == w3  # round trip


def test_bad_heights_are_refused():
    with pytest.raises(InvalidParameterError, match="top_height_m"):
        VentSpec(0.0, 0.0, top_height_m=30_000.0)
    with pytest.raises(InvalidParameterError, match="rise_mps"):
        VentSpec(0.0, 0.0, rise_mps=20.0)  # a rise without a top
    with pytest.raises(InvalidParameterError, match="height_m"):
        CloudSpec(0.0, 0.0, height_m=math.nan)
    with pytest.raises(InvalidParameterError, match="plume height"):
        with_heights(sample_world(0, 0, size=32), plume_height_km=(5, 2))


def test_column_rises_linearly_then_levels():
    # onset at -eruption_age_s = -100 s, 30 m/s, top 9 km: 3 km at t = 0, 9 km from t = 200 s
    v = VentSpec(10.0, 10.0, eruption_age_s=100.0, top_height_m=9000.0, rise_mps=30.0)
    w = World(WorldSpec(0, 32, 8.0, Wind(5.0, 0.0), (v,)))
    got = [w.column_height(0, t) for t in (-150.0, -100.0, 0.0, 100.0, 200.0, 900.0)]
    assert got == [0.0, 0.0, 3000.0, 6000.0, 9000.0, 9000.0]


# -------------------------------------------------------------------- the oblique look


def _centroid(a: np.ndarray) -> tuple[float, float]:
    rows, cols = np.indices(a.shape)
    return float((a * cols).sum() / a.sum()), float((a * rows).sum() / a.sum())


@pytest.mark.parametrize("height_m", [5_000.0, 12_000.0])
def test_a_cloud_at_height_is_displaced_by_its_parallax(height_m):
    # a volcanic cloud at (64, 64), calm air; the spacecraft 500 km up, its nadir 450 km
    # south (rows grow southward, 8 m px: 56,250 px below). The cloud is seen displaced
    # north (away from the nadir). Hand: tan(theta) at 450 km = (R + H) sin g /
    # ((R + H) cos g - R), g = 450 / 6371.009: 6871.009 * 0.070573 / (6871.009 * 0.997507
    # - 6371.009) = 484.92 / 482.87 = 1.00424; shift ~ h tan(theta) (+ ~2 % curvature).
    gsd, ahead = 8.0, 450e3
    g = ahead / R
    tan_t = (R + 500e3) * math.sin(g) / ((R + 500e3) * math.cos(g) - R)
    first_order_px = height_m * tan_t / gsd
    cloud = CloudSpec(64.0, 64.0, radius_m=200.0, optical_depth=3.0, height_m=height_m)
    spec = WorldSpec(0, 128, gsd, Wind(0.0, 0.0), (), (cloud,))
    w = World(spec)
    shift = round(first_order_px)
    window = (0, -shift - 64, 128, 256)  # room for the curvature's extra and the stretch
    look = w.render_look(0.0, window, nadir_px=(64.0, 64.0 + ahead / gsd), altitude_m=500e3)
    flat = World(replace(spec, clouds=(replace(cloud, height_m=None),))).render(0.0)
    cx0, cy0 = _centroid(flat.tau)
    cx1, cy1 = _centroid(look.tau)
    moved = (cy0 - (cy1 - shift - 64)) * gsd  # metres north
    # across track the view is radial from the nadir 56,250 px away: a cloud 1.6 px east
    # of the nadir's column moves east by 1.6 x shift / 56,250 px, under 0.06 px
    assert cx1 == pytest.approx(cx0, abs=0.1)
    assert moved == pytest.approx(height_m * tan_t, rel=0.03)
    assert moved > height_m * tan_t  # the curvature adds, never removes
    assert look.mask.any()


# -------------------------------------------------------------------- the truth file


def test_strip_plumes_geojson_matches_the_spec(tmp_path, capsys):
    pyogrio = pytest.importorskip("pyogrio")
    from rasterio.crs import CRS
    from rasterio.warp import transform as warp

    out = tmp_path / "s"
    rc, _ = _synth(capsys, "synth", "--strip", "--scenes", 1, "--size", 64, "--length", 256,
                   "--plumes", 3, "--seed", 5, "--plume-height-km", "4,9",
                   "--cloud-height-km", "2,3", "--out", out, "--quiet")  # fmt: skip
    assert rc == 0
    world = json.loads((out / "strip-0005.world.json").read_text())["world"]
    meta, _, wkb, fields = pyogrio.raw.read(out / "strip-0005.plumes.geojson")
    assert list(meta["fields"][:4]) == ["plume_id", "top_height_m", "rise_mps", "onset_s"]
    assert len(wkb) == 3 == len(world["vents"])
    from shapely import from_wkb

    for i, v in enumerate(world["vents"]):
        assert 4000.0 <= v["top_height_m"] <= 9000.0 and 10.0 <= v["rise_mps"] <= 100.0
        assert fields[0][i] == i
        assert fields[1][i] == pytest.approx(v["top_height_m"], abs=1e-6)
        assert fields[2][i] == pytest.approx(v["rise_mps"], abs=1e-6)
        assert fields[3][i] == pytest.approx(-v["eruption_age_s"], abs=1e-6)
        # the vent's pixel centre in UTM, then WGS 84 (GDAL/PROJ, not the writer's code)
        e = world["origin_easting"] + (v["x"] + 0.5) * world["gsd"]
        n = world["origin_northing"] - (v["y"] + 0.5) * world["gsd"]
        lon, lat = warp(CRS.from_user_input(world["crs"]), CRS.from_epsg(4326), [e], [n])
        pt = from_wkb(wkb[i])
        assert (pt.x, pt.y) == pytest.approx((lon[0], lat[0]), abs=2e-7)
    for c in world["clouds"]:
        assert 2000.0 <= c["height_m"] <= 3000.0


def test_frames_get_a_truth_file_beside_each_folder(tmp_path, capsys):
    out = tmp_path / "f"
    rc, _ = _synth(capsys, "synth", "--frames", 1, "--scenes", 2, "--size", 32, "--seed", 1,
                   "--cloud-height-km", "1,12", "--out", out, "--quiet")  # fmt: skip
    assert rc == 0
    for sid in ("dyn-0001-0000", "dyn-0001-0001"):
        doc = json.loads((out / f"{sid}.plumes.geojson").read_text())
        spec = json.loads((out / sid / "sequence.json").read_text())["meta"]["world"]
        (feat,) = doc["features"]
        assert feat["properties"]["top_height_m"] == pytest.approx(
            spec["vents"][0]["top_height_m"], abs=1e-6
        )
        assert 2000.0 <= feat["properties"]["top_height_m"] <= 15000.0  # the default range


@pytest.mark.parametrize(
    ("extra", "needle"),
    [
        (["--strip", "--plume-height-km", "15,2"], "0 <= LO <= HI <= 25"),
        (["--strip", "--cloud-height-km", "1,26"], "0 <= LO <= HI <= 25"),
        (["--strip", "--plume-height-km", "nan"], "0 <= LO <= HI <= 25"),
        (["--strip", "--plume-height-km", "2,x"], "expected LO,HI km"),
        (["--strip", "--plume-height-km", "2,5", "--flat"], "exclude each other"),
        (["--plume-height-km", "2,5"], "static scenes stay flat"),
    ],
)
def test_bad_height_options_one_line_exit_2(tmp_path, capsys, extra, needle):
    out = tmp_path / "bad"
    rc, err = _synth(capsys, "synth", "--scenes", 1, "--size", 64, "--out", out, *extra)
    assert rc == 2
    assert err.count("\n") == 1 and err.startswith("dyntarget: error:") and needle in err
    assert not out.exists()


def test_cli_constants_match_the_renderer():
    from dyntarget.cli import options
    from dyntarget.cli import synth as cli
    from dyntarget.synth import dynamic

    assert options.MAX_HEIGHT_KM * 1e3 == dynamic.MAX_HEIGHT_M
    assert (cli.PLUME_HEIGHT_KM, cli.CLOUD_HEIGHT_KM) == (
        dynamic.PLUME_HEIGHT_KM,
        dynamic.CLOUD_HEIGHT_KM,
    )
