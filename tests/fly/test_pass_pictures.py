"""Pictures of a pass: the lean install says in one line what it skipped; long passes get an
overview (pass.png, pass.html) and full-resolution pages per segment, in bounded memory."""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from dyntarget.io import write_scene
from dyntarget.scene import Scene


def _static_strip(directory, *, rows=1024, cols=128, plumes=((600, 680, 20, 80),)):
    image = np.full((4, rows, cols), 0.05, np.float32)
    label = np.zeros((rows, cols), bool)
    for r0, r1, c0, c1 in plumes:
        label[r0:r1, c0:c1] = True
    image[:, label] = 0.8
    write_scene(Scene(image, label=label, gsd=8.0, id="strip"), directory)
    return directory / "strip.tif"


def _fly_without(modules, strip, out):
    """Run ``dyntarget fly`` in a fresh process where ``modules`` cannot be imported."""
    code = textwrap.dedent(
        f"""
        import sys
        for m in {list(modules)!r}:
            sys.modules[m] = None  # import m raises ImportError, as on the lean install
        from dyntarget.cli import main
        sys.exit(main(sys.argv[1:]))
        """
    )
    args = ["fly", "--scene", str(strip), "--truth", "--agility", "unlimited"]
    args += ["--compute-budget-s", "0.05", "--out", str(out), "--quiet"]
    return subprocess.run(
        [sys.executable, "-c", code, *args], capture_output=True, text=True, timeout=300
    )


@pytest.mark.slow
def test_fly_without_matplotlib_says_so_in_one_line_and_writes_the_rest(tmp_path):
    strip = _static_strip(tmp_path / "in")
    out = tmp_path / "out"
    done = _fly_without(["matplotlib"], strip, out)
    assert done.returncode == 0, done.stderr
    skipped = [ln for ln in done.stderr.splitlines() if "skipped" in ln]
    assert skipped == [
        'dyntarget: pass.png skipped: matplotlib is not installed (pip install "dyntarget[full]"); '
        "the rest of the pass is written"
    ]
    assert "Traceback" not in done.stderr
    written = {p.name for p in out.iterdir()}
    assert {
        "timeline.csv",
        "pointings.geojson",
        "summary.md",
        "summary.json",
        "pass.html",
    } <= written
    assert "pass.png" not in written
    assert "matplotlib is not installed" in (out / "summary.md").read_text()
    # the "wrote" line names every file written, stage_times.csv included (fixed budget)
    wrote = next(ln for ln in done.stderr.splitlines() if ln.startswith("wrote "))
    assert "stage_times.csv" in wrote and "pass.png" not in wrote


@pytest.mark.slow
def test_fly_without_matplotlib_and_plotly_says_both_in_one_line(tmp_path):
    strip = _static_strip(tmp_path / "in")
    done = _fly_without(["matplotlib", "plotly"], strip, tmp_path / "out")
    assert done.returncode == 0, done.stderr
    skipped = [ln for ln in done.stderr.splitlines() if "skipped" in ln]
    assert skipped == [
        "dyntarget: pass.png and pass.html skipped: matplotlib and plotly are not installed "
        '(pip install "dyntarget[full]"); the rest of the pass is written'
    ]


def test_overview_decimates_in_bounded_rows():
    """Rows averaged by hand: 8 rows of values 0..7 kept in at most 4 rows -> pairs averaged."""
    from dyntarget.view.pass_report import _Overview

    ov = _Overview(max_rows=4)
    for top in (0, 4):  # two frames of 4 rows, 2 columns
        img = np.zeros((4, 4, 2), np.float32)
        img[0] = (top + np.arange(4))[:, None]  # red = row number
        ov.add(top, img, np.ones((4, 2), bool))
    first, rgb, plume = ov.arrays()
    assert ov.d == 2 and first == 0
    np.testing.assert_allclose(rgb[:, 0, 0], [0.5, 2.5, 4.5, 6.5])
    np.testing.assert_allclose(plume, 1.0)


def test_overlapping_frames_average_their_rows():
    from dyntarget.view.pass_report import _Overview

    ov = _Overview(max_rows=100)
    a = np.zeros((4, 2, 1), np.float32)
    b = np.full((4, 2, 1), 1.0, np.float32)
    ov.add(0, a, None)
    ov.add(1, b, None)  # row 1 seen twice: 0 and 1 -> 0.5
    _, rgb, _ = ov.arrays()
    np.testing.assert_allclose(rgb[:, 0, 0], [0.0, 0.5, 1.0])


@pytest.mark.slow
def test_a_long_pass_gets_an_overview_and_one_page_per_segment(tmp_path):
    """A pass of more than 64 frames: pass.png, pass.html linking every segment page."""
    from dyntarget.cli import main

    strip = _static_strip(
        tmp_path / "in", rows=4096, cols=64, plumes=((600, 680, 20, 50), (3000, 3100, 10, 40))
    )
    out = tmp_path / "out"
    args = ["fly", "--scene", str(strip), "--truth", "--agility", "unlimited", "--factor", "1"]
    assert main([*args, "--compute-budget-s", "0.05", "--out", str(out), "--quiet"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    frames = summary["frames"]
    assert frames > 64
    pages = sorted((out / "pass-segments").glob("segment-*.html"))
    assert len(pages) == -(-frames // 64)  # ceil: 64 frames a page
    assert (out / "pass-segments" / "plotly.min.js").stat().st_size > 1_000_000
    assert 'src="plotly.min.js"' in pages[0].read_text()
    html = (out / "pass.html").read_text()
    assert all(f"pass-segments/{p.name}" in html for p in pages)
    assert f"{summary['pointings_flown']} pointings" in html
    assert (out / "pass.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_a_geo_target_at_the_look_ahead_point_is_drawn_mid_first_frame():
    """A target ``look_ahead_m`` ahead of nadir at t = 0, on the ground track, is the centre
    of the first frame: half a frame along the pass, half the strip across."""
    from dyntarget.fly import PassConfig, fly_pass
    from dyntarget.synth.worlds import StaticWorld
    from dyntarget.view.pass_report import ViewCollector, _overview_data

    img = np.full((4, 512, 64), 0.1, np.float32)
    world = StaticWorld(Scene(img, label=np.zeros((512, 64), bool), gsd=8.0))
    views = ViewCollector()
    result = fly_pass(world, None, PassConfig(compute_budget_s=0.5), frame_sink=views)
    fp = result.frames
    result = dataclasses.replace(
        result, geo={"target_along_cross_m": [[fp.geometry.look_ahead_m, 0.0]]}
    )
    data = _overview_data(result, views)
    gsd_km = fp.geometry.wfov_gsd_m / 1e3
    along, across = data.targets
    assert along[0] == pytest.approx(fp.frame_px / 2 * gsd_km)
    assert across[0] == pytest.approx(fp.wfov_shape[1] / 2 * gsd_km)
    views.close()
