"""The interactive HTML view: self-contained, checked input, and drawn as asked in Chromium."""

from __future__ import annotations

import re

import numpy as np
import pytest
from shapely.geometry import box

from dyntarget.errors import InvalidParameterError, InvalidSceneError
from dyntarget.observe import pointing_truth
from dyntarget.trajectory import Trajectory

pytest.importorskip("plotly", reason="the view needs plotly (extra 'view', in 'test')")

from dyntarget.view import (
    PassFrame,
    pass_view_html,
    scene_view_html,
    write_pass_view,
    write_scene_view,
)
from view_browser import find_chromium, render


def _image(h=24, w=32, seed=0):
    return np.random.default_rng(seed).uniform(0, 0.5, (4, h, w)).astype(np.float32)


def _traj(n=7, seed=1, times=True):
    rng = np.random.default_rng(seed)
    pts = rng.uniform(0, 20, (n, 2)).round(2)
    t = np.cumsum(rng.uniform(0.5, 2.0, n)) if times else None
    return Trajectory(pts, np.repeat([0, 1], [n // 2, n - n // 2]), "test", times=t)


def _text(page: str) -> str:
    """The page with every JSON ``\\uXXXX`` escape undone: plotly escapes <, >, / and, without
    orjson (plotly 7), every non-ASCII character such as ``·`` or ``–``; with orjson it does
    not, so the tests read the decoded text either way."""
    return re.sub(r"\\u([0-9a-fA-F]{4})", lambda m: chr(int(m.group(1), 16)), page)


def test_page_is_self_contained_no_script_or_style_is_fetched():
    page = _text(scene_view_html(_image(), trajectory=_traj(), probability=_image()[0]))
    assert page.startswith("<!doctype html>")
    assert "plotly.js v" in page  # the library itself is inline
    assert not re.search(r"<script[^>]+src=", page)
    assert not re.search(r"<link[^>]+href=\"?https?:", page)
    # the image layers are inline PNGs, not files beside the page
    assert len(re.findall(r'"source":\s*"data:image/png;base64,', page)) == 2


def test_same_input_same_bytes(tmp_path):
    a = write_scene_view(
        tmp_path / "a.html", _image(), trajectory=_traj(), polygons=[box(1, 1, 5, 5)]
    )
    b = write_scene_view(
        tmp_path / "b.html", _image(), trajectory=_traj(), polygons=[box(1, 1, 5, 5)]
    )
    assert a.read_bytes() == b.read_bytes()


def test_hover_text_carries_order_time_utc_and_observed_values():
    t = Trajectory(np.array([[1.0, 2.0], [3.0, 4.0]]), np.zeros(2, np.int64), "t",
                   times=np.array([1.5, 62.0]))  # fmt: skip
    page = scene_view_html(
        _image(),
        trajectory=t,
        point_values={"plume": [1.0, np.nan]},
        acquired="2024-05-01T10:00:00Z",
    )
    page = _text(page)
    assert "<b>pointing 1</b> (part 0)<br>t = 62.000 s (2024-05-01T10:01:02.000Z)" in page
    assert "plume: 1.000" in page and "plume: –" in page
    assert "time (s)<br>after acquisition" in page


def test_untimed_pointings_are_coloured_by_order():
    page = scene_view_html(_image(), trajectory=_traj(times=False))
    assert re.search(r'"text":\s*"order"', page) and "time after acquisition" not in page


def test_bad_input_names_the_argument(tmp_path):
    with pytest.raises(InvalidParameterError, match=r"probability: shape \(3, 3\)"):
        scene_view_html(_image(), probability=np.zeros((3, 3)))
    with pytest.raises(InvalidParameterError, match=r"point_values\['u'\]: expected 7 values"):
        scene_view_html(_image(), trajectory=_traj(), point_values={"u": [1.0]})
    with pytest.raises(InvalidParameterError, match=r"polygons\[0\]"):
        scene_view_html(_image(), polygons=[[0, 1]])
    with pytest.raises(InvalidSceneError, match="image"):
        scene_view_html(np.zeros((3, 4, 4), np.float32))
    with pytest.raises(InvalidParameterError, match="ending in .html"):
        write_scene_view(tmp_path / "v.png", _image())
    with pytest.raises(InvalidParameterError, match="acquired: expected an ISO-8601"):
        scene_view_html(_image(), acquired="noon")
    assert list(tmp_path.iterdir()) == []


def test_pass_view_refuses_empty_mismatched_or_unordered_frames():
    with pytest.raises(InvalidParameterError, match="frames: expected at least one"):
        pass_view_html([])
    with pytest.raises(InvalidParameterError, match=r"frames\[1\]\.image: shape \(8, 8\) differs"):
        pass_view_html([PassFrame(0.0, _image()), PassFrame(1.0, _image(8, 8))])
    with pytest.raises(InvalidParameterError, match="time_s must not decrease"):
        pass_view_html([PassFrame(2.0, _image()), PassFrame(1.0, _image())])
    with pytest.raises(InvalidParameterError, match=r"frames\[0\]: expected a PassFrame"):
        pass_view_html([_image()])


def test_pointing_truth_by_hand():
    # 4x4 high-res, factor 2 -> 2x2 WFOV. Plume in the left column of high-res pixels.
    img = np.full((4, 4, 4), 0.5, np.float32)
    label = np.zeros((4, 4), bool)
    label[:, 0] = True
    t = Trajectory(np.array([[0.0, 0.0], [1.0, 1.0], [0.4, 1.4], [-1.0, 0.0]]), np.zeros(4), "t")
    got = pointing_truth(t, img, label, factor=2)
    # WFOV (0, 0) covers high-res columns 0-1: half plume; (1, 1) none; (0.4, 1.4) rounds to (0, 1)
    np.testing.assert_array_equal(got["plume"], [0.5, 0.0, 0.5, np.nan])
    # intensity = label * blue / max = 1 on plume pixels -> block means 0.5, 0, 0.5
    np.testing.assert_array_equal(got["intensity"], [0.5, 0.0, 0.5, np.nan])


# ----------------------------------------------------------------------- a real browser

CHROMIUM = find_chromium()
needs_chromium = pytest.mark.skipif(
    CHROMIUM is None,
    reason="headless Chromium not installed (Debian: apt-get install -y chromium chromium-driver; "
    ".ci/run installs it)",
)


@pytest.fixture(scope="module")
def planned(tmp_path_factory):
    """A synthetic georeferenced scene planned on its label, timed under the 'fast' agility."""
    from dyntarget.pipeline import plan_scene
    from dyntarget.schedule import OrbitGeometry, get_agility, make_feasible
    from dyntarget.synth import generate_scene

    scene = generate_scene(3, 0, size=96)[0]
    result = plan_scene(scene.image, None, "lawnmower-transect", mask=scene.label)
    geometry = OrbitGeometry(altitude_m=500e3, look_ahead_m=500e3, wfov_gsd_m=scene.gsd)
    sched = make_feasible(result.trajectory, scene.shape, geometry, get_agility("fast"))
    assert len(sched.trajectory) >= 5
    return scene, result, sched.trajectory


@pytest.mark.slow
@needs_chromium
def test_chromium_draws_the_trajectory_points_with_no_console_error(tmp_path, planned):
    scene, result, traj = planned
    path = write_scene_view(
        tmp_path / "view.html",
        scene.image,
        probability=result.mask.astype(np.float32),
        polygons=result.polygons,
        trajectory=traj,
        point_values=pointing_truth(traj, scene.image, scene.label),
        transform=scene.transform,
        crs=scene.crs,
        acquired="2024-05-01T10:00:00Z",
    )
    shown = render(path)
    assert shown.errors == [], shown.console
    assert shown.traces[-1] == "pointings" and "plume polygons (denoised)" in shown.traces
    assert shown.images == 1  # the RGB layer (false colour and probability start hidden)
    # the page's data for the layer: the trajectory's points, in order
    np.testing.assert_allclose(shown.pointings, traj.points, atol=1e-3)
    # and what was drawn: one marker per pointing at that place (within half a screen pixel)
    assert len(shown.drawn) == len(traj)
    np.testing.assert_allclose(shown.drawn, traj.points, atol=0.5 / shown.px_per_unit + 1e-3)


@pytest.mark.slow
@needs_chromium
def test_chromium_pass_slider_shows_each_frames_pointings(tmp_path, planned):
    scene, _, traj = planned
    k = len(traj) // 2
    frames = [
        PassFrame(0.0, scene.image, trajectory=traj.without(np.arange(len(traj)) >= k)),
        PassFrame(10.0, scene.image[:, ::-1].copy(), trajectory=traj),
    ]
    path = write_pass_view(tmp_path / "pass.html", frames, transform=scene.transform, crs=scene.crs)
    first = render(path)
    assert first.errors == [], first.console
    np.testing.assert_allclose(first.drawn, traj.points[:k], atol=0.5 / first.px_per_unit + 1e-3)
    second = render(path, frame=1)
    assert second.errors == [], second.console
    np.testing.assert_allclose(second.pointings, traj.points, atol=1e-3)
    np.testing.assert_allclose(second.drawn, traj.points, atol=0.5 / second.px_per_unit + 1e-3)


def test_importing_the_view_and_writers_loads_neither_plotly_nor_selenium():
    import json
    import subprocess
    import sys

    code = (
        "import sys, json, dyntarget.view, dyntarget.io.geojson, "
        "dyntarget.cli\n"
        "print(json.dumps([m for m in ('plotly', 'selenium') if m in sys.modules]))"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert json.loads(done.stdout.strip().splitlines()[-1]) == []


def test_pass_frames_with_their_own_transform_hover_their_own_lonlat():
    from affine import Affine

    t = Trajectory(np.array([[0.0, 0.0]]), np.zeros(1, np.int64), "t", times=np.array([1.0]))
    # UTM 32N: pixel (0, 0)'s centre on the central meridian (9°E) at the equator, then
    # the second frame's grid 30 m further north: 30 m / 0.9996 (UTM scale on the central
    # meridian) / 110 574 m per degree of latitude at the equator (WGS 84) = 0.0002714°
    first = Affine(30.0, 0.0, 499985.0, 0.0, -30.0, 15.0)
    second = Affine(30.0, 0.0, 499985.0, 0.0, -30.0, 45.0)
    page = _text(
        pass_view_html(
            [
                PassFrame(0.0, _image(), trajectory=t, transform=first),
                PassFrame(2.0, _image(), trajectory=t, transform=second),
            ],
            crs="EPSG:32632",
        )
    )
    assert "lon 9.0000000, lat 0.0000000" in page
    assert "lon 9.0000000, lat 0.0002714" in page


def test_a_frame_label_reads_the_same_with_or_without_orjson():
    """plotly 7 writes ``·`` as ``\\u00b7`` without orjson and as itself with it: the
    decoded page holds the label either way."""
    frames = [PassFrame(0.0, _image()), PassFrame(2.5, _image(), label="second look")]
    assert "t = 2.5 s · second look" in _text(pass_view_html(frames))
