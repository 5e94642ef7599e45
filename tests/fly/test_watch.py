"""Live mode: frames planned as they appear, never read half-written."""

from __future__ import annotations

import json
import time

import pytest

from dyntarget.errors import DataFileError
from dyntarget.fly.watch import FRAMES, REJECTED, WatchConfig, Watcher, candidates
from dyntarget.io import read_scene, write_scene
from dyntarget.perceive import make_classifier
from dyntarget.pipeline import plan_scene


@pytest.fixture(scope="module")
def classifier(tiny_scenes):
    return make_classifier("band-threshold").fit([s.to_wfov(4) for s in tiny_scenes])


@pytest.fixture(scope="module")
def frame_bytes(tmp_path_factory, tiny_scenes) -> dict[str, bytes]:
    """Complete GeoTIFF bytes of two 64 px frames (written once, copied in by the tests)."""
    d = tmp_path_factory.mktemp("frames")
    out = {}
    for s in tiny_scenes[:2]:
        path = write_scene(s, d)[0]
        out[path.name] = path.read_bytes()
    return out


def _config(**kw) -> WatchConfig:
    return WatchConfig(factor=4, poll_s=0.02, settle_s=0.3, corrupt_after_s=30.0, **kw)


def test_only_complete_frame_files_are_candidates(tmp_path):
    for n in ("a.tif", "a.tif.part", ".a.tmp.tif", "a_mask.tif", "notes.txt"):
        (tmp_path / n).write_bytes(b"x")
    assert [p.name for p in candidates(tmp_path)] == ["a.tif"]


@pytest.mark.slow
def test_a_frame_written_slowly_is_read_only_when_complete(tmp_path, classifier, frame_bytes):
    watched, out = tmp_path / "in", tmp_path / "out"
    watched.mkdir()
    name, data = next(iter(frame_bytes.items()))
    plan_path = out / f"{name[:-4]}.geojson"
    w = Watcher(watched, out, classifier, _config())
    with open(watched / name, "wb") as f:  # written in place, in pieces, with pauses
        for piece in (data[:200], data[200 : len(data) // 2]):
            f.write(piece)
            f.flush()
            t_end = time.monotonic() + 0.8  # longer than settle_s: the partial file looks settled
            while time.monotonic() < t_end:
                assert w.step() == 0  # settled but incomplete: never planned
                time.sleep(0.02)
        assert not plan_path.exists()
        f.write(data[len(data) // 2 :])
    deadline = time.monotonic() + 60
    while not plan_path.exists() and time.monotonic() < deadline:
        w.step()
        time.sleep(0.02)
    assert plan_path.exists()
    # the plan is the one of the complete file
    (tmp_path / "ref").mkdir()
    (tmp_path / "ref" / name).write_bytes(data)
    scene = read_scene(tmp_path / "ref" / name, factor=4, auto_label=False)
    ref = plan_scene(scene.image, classifier, "lawnmower-transect", valid=scene.valid)
    doc = json.loads((out / f"{name[:-4]}.geojson").read_text())
    points = [f for f in doc["features"] if f["geometry"]["type"] == "Point"]
    assert len(points) == len(ref.trajectory)


def test_part_files_are_renamed_in_and_frames_go_in_acquisition_order(
    tmp_path, classifier, frame_bytes
):
    import rasterio

    watched, out = tmp_path / "in", tmp_path / "out"
    watched.mkdir()
    (a, da), (b, db) = frame_bytes.items()
    # acquisition times tagged: the file named last was taken first
    for name, data, when in ((a, da, "2026-01-01T00:00:10Z"), (b, db, "2026-01-01T00:00:00Z")):
        part = watched / f"{name}.part"
        part.write_bytes(data)
        with rasterio.open(part, "r+") as dst:
            dst.update_tags(DYNTARGET_ACQUIRED=when)
    w = Watcher(watched, out, classifier, _config())
    assert w.step() == 0 and w.step() == 0  # .part files are never read
    for name in (a, b):
        (watched / f"{name}.part").rename(watched / name)
    deadline = time.monotonic() + 10
    while len(w.rows) < 2 and time.monotonic() < deadline:
        w.step()
        time.sleep(0.05)
    assert [r["frame"] for r in w.rows] == [b, a]
    table = (out / FRAMES).read_text().splitlines()
    assert table[0].startswith("frame,acquired") and len(table) == 3
    # a restarted watcher does not plan them again
    again = Watcher(watched, out, classifier, _config(idle_exit_s=0.5))
    assert again.run() == 0


def test_a_corrupt_frame_is_reported_once_and_skipped(tmp_path, classifier):
    watched, out = tmp_path / "in", tmp_path / "out"
    watched.mkdir()
    (watched / "bad.tif").write_bytes(b"II*\x00" + bytes(100))
    w = Watcher(
        watched,
        out,
        classifier,
        WatchConfig(factor=4, poll_s=0.02, settle_s=0.05, corrupt_after_s=0.3, idle_exit_s=1.0),
    )
    assert w.run() == 0
    assert (out / REJECTED).read_text().splitlines()[1].startswith("bad.tif,")


def test_stop_request_returns_between_frames(tmp_path, classifier):
    watched = tmp_path / "in"
    watched.mkdir()
    w = Watcher(watched, tmp_path / "out", classifier, _config())
    t0 = time.monotonic()
    calls = []
    assert w.run(should_stop=lambda: calls.append(1) or len(calls) > 3) == 0
    assert time.monotonic() - t0 < 5


def test_missing_directory_is_refused(tmp_path, classifier):
    with pytest.raises(DataFileError, match="not a directory"):
        Watcher(tmp_path / "nope", tmp_path / "out", classifier, _config())
