"""A pass's picture and pages drawn from plain arrays (view.pass_figure, view.pass_html):
checked input, what is drawn where, the page names and links, and None without the library."""

from __future__ import annotations

import sys

import numpy as np
import pytest

from dyntarget.errors import InvalidParameterError
from dyntarget.view.html import PassFrame
from dyntarget.view.pass_figure import (
    PassOverview,
    PassPicture,
    draw_pass_overview,
    draw_pass_picture,
)
from dyntarget.view.pass_html import write_overview_page, write_pass_page, write_segment_pages


def _picture(dropped=(False, False), **kw):
    hw, ww = 64, 16
    args = {
        "rgb": np.full((hw, ww, 3), 0.1, np.float32),
        "plume": np.zeros((hw, ww), np.float32),
        "frame_px": 16,
        "tops": [48, 40],
        "dropped": list(dropped),
        "pointings": ([8.0], [50.0], [1.5]),
        "title": "a pass",
    }
    return PassPicture(**{**args, **kw})


def _overview(targets=None):
    return PassOverview(
        rgb=np.full((40, 8, 3), 0.1),
        plume=np.zeros((40, 8)),
        extent=(0.0, 250.0, 0.0, 2.0),
        pointings=(np.array([10.0, 200.0]), np.array([1.0, 1.5]), np.array([0.0, 9.0])),
        targets=targets,
        dropped=np.array([]),
        rows_per_cell=8,
        km_per_cell=0.8,
        title="a long pass",
    )


def _red_pixels(path):
    """Pixels of pure red (the dropped frames' bars, GEO targets' crosses, legend entries)."""
    plt = pytest.importorskip("matplotlib.pyplot")
    img = plt.imread(path)[..., :3]
    return int(np.sum((img[..., 0] > 0.9) & (img[..., 1] < 0.1) & (img[..., 2] < 0.1)))


def test_a_picture_of_other_shapes_is_refused_in_one_line():
    with pytest.raises(InvalidParameterError, match="rgb .* and plume"):
        _picture(plume=np.zeros((63, 16)))
    with pytest.raises(InvalidParameterError, match="rgb"):
        _picture(rgb=np.zeros((64, 16, 4)))
    with pytest.raises(InvalidParameterError, match="tops \\(2\\) and dropped \\(1\\)"):
        _picture(dropped=(False,))


def test_a_dropped_frame_is_drawn_red(tmp_path):
    """Its bar is red (the legend's red square is in both pictures): more red than none dropped."""
    pytest.importorskip("matplotlib")
    ok = draw_pass_picture(_picture(), tmp_path / "ok.png")
    late = draw_pass_picture(_picture(dropped=(False, True)), tmp_path / "late.png")
    assert ok.read_bytes()[:8] == late.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert _red_pixels(late) > _red_pixels(ok) + 50  # a bar of 16 x 1.6 px at 110 dpi, at least


def test_geo_targets_are_drawn_on_the_overview(tmp_path):
    pytest.importorskip("matplotlib")
    bare = draw_pass_overview(_overview(), tmp_path / "bare.png")
    two = (np.array([50.0, 120.0]), np.array([0.5, 1.5]))
    crossed = draw_pass_overview(_overview(targets=two), tmp_path / "crossed.png")
    assert _red_pixels(crossed) > _red_pixels(bare) + 20  # two crosses of 30 pt²


def test_without_matplotlib_nothing_is_drawn(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "matplotlib", None)  # import matplotlib raises, as lean
    assert draw_pass_picture(_picture(), tmp_path / "p.png") is None
    assert draw_pass_overview(_overview(), tmp_path / "o.png") is None
    assert not list(tmp_path.iterdir())


def test_without_plotly_no_page_is_written(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "plotly.graph_objects", None)
    frames = [PassFrame(0.0, np.full((4, 8, 8), 0.2, np.float32))]
    assert write_pass_page(frames, tmp_path / "pass.html", title="t") is None
    assert write_overview_page(_overview(), tmp_path / "pass.html") is None
    assert write_segment_pages([("t", frames, "x")], tmp_path / "segs") == []
    assert not list(tmp_path.iterdir())


def test_segment_pages_are_numbered_share_one_plotlyjs_and_are_linked(tmp_path):
    pytest.importorskip("plotly")
    img = np.full((4, 8, 8), 0.2, np.float32)
    folder = tmp_path / "pass-segments"
    segments = (
        (f"frames {i}", [PassFrame(float(i), img)], f"text {i}") for i in range(3)
    )  # a generator: pages written one at a time
    links = write_segment_pages(segments, folder)
    assert links == [(f"pass-segments/segment-000{i}.html", f"text {i}") for i in range(3)]
    assert sorted(p.name for p in folder.iterdir()) == [
        "plotly.min.js",
        "segment-0000.html",
        "segment-0001.html",
        "segment-0002.html",
    ]
    page = (folder / "segment-0002.html").read_text()
    assert 'src="plotly.min.js"' in page and "frames 2" in page


def test_the_overview_page_says_its_decimation_and_links_each_segment(tmp_path):
    pytest.importorskip("plotly")
    links = [("pass-segments/segment-0000.html", "frames 0-63: 12 pointings flown")]
    page = write_overview_page(_overview(), tmp_path / "pass.html", segments=links)
    text = page.read_text()
    # 8 WFOV rows per cell at 100 m: 0.80 km per column
    assert "decimated: 0.80 km per column (8 WFOV rows)" in text
    assert 'href="pass-segments/segment-0000.html"' in text
    assert "frames 0-63: 12 pointings flown" in text
    assert "a long pass" in text
