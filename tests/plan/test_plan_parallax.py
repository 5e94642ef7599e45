"""``plan_scene(aim_height_m=...)`` and ``dyntarget plan --plume-height-km H / --no-parallax``.

Expected moves come from ray-sphere vector algebra (as tests/test_parallax.py), not from
dyntarget.parallax: the top is where the ray from the spacecraft at the acquisition through
the pixel's ground point crosses R + h; the NFOV flown at t aims where the ray from the
spacecraft then through that top meets the ground.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from affine import Affine

from dyntarget.cli import main
from dyntarget.errors import InvalidParameterError
from dyntarget.io import write_scene
from dyntarget.pipeline import Kinematics, plan_scene
from dyntarget.scene import Scene
from dyntarget.schedule import OrbitGeometry

R = 6_371_008.7714  # WGS 84 mean radius (2a + b) / 3, the sphere of dyntarget.parallax
H_SC, H_TOP, GSD, SIZE = 500e3, 10e3, 30.0, 48
T_OVER = 500e3 / OrbitGeometry(altitude_m=H_SC).ground_speed  # the nadir under the centre


def _ray_hits_sphere(s: np.ndarray, through: np.ndarray, radius: float) -> np.ndarray:
    d = (through - s) / np.linalg.norm(through - s)
    b = float(s @ d)
    c = float(s @ s) - radius**2
    return s + (-b - math.sqrt(b * b - c)) * d


def _expected_move(x: float, y: float, t_s: float) -> tuple[float, float]:
    """(dx, dy) px for a pointing planned at frame pixel (x, y), flown t_s after acquisition."""
    along = 500e3 + ((SIZE - 1) / 2 - y) * GSD
    cross = (x - (SIZE - 1) / 2) * GSD
    d = math.hypot(along, cross)
    u = np.array([math.sin(d / R) * along / d, math.sin(d / R) * cross / d, math.cos(d / R)])
    top = _ray_hits_sphere(np.array([0.0, 0.0, R + H_SC]), R * u, R + H_TOP)
    g = OrbitGeometry(altitude_m=H_SC).ground_speed * t_s / R
    hit = _ray_hits_sphere((R + H_SC) * np.array([math.sin(g), 0.0, math.cos(g)]), top, R)
    hit /= np.linalg.norm(hit)
    dist = R * math.atan2(math.hypot(hit[0], hit[1]), hit[2])
    az = math.atan2(hit[1], hit[0])
    return (dist * math.sin(az) - cross) / GSD, -(dist * math.cos(az) - along) / GSD


def _image_and_mask():
    image = np.full((4, SIZE, SIZE), 0.05, np.float32)
    mask = np.zeros((SIZE, SIZE), bool)
    mask[10:38, 8:40] = True
    image[:, mask] = 0.7
    return image, mask


def _kinematics(start_s: float = T_OVER) -> Kinematics:
    g = OrbitGeometry(altitude_m=H_SC, look_ahead_m=500e3, wfov_gsd_m=GSD, start_s=start_s)
    return Kinematics(geometry=g, agility="unlimited")


def test_plan_scene_moves_every_pointing_by_the_parallax_at_its_time():
    image, mask = _image_and_mask()
    plain = plan_scene(image, None, "lawnmower-transect", mask=mask, kinematics=_kinematics())
    aimed = plan_scene(
        image, None, "lawnmower-transect", mask=mask, kinematics=_kinematics(), aim_height_m=H_TOP
    )
    planned = plain.trajectory.points
    assert aimed.trajectory.points.tolist() == planned.tolist()  # the plan itself is the same
    flown = aimed.schedule
    assert len(flown.kept) == len(planned) > 10 and (flown.times == T_OVER).all()
    want = np.array([_expected_move(x, y, T_OVER) for x, y in planned[flown.kept]])
    got = flown.trajectory.points - planned[flown.kept]
    assert got == pytest.approx(want, abs=1e-3)  # 3 cm
    # ~11.5 km back towards the spacecraft: 380-390 px of 30 m down the frame
    assert (got[:, 1] > 370).all() and (got[:, 1] < 395).all()
    assert flown.trajectory.params["parallax_height_m"] == H_TOP
    assert "parallax_height_m" not in plain.schedule.trajectory.params
    assert plain.schedule.trajectory.points.tolist() == planned[plain.schedule.kept].tolist()


def test_plan_scene_flown_at_the_acquisition_does_not_move_and_bad_heights_are_refused():
    image, mask = _image_and_mask()
    r = plan_scene(
        image, None, "lawnmower-transect", mask=mask, kinematics=_kinematics(0.0),
        aim_height_m=H_TOP,
    )  # fmt: skip
    planned = r.trajectory.points[r.schedule.kept]
    assert np.abs(r.schedule.trajectory.points - planned).max() < 1e-6
    for bad in (float("nan"), -1.0, 0.0, float("inf")):
        with pytest.raises(InvalidParameterError, match="height_m"):
            plan_scene(image, None, "track-center", mask=mask, kinematics=_kinematics(),
                       aim_height_m=bad)  # fmt: skip
    with pytest.raises(InvalidParameterError, match="kinematics"):
        plan_scene(image, None, "track-center", mask=mask, aim_height_m=H_TOP)


# -- the command ----------------------------------------------------------------------------


def run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture
def scene(tmp_path):
    image, mask = _image_and_mask()
    transform = Affine(GSD, 0.0, 653000.0, 0.0, -GSD, 5120000.0)
    s = Scene(image, label=mask, gsd=GSD, crs="EPSG:32632", transform=transform, id="s")
    write_scene(s, tmp_path)
    return tmp_path / "s.tif", tmp_path / "s_mask.tif"


KINEMATICS = ("--agility", "unlimited", "--altitude-km", 500, "--look-ahead-km", 500)


def _plan(capsys, scene, out, *extra):
    image, mask = scene
    return run(
        capsys, "plan", image, "--mask", mask, "--planner", "lawnmower-transect",
        "--out", out, *extra,
    )  # fmt: skip


def test_plan_cli_prior_height_corrects_the_schedule_and_labels_the_polygons(
    scene, tmp_path, capsys
):
    t = f"{T_OVER:.6f}"
    code, _, err = _plan(
        capsys, scene, tmp_path / "h.geojson", *KINEMATICS, "--start-s", t,
        "--plume-height-km", 10, "--polygons", tmp_path / "hp.geojson",
    )  # fmt: skip
    assert code == 0, err
    assert "parallax" in err and "10 km" in err
    code, _, err = _plan(
        capsys, scene, tmp_path / "n.geojson", *KINEMATICS, "--start-s", t,
        "--no-parallax", "--polygons", tmp_path / "np.geojson",
    )  # fmt: skip
    assert code == 0, err
    code, _, err = _plan(
        capsys, scene, tmp_path / "d.geojson", *KINEMATICS, "--start-s", t,
        "--polygons", tmp_path / "dp.geojson",
    )  # fmt: skip
    assert code == 0, err
    # the default (neither option) and --no-parallax fly the same bytes; the polygons of
    # the default carry no height properties at all
    assert (tmp_path / "n.geojson").read_bytes() == (tmp_path / "d.geojson").read_bytes()
    default = json.loads((tmp_path / "dp.geojson").read_text())
    assert all("height_source" not in f["properties"] for f in default["features"])
    none = json.loads((tmp_path / "np.geojson").read_text())
    assert [f["properties"]["height_source"] for f in none["features"]] == ["none"]
    assert none["features"][0]["properties"]["top_height_m"] is None
    prior = json.loads((tmp_path / "hp.geojson").read_text())
    (feature,) = prior["features"]
    p = feature["properties"]
    assert (p["top_height_m"], p["top_height_sigma_m"], p["rise_mps"]) == (10000.0, None, None)
    assert p["height_source"] == "prior" and p["kind"] == "plume"
    assert feature["geometry"] == default["features"][0]["geometry"]
    # the trajectory: params record the height, every pointing moved as the vectors say
    h = json.loads((tmp_path / "h.geojson").read_text())
    n = json.loads((tmp_path / "n.geojson").read_text())
    assert h["properties"]["params"]["parallax_height_m"] == 10000.0
    assert "parallax_height_m" not in n["properties"]["params"]

    def pixels(doc):
        pts = [f["properties"] for f in doc["features"] if f["properties"]["kind"] == "pointing"]
        return np.array([[q["x_px"], q["y_px"]] for q in pts])

    before, after = pixels(n), pixels(h)
    assert len(before) == len(after) > 10
    want = np.array([_expected_move(x, y, T_OVER) for x, y in before])
    assert after - before == pytest.approx(want, abs=2e-3)  # the files keep 3 decimals


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--plume-height-km", "0"], "argument --plume-height-km: expected a plume-top height"),
        (["--plume-height-km", "nan"], "argument --plume-height-km: expected a plume-top height"),
        (["--plume-height-km", "-1"], "argument --plume-height-km: expected a plume-top height"),
        (["--plume-height-km", "30"], "argument --plume-height-km: expected a plume-top height"),
        (["--plume-height-km", "10", "--no-parallax"], "not allowed with argument"),
    ],
)
def test_plan_cli_bad_height_options_exit_2_one_line(scene, tmp_path, capsys, extra, message):
    code, _, err = _plan(capsys, scene, tmp_path / "t.geojson", *KINEMATICS, *extra)
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and message in lines[0] and "Traceback" not in err
    assert not (tmp_path / "t.geojson").exists()


def test_plan_cli_height_without_agility_exit_2_one_line(scene, tmp_path, capsys):
    code, _, err = _plan(capsys, scene, tmp_path / "t.geojson", "--plume-height-km", "10")
    assert code == 2
    (line,) = err.strip().splitlines()
    assert "--plume-height-km 10" in line and "--agility" in line
    assert not (tmp_path / "t.geojson").exists()
