"""One acquisition-time reader: the live mode dates dyntarget's own sequence frames by their tag."""

from __future__ import annotations

import os

import numpy as np

from dyntarget.fly.watch import acquired_time
from dyntarget.io import write_scene
from dyntarget.io.acquisition import read_acquisition
from dyntarget.scene import Scene
from dyntarget.sequence import format_time


def _frame(tmp_path, name, tags):
    scene = Scene(np.full((4, 16, 16), 0.1, np.float32), id=name, gsd=8.0)
    (path,) = [p for p in write_scene(scene, tmp_path, tags=tags) if p.name == f"{name}.tif"]
    return path


def test_watch_dates_a_synth_frames_frame_by_its_tag_not_its_mtime(tmp_path):
    # synth --frames tags frame 1 (10 s after the 2026-01-01 epoch) as io.sequences does
    tags = {"DYNTARGET_TIME_S": "10.0", "DYNTARGET_TIME": format_time("2026-01-01T00:00:00Z", 10.0)}
    path = _frame(tmp_path, "f001", tags)
    os.utime(path, (0, 0))  # an mtime far from the tag: 1970
    when, source = acquired_time(path)
    assert source == "DYNTARGET_TIME"
    assert when == 1767225610.0  # 2026-01-01T00:00:10Z (date -d ... +%s)


def test_an_undated_frame_says_it_is_dated_by_its_mtime(tmp_path):
    path = _frame(tmp_path, "f000", {})
    os.utime(path, (1234.0, 1234.0))
    assert read_acquisition(path) == (None, None)
    assert acquired_time(path) == (1234.0, "file mtime")
