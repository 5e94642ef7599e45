"""Time-aware scene directories: round trip, foreign folders read by their time tags, bad input."""

from __future__ import annotations

import json

import numpy as np
import pytest
import rasterio

from dyntarget import DataFileError, InvalidSceneError, Scene
from dyntarget.io import read_sequence, read_sequence_dir, write_scene, write_sequence
from dyntarget.sequence import FrameSequence
from dyntarget.synth.dynamic import World, sample_world, truth_provider, world_sequence


def _frames(n, shape=(8, 8)):
    return [
        Scene(
            np.linspace(0.0, 0.5, 4 * shape[0] * shape[1], dtype=np.float32).reshape(4, *shape)
            + 0.01 * i,
            label=np.eye(*shape, dtype=bool),
            id=f"f{i:03d}",
        )
        for i in range(n)
    ]


def test_round_trip_keeps_frames_times_epoch_and_world(tmp_path):
    seq = world_sequence(World(sample_world(2, 1, size=32)), frames=3, interval_s=15.0)
    write_sequence(seq, tmp_path)
    back = read_sequence(tmp_path / seq.id)
    assert back.times.tolist() == [0.0, 15.0, 30.0]
    assert back.epoch == "2026-01-01T00:00:00.000Z"
    for a, b in zip(seq.frames, back.frames, strict=True):
        np.testing.assert_array_equal(a.image, b.image)
        np.testing.assert_array_equal(a.label, b.label)
    truth = truth_provider(back.meta, step_s=0.0)
    np.testing.assert_array_equal(truth(210.0).label, seq.truth_at(210.0).label)
    with rasterio.open(tmp_path / seq.id / "f002.tif") as src:
        assert src.tags()["DYNTARGET_TIME"] == "2026-01-01T00:00:30.000Z"
    assert [s.id for s in read_sequence_dir(tmp_path)] == [seq.id]


def test_folder_without_sidecar_is_ordered_by_tiff_datetime(tmp_path):
    folder = tmp_path / "cam"
    stamps = ["2025:06:01 10:00:40", "2025:06:01 10:00:00", "2025:06:01 10:00:10"]
    for f, stamp in zip(_frames(3), stamps, strict=True):
        write_scene(f, folder, tags={"TIFFTAG_DATETIME": stamp})
    seq = read_sequence(folder)
    # by hand: sorted 10:00:00 (f001), 10:00:10 (f002), 10:00:40 (f000)
    assert [f.id for f in seq.frames] == ["f001", "f002", "f000"]
    assert seq.times.tolist() == [0.0, 10.0, 40.0]
    assert seq.epoch == "2025-06-01T10:00:00.000Z"
    assert seq.truth_at(12.0).id == "f002"  # last frame at or before t


def test_sidecar_with_iso_times(tmp_path):
    folder = tmp_path / "s"
    for f in _frames(2):
        write_scene(f, folder)
    doc = {
        "format": "dyntarget-sequence",
        "version": 1,
        "frames": [
            {"file": "f000.tif", "time": "2025-06-01T10:00:00Z"},
            {"file": "f001.tif", "time": "2025-06-01T10:01:30.5Z"},
        ],
    }
    (folder / "sequence.json").write_text(json.dumps(doc))
    assert read_sequence(folder).times.tolist() == [0.0, 90.5]


def test_frame_without_time_is_refused_naming_the_file(tmp_path):
    folder = tmp_path / "s"
    write_scene(_frames(1)[0], folder)
    with pytest.raises(DataFileError, match=r"f000\.tif.*acquisition time"):
        read_sequence(folder)


def test_mismatched_frames_are_refused(tmp_path):
    a = _frames(1)[0]
    b = Scene(np.zeros((4, 6, 8), np.float32), id="f001")
    with pytest.raises(InvalidSceneError, match="f001.*shape"):
        FrameSequence([a, b], [0.0, 1.0], id="x")
    with pytest.raises(InvalidSceneError, match="increasing"):
        FrameSequence(_frames(2), [5.0, 5.0], id="x")


@pytest.mark.parametrize(
    "doc",
    [
        "not json",
        json.dumps({"format": "other"}),
        json.dumps({"format": "dyntarget-sequence", "version": 1, "frames": []}),
    ],
)
def test_corrupt_sidecar_is_refused(tmp_path, doc):
    folder = tmp_path / "s"
    write_scene(_frames(1)[0], folder)
    (folder / "sequence.json").write_text(doc)
    with pytest.raises(DataFileError, match="sequence.json"):
        read_sequence(folder)
